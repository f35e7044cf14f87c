"""The RVE file: a batch of periodic disc packings in one ``.npz`` (DESIGN §3).

The file is the exchange format between our engine, YADE and users. Arrays, all SI and
float64, with the batch axis first:

- ``radius`` (B, N) [m], ``position`` (B, N, 2) [m] Cartesian inside the cell,
- ``cell`` (B, 2, 2) [m], columns are the cell vectors,
- ``velocity`` (B, N, 2) [m/s] (the fluctuation about the cell's affine field),
- ``angular_velocity`` (B, N) [rad/s],
- ``meta``: a JSON string (see :class:`RVEMeta`).

Further arrays (contact history) are kept in :attr:`RVEData.extra`; readers ignore keys they do
not know.
"""

from __future__ import annotations

import json
import math
import zipfile
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FORMAT_VERSION", "RVEData", "RVEFileError", "RVEMeta", "load_rve", "save_rve"]

FORMAT_VERSION = 1
_CORE_KEYS = ("radius", "position", "cell", "velocity", "angular_velocity", "meta")
_BATCH_ARRAYS = ("radius", "position", "cell", "velocity", "angular_velocity")


class RVEFileError(ValueError):
    """An RVE file cannot be read, or its content is not a valid RVE batch."""


@dataclass(frozen=True)
class RVEMeta:
    """Material and run parameters stored with an RVE batch.

    Attributes:
        thickness: disc thickness t [m]; discs are cylinders, mass = ρ·t·π·r².
        density: solid density ρ [kg/m³].
        friction_angle: interparticle friction angle φ [rad], μ = tan φ.
        damping: YADE-style local non-viscous damping coefficient [-].
        stiffness: ``{"law": "constant", "kn": N/m, "kt": N/m}`` or
            ``{"law": "frictmat", "young": Pa, "kt_over_kn": -}``.
        seed: the random seed the packing was generated with (None if unknown).
        timestep: explicit time step [s]; when present it is used as it is.
    """

    thickness: float = 0.1
    density: float = 2650.0
    friction_angle: float = 0.5
    damping: float = 0.1
    stiffness: dict[str, Any] = field(
        default_factory=lambda: {"law": "constant", "kn": 3.0e6, "kt": 2.4e6}
    )
    seed: int | None = None
    timestep: float | None = None

    def to_json(self) -> str:
        """The meta as the JSON string stored in the file."""
        data = {"format_version": FORMAT_VERSION, **asdict(self)}
        if data["timestep"] is None:
            del data["timestep"]
        return json.dumps(data, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> RVEMeta:
        """Parse the ``meta`` string of a file; unknown keys are ignored."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise RVEFileError(f"meta is not valid JSON: {exc}") from exc
        if not isinstance(data, dict):
            raise RVEFileError("meta must be a JSON object")
        version = data.get("format_version", FORMAT_VERSION)
        if version > FORMAT_VERSION:
            raise RVEFileError(
                f"format_version {version} is newer than this reader ({FORMAT_VERSION})"
            )
        known = {k: data[k] for k in cls.__dataclass_fields__ if k in data}
        meta = cls(**known)
        meta.validate()
        return meta

    def validate(self) -> None:
        """Raise ``RVEFileError`` naming the field whose value is not physical."""
        for name in ("thickness", "density"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise RVEFileError(f"meta.{name} must be a positive number, got {value!r}")
        if not (math.isfinite(self.friction_angle) and 0 <= self.friction_angle < math.pi / 2):
            raise RVEFileError(
                f"meta.friction_angle must lie in [0, pi/2) rad, got {self.friction_angle!r}"
            )
        if not (math.isfinite(self.damping) and 0 <= self.damping < 1):
            raise RVEFileError(f"meta.damping must lie in [0, 1), got {self.damping!r}")
        if self.timestep is not None and not (
            math.isfinite(self.timestep) and self.timestep > 0
        ):
            raise RVEFileError(f"meta.timestep must be a positive number, got {self.timestep!r}")
        law = self.stiffness.get("law")
        if law == "constant":
            required = ("kn", "kt")
        elif law == "frictmat":
            required = ("young", "kt_over_kn")
        else:
            raise RVEFileError(
                f"meta.stiffness.law must be 'constant' or 'frictmat', got {law!r}"
            )
        for key in required:
            value = self.stiffness.get(key)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise RVEFileError(
                    f"meta.stiffness.{key} must be a positive number, got {value!r}"
                )


@dataclass(frozen=True)
class RVEData:
    """A batch of B periodic RVEs of N discs each, as host (numpy) arrays.

    Attributes:
        radius: disc radii [m], shape (B, N), float64.
        position: disc centres [m], Cartesian inside the cell, shape (B, N, 2), float64.
        cell: cell matrices H [m] (columns = cell vectors), shape (B, 2, 2), float64.
        velocity: fluctuating velocities [m/s], shape (B, N, 2), float64.
        angular_velocity: [rad/s], shape (B, N), float64.
        meta: material and run parameters.
        extra: further arrays (contact history), passed through unchanged.
    """

    radius: np.ndarray
    position: np.ndarray
    cell: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    meta: RVEMeta = field(default_factory=RVEMeta)
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def n_rve(self) -> int:
        """Number of RVEs B in the batch."""
        return int(self.radius.shape[0])

    @property
    def n_disc(self) -> int:
        """Number of discs N per RVE."""
        return int(self.radius.shape[1])

    def select(self, index: int) -> RVEData:
        """The single RVE ``index`` as a batch of one (extra arrays are dropped)."""
        if not -self.n_rve <= index < self.n_rve:
            raise IndexError(f"rve index {index} out of range for a batch of {self.n_rve}")
        sl = slice(index, index + 1) if index != -1 else slice(-1, None)
        return RVEData(
            self.radius[sl], self.position[sl], self.cell[sl], self.velocity[sl],
            self.angular_velocity[sl], self.meta,
        )

    def _arrays(self) -> dict[str, np.ndarray]:
        """Every per-RVE array of the core format (batch axis first)."""
        return {name: getattr(self, name) for name in _BATCH_ARRAYS}

    def take(self, rves: slice | np.ndarray | list[int]) -> RVEData:
        """The RVEs ``rves`` (a slice or indices) as a batch, contact history included."""
        return replace(self, **{k: v[rves] for k, v in self._arrays().items()},
                       extra={k: v[rves] for k, v in self.extra.items()})

    def replicate(self, n_rve: int) -> RVEData:
        """A batch of ``n_rve`` copies of RVE 0 (contact history included)."""
        if n_rve < 1:
            raise ValueError(f"n_rve must be >= 1, got {n_rve}")
        return self.take(np.zeros(n_rve, dtype=np.int64))

    @staticmethod
    def concatenate(parts: list[RVEData]) -> RVEData:
        """One batch of the RVEs of ``parts`` in order; the meta (and the set of extra
        arrays) of the first part is kept."""
        if not parts:
            raise ValueError("concatenate needs at least one RVEData")
        first = parts[0]
        arrays = {k: np.concatenate([getattr(p, k) for p in parts]) for k in _BATCH_ARRAYS}
        extra = {k: np.concatenate([p.extra[k] for p in parts]) for k in first.extra}
        return replace(first, **arrays, extra=extra)

    def validate(self) -> None:
        """Raise ``RVEFileError`` naming the first array or value that is not a valid RVE."""
        if self.radius.ndim != 2:
            raise RVEFileError(f"radius must have shape (B, N), got {self.radius.shape}")
        b, n = self.radius.shape
        if b < 1 or n < 1:
            raise RVEFileError(f"an RVE batch needs B >= 1 and N >= 1, got B={b}, N={n}")
        expected = {
            "position": (b, n, 2), "cell": (b, 2, 2), "velocity": (b, n, 2),
            "angular_velocity": (b, n),
        }
        for name, shape in expected.items():
            got = getattr(self, name).shape
            if got != shape:
                raise RVEFileError(f"{name} must have shape {shape}, got {got}")
        for name in ("radius", *expected):
            array = getattr(self, name)
            bad = ~np.isfinite(array)
            if bad.any():
                where = np.argwhere(bad)[0].tolist()
                raise RVEFileError(f"{name} holds a non-finite value at index {where}")
        if (self.radius <= 0).any():
            where = np.argwhere(self.radius <= 0)[0].tolist()
            value = self.radius[tuple(where)]
            raise RVEFileError(f"radius must be positive, got {value!r} at index {where}")
        area = np.linalg.det(self.cell)
        if (area <= 0).any():
            rve = int(np.argmax(area <= 0))
            raise RVEFileError(
                f"cell of RVE {rve} has non-positive area {area[rve]!r} m² "
                "(columns must be right-handed cell vectors)"
            )
        solid = np.pi * (self.radius**2).sum(axis=1)
        if (solid >= area).any():
            rve = int(np.argmax(solid >= area))
            raise RVEFileError(
                f"cell of RVE {rve} is too small for its discs: area {area[rve]:.6g} m² "
                f"<= solid area {solid[rve]:.6g} m²"
            )
        self.meta.validate()


def save_rve(path: str | Path, data: RVEData) -> None:
    """Write ``data`` to ``path`` (.npz); written to a temporary file first, never half-way."""
    data.validate()
    path = Path(path)
    arrays = {
        "radius": np.asarray(data.radius, dtype=np.float64),
        "position": np.asarray(data.position, dtype=np.float64),
        "cell": np.asarray(data.cell, dtype=np.float64),
        "velocity": np.asarray(data.velocity, dtype=np.float64),
        "angular_velocity": np.asarray(data.angular_velocity, dtype=np.float64),
        "meta": np.array(data.meta.to_json()),
    }
    for key, value in data.extra.items():
        if key in arrays:
            raise ValueError(f"extra array {key!r} clashes with a core key")
        arrays[key] = value
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    tmp.replace(path)


def load_rve(path: str | Path) -> RVEData:
    """Read and validate an RVE batch file; raises ``RVEFileError`` naming what is wrong."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [k for k in _CORE_KEYS if k not in npz.files]
            if missing:
                raise RVEFileError(f"{path}: missing array(s) {', '.join(missing)}")
            core = {k: np.asarray(npz[k], dtype=np.float64) for k in _CORE_KEYS[:-1]}
            meta = RVEMeta.from_json(str(npz["meta"]))
            extra = {k: np.asarray(npz[k]) for k in npz.files if k not in _CORE_KEYS}
    except RVEFileError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise RVEFileError(f"{path}: not a readable RVE file ({exc})") from exc
    data = RVEData(meta=meta, extra=extra, **core)
    try:
        data.validate()
    except RVEFileError as exc:
        raise RVEFileError(f"{path}: {exc}") from exc
    return data
