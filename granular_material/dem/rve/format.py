"""The RVE file format's constants, its error and its meta: the JSON string of material and
run parameters stored with a batch (docs/design.md#rve-file)."""

from __future__ import annotations

import json
import math
import numbers
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "CONSTANT_STIFFNESS",
    "CONTACT_HISTORY_KEYS",
    "FORMAT_VERSION",
    "FRICTMAT_STIFFNESS",
    "REQUIRED_META_KEYS",
    "RVEFileError",
    "RVEMeta",
]

FORMAT_VERSION = 1
_BATCH_ARRAYS = ("radius", "position", "cell", "velocity", "angular_velocity")
#: meta keys every file must give (a missing one is an error, never a silent default)
REQUIRED_META_KEYS = ("thickness", "density", "friction_angle", "damping", "stiffness")
#: the contact law of an RVE whose meta names none: constant stiffnesses [N/m] (Wu et al.
#: 2025, Table 1)
CONSTANT_STIFFNESS: dict[str, Any] = {"law": "constant", "kn": 3.0e6, "kt": 2.4e6}
#: the FrictMat contact law's defaults (YADE, Guo & Zhao): Young's modulus [Pa], kt/kn [-]
FRICTMAT_STIFFNESS: dict[str, Any] = {"law": "frictmat", "young": 6.0e8, "kt_over_kn": 0.8}
#: the further arrays of a resumable file (the engine's contact history, see
#: :data:`granular_material.dem.state.HISTORY_KEYS`): all of them or none
CONTACT_HISTORY_KEYS = (
    "contact_partner",  # (B, N, K) integers, partner index within the RVE, -1 = empty slot
    "contact_count",  # (B, N) integers, used slots (the first ones)
    "contact_shear_force",  # (B, N, K) tangential spring force [N], both slots of a pair
    "fractional_position",  # (B, N, 2) s = H⁻¹x in [0, 1]
    "verlet_displacement",  # (B, N, 2) displacement since the last list build [m]
    "cell_at_list_build",  # (B, 2, 2) H at the last list build [m]
)


def _is_real(value: object) -> bool:
    """Whether ``value`` is a real number (int or float, numpy's included; never a bool)."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _real(name: str, value: object) -> float:
    """``value`` as a finite float, or ``RVEFileError`` naming ``name``."""
    if not _is_real(value):
        raise RVEFileError(f"{name} must be a number, got {value!r} ({type(value).__name__})")
    if not math.isfinite(float(value)):
        raise RVEFileError(f"{name} must be finite, got {value!r}")
    return float(value)


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
    stiffness: dict[str, Any] = field(default_factory=lambda: dict(CONSTANT_STIFFNESS))
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
        if not (_is_real(version) and float(version).is_integer() and version >= 1):
            raise RVEFileError(
                f"meta.format_version must be a positive integer, got {version!r}"
            )
        if version > FORMAT_VERSION:
            raise RVEFileError(
                f"meta.format_version {version} is newer than this reader ({FORMAT_VERSION})"
            )
        missing = [k for k in REQUIRED_META_KEYS if k not in data]
        if missing:
            raise RVEFileError(f"meta lacks {', '.join(missing)} (no default is assumed)")
        known = {k: data[k] for k in cls.__dataclass_fields__ if k in data}
        meta = cls(**known)
        meta.validate()
        return meta

    def validate(self) -> None:
        """Raise ``RVEFileError`` naming the field whose value is of the wrong type or not
        physical (every number finite; lengths, density and stiffnesses positive)."""
        for name in ("thickness", "density"):
            if _real(f"meta.{name}", getattr(self, name)) <= 0:
                raise RVEFileError(
                    f"meta.{name} must be a positive number, got {getattr(self, name)!r}"
                )
        if not 0 <= _real("meta.friction_angle", self.friction_angle) < math.pi / 2:
            raise RVEFileError(
                f"meta.friction_angle must lie in [0, pi/2) rad, got {self.friction_angle!r}"
            )
        if not 0 <= _real("meta.damping", self.damping) < 1:
            raise RVEFileError(f"meta.damping must lie in [0, 1), got {self.damping!r}")
        if self.timestep is not None and _real("meta.timestep", self.timestep) <= 0:
            raise RVEFileError(f"meta.timestep must be a positive number, got {self.timestep!r}")
        if self.seed is not None and not (
            _is_real(self.seed) and float(self.seed).is_integer()
        ):
            raise RVEFileError(f"meta.seed must be an integer or null, got {self.seed!r}")
        if not isinstance(self.stiffness, dict):
            raise RVEFileError(
                "meta.stiffness must be an object {\"law\": ..., ...}, got "
                f"{self.stiffness!r}"
            )
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
            if not _is_real(value) or not math.isfinite(value) or value <= 0:
                raise RVEFileError(
                    f"meta.stiffness.{key} must be a positive number, got {value!r}"
                )
