"""Model: the static description of a DEM batch (read-only once built) and how it is built."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import warp as wp

from granular_material.dem.kernels.laws import LAW_CONSTANT, LAW_FRICTMAT, ContactLaw
from granular_material.dem.rve.checks import validate_rve
from granular_material.dem.rve.file import RVEData, RVEFileError, RVEMeta, _touching_pairs

__all__ = [
    "DEFAULT_CAPACITY",
    "DEFAULT_SAFETY",
    "FLOAT32_MAX_RESOLUTION",
    "DeviceConstants",
    "Model",
    "build_model",
    "cell_heights",
    "critical_timestep",
    "disc_mass",
    "float32_resolution",
    "float_type",
    "median_overlap",
    "resolve_device",
]

DEFAULT_CAPACITY = 16  #: neighbour-list slots per disc (a dense 400-disc packing uses <= 8)
DEFAULT_SAFETY = 0.3  #: default time step as a fraction of the critical one
SKIN_FRACTION = 0.25  #: Verlet skin as a fraction of the mean disc diameter
#: largest float32 resolution of a cell (:func:`float32_resolution`) as a share of the median
#: contact overlap that ``dtype="float32"`` accepts. Measured on 64-disc packings, tiled up
#: to 65 536 discs a cell, held at a fixed cell for 2000 steps: float32's unbalanced-force
#: ratio settles near 2–3 times that share (float64: below 1e-7), e.g. 0.003 at 0.0013, 0.03 at
#: 0.012 and 0.12 at 0.073, with contacts lost beyond 0.01 (coordination 3.78 -> 3.56 at
#: 0.073); consolidation asks for 0.02.
FLOAT32_MAX_RESOLUTION = 0.005


def resolve_device(device: str | None) -> str:
    """The warp device to use: ``device`` itself, or CUDA when present else the CPU."""
    wp.init()
    if device is None:
        return "cuda" if wp.is_cuda_available() else "cpu"
    if device not in ("cpu", "cuda") and not device.startswith("cuda:"):
        raise ValueError(f"device must be 'cpu' or 'cuda', got {device!r}")
    if device.startswith("cuda") and not wp.is_cuda_available():
        raise ValueError(f"device {device!r} requested but no CUDA device is available")
    return device


def float_type(dtype: str) -> Any:
    """The warp scalar type of ``dtype`` ("float64" or "float32")."""
    if dtype == "float64":
        return wp.float64
    if dtype == "float32":
        return wp.float32
    raise ValueError(f"dtype must be 'float64' or 'float32', got {dtype!r}")


def disc_mass(radius: np.ndarray, meta: RVEMeta) -> np.ndarray:
    """Mass [kg] of discs of ``radius`` [m]: cylinders ρ·t·π·r² (docs/design.md#units), same
    shape."""
    return meta.density * meta.thickness * np.pi * np.asarray(radius, dtype=np.float64) ** 2


def critical_timestep(radius: np.ndarray, meta: RVEMeta) -> float:
    """Smallest ``sqrt(m_i / kn_i)`` [s] over discs, kn_i the stiffness against an equal disc.

    Explicit central differences are stable for a linear spring below ``2·sqrt(m/k)``; a disc
    with several contacts lowers that bound, so the engine refuses steps above this value and
    uses ``DEFAULT_SAFETY`` times it by default.
    """
    r = np.asarray(radius, dtype=np.float64)
    mass = disc_mass(r, meta)
    law = meta.stiffness["law"]
    if law == "frictmat":
        kn = meta.stiffness["young"] * r
        kt = meta.stiffness["kt_over_kn"] * kn
    else:
        kn = np.full_like(r, meta.stiffness["kn"])
        kt = np.full_like(r, meta.stiffness["kt"])
    # rotation: I·θ'' = -kt·r²·θ with I = m r²/2  ->  same form with stiffness 2·kt
    k_eff = np.maximum(kn, 2.0 * kt)
    return float(np.min(np.sqrt(mass / k_eff)))


def contact_law(meta: RVEMeta) -> ContactLaw:
    """The kernels' description of the stiffness law of ``meta``."""
    s = meta.stiffness
    law = ContactLaw()
    law.law = LAW_FRICTMAT if s["law"] == "frictmat" else LAW_CONSTANT
    law.kn = float(s.get("kn", 0.0)) if law.law == LAW_CONSTANT else 0.0
    law.kt = float(s.get("kt", 0.0)) if law.law == LAW_CONSTANT else 0.0
    law.young = float(s["young"]) if law.law == LAW_FRICTMAT else 0.0
    law.kt_over_kn = float(s["kt_over_kn"]) if law.law == LAW_FRICTMAT else 0.0
    return law


@dataclass(frozen=True, eq=False)
class DeviceConstants:
    """The model's constants on its device, in its float type (what the kernels read).

    Attributes:
        radius: disc radii [m], shape (B·N,). inv_mass [1/kg], inv_inertia [1/(kg·m²)]:
            shape (B·N,).
        timestep: time step per RVE [s], shape (B,). friction: μ = tan φ per RVE, (B,).
    """

    radius: wp.array
    inv_mass: wp.array
    inv_inertia: wp.array
    timestep: wp.array
    friction: wp.array


@dataclass(frozen=True, eq=False)
class Model:
    """Static description of B RVEs of N discs on one device.

    ``radius`` and ``timestep`` are the float64 host values the model was built from (the
    RVE file and the void ratio use them, exact even when the device runs in float32);
    ``constants`` holds what the kernels read, on the device.

    Attributes:
        device: warp device name ("cpu", "cuda", "cuda:0"). dtype: "float64" or "float32".
        n_rve: B. n_disc: N.
        meta: material parameters (friction, damping, stiffness law, density, thickness).
        radius: disc radii [m], shape (B, N), float64.
        timestep: time step per RVE [s], shape (B,), float64.
        explicit_timestep: True when the step was given (argument or file), not derived.
        skin: Verlet skin [m]. cutoff: largest pair reach 2·r_max + skin [m].
        capacity: neighbour slots per disc. max_bins: most contact-detection bins per axis.
        law: the contact stiffness law, as the kernels take it.
        constants: the device arrays.
    """

    device: str
    dtype: str
    n_rve: int
    n_disc: int
    meta: RVEMeta
    radius: np.ndarray
    timestep: np.ndarray
    explicit_timestep: bool
    skin: float
    cutoff: float
    capacity: int
    max_bins: int
    law: Any
    constants: DeviceConstants

    @property
    def float_type(self) -> Any:
        """The warp scalar type of the device arrays."""
        return float_type(self.dtype)

    def scalar(self, value: float) -> Any:
        """``value`` as a kernel argument of the model's float type."""
        return self.float_type(value)

    def with_friction(self, friction_angle: float) -> Model:
        """A model sharing every array but with friction angle ``friction_angle`` [rad]."""
        meta = replace(self.meta, friction_angle=friction_angle)
        meta.validate()
        mu = np.full(self.n_rve, math.tan(friction_angle))
        friction = wp.array(mu, dtype=self.float_type, device=self.device)
        return replace(self, meta=meta, constants=replace(self.constants, friction=friction))


def cell_heights(cell: np.ndarray) -> np.ndarray:
    """The smaller perpendicular height [m] of each cell (…, 2, 2) (columns = cell vectors):
    det H over the longer column's length. The engine stops an RVE whose contact cut-off is
    not below half of it (minimum images would no longer be unique)."""
    with np.errstate(all="ignore"):
        area = np.linalg.det(cell)
        lengths = np.linalg.norm(cell, axis=-2)  # |column 0|, |column 1|
        return np.minimum(area / lengths[..., 1], area / lengths[..., 0])


def _check_cell_heights(data: RVEData) -> None:
    """``RVEFileError`` where a cell is narrower than twice the contact cut-off 2·r_max + skin
    (the engine would stop at its first step: minimum images would no longer be unique)."""
    skin = SKIN_FRACTION * 2.0 * float(np.mean(data.radius))
    cutoff = 2.0 * float(np.max(data.radius)) + skin
    heights = cell_heights(data.cell)
    narrow = ~(cutoff < 0.5 * heights)  # NaN included
    if narrow.any():
        rve = int(np.argmax(narrow))
        raise RVEFileError(
            f"cell of RVE {rve} is too narrow for its discs: perpendicular height "
            f"{heights[rve]:.6g} m is not above twice the contact cut-off {cutoff:.6g} m"
        )


def float32_resolution(cell: np.ndarray) -> np.ndarray:
    """How far apart [m] float32 fractional coordinates place discs in each cell (…, 2, 2):
    2⁻²⁴ times the longer cell vector (the spacing of float32 numbers in [0.5, 1))."""
    return 2.0**-24 * np.linalg.norm(cell, axis=-2).max(axis=-1)


def median_overlap(data: RVEData) -> np.ndarray:
    """Median overlap [m] of the touching pairs of each RVE (B,); NaN where none touch."""
    out = np.full(data.n_rve, np.nan)
    for b in range(data.n_rve):
        frac = np.linalg.solve(data.cell[b], data.position[b].T).T
        frac -= np.floor(frac)
        _i, _j, dist2, reach = _touching_pairs(frac, data.cell[b], data.radius[b])
        if reach.size:
            out[b] = float(np.median(reach - np.sqrt(dist2)))
    return out


def _check_float32(data: RVEData) -> None:
    """``ValueError`` where float32 positions could not resolve an RVE's contacts: its
    :func:`float32_resolution` above :data:`FLOAT32_MAX_RESOLUTION` of its median overlap."""
    share = float32_resolution(data.cell) / median_overlap(data)
    coarse = share > FLOAT32_MAX_RESOLUTION  # NaN (no contact yet) passes
    if coarse.any():
        b = int(np.argmax(np.where(coarse, share, -np.inf)))
        raise ValueError(
            f"dtype float32 cannot resolve the contacts of RVE {b}: its cell is "
            f"{np.linalg.norm(data.cell[b], axis=0).max():.4g} m across, so float32 "
            f"fractional positions are {float32_resolution(data.cell[b]):.3g} m apart, "
            f"{share[b]:.2%} of its median contact overlap {median_overlap(data.take([b]))[0]:.3g}"
            f" m (at most {FLOAT32_MAX_RESOLUTION:.1%}): the contact forces would be rounding "
            f"noise ({int(coarse.sum())} RVE(s) in all); use float64, or smaller cells"
        )


def _check_speeds(data: RVEData, dt: np.ndarray) -> None:
    """``RVEFileError`` where a disc's velocity [m/s] (or its surface's, ω·r) would carry it
    more than r/4 in one step of ``dt`` [s]: the engine's blow-up limit, already passed."""
    limit = 0.25 * data.radius / dt[:, None]
    with np.errstate(over="ignore"):  # a speed of 1e300 m/s overflows to inf: refused too
        speeds = (("velocity", np.linalg.norm(data.velocity, axis=-1)),
                  ("angular_velocity", np.abs(data.angular_velocity) * data.radius))
    for name, speed in speeds:
        fast = speed > limit
        if fast.any():
            b, j = (int(v) for v in np.argwhere(fast)[0])
            raise RVEFileError(
                f"{name} of disc {j} of RVE {b} is beyond the engine's blow-up limit: "
                f"{speed[b, j]:.4g} m/s would move it more than r/4 in one time step "
                f"({dt[b]:.4g} s)"
            )


def build_model(
    data: RVEData,
    device: str | None = None,
    dtype: str = "float64",
    timestep: float | None = None,
    safety: float = DEFAULT_SAFETY,
    capacity: int = DEFAULT_CAPACITY,
) -> Model:
    """Build the static model of ``data`` on ``device``.

    The time step is ``timestep`` if given, else ``data.meta.timestep`` if present, else
    ``safety`` × :func:`critical_timestep` of each RVE's own discs. A step above the critical
    one, contact lists that do not fit ``capacity``, or a cell narrower than twice the
    contact cut-off raise ValueError (``RVEFileError`` for the data).
    """
    if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 1:
        raise ValueError(f"capacity must be a positive integer, got {capacity!r}")
    validate_rve(data, capacity)
    device = resolve_device(device)
    ft = float_type(dtype)
    meta = data.meta
    # per RVE, so that an RVE's time step (and result) never depends on its batch neighbours
    with np.errstate(all="ignore"):
        crit = np.array([critical_timestep(r, meta) for r in data.radius])
    if not (np.isfinite(crit) & (crit > 0)).all():
        raise RVEFileError(
            "meta.density, meta.thickness and meta.stiffness give no finite positive "
            f"critical time step (got {crit.min()!r} s): a value is out of range"
        )
    _check_cell_heights(data)
    if dtype == "float32":
        _check_float32(data)
    if timestep is None:
        timestep = meta.timestep
    if timestep is None:
        if not 0 < safety <= 1:
            raise ValueError(f"safety must lie in (0, 1], got {safety!r}")
        dt = safety * crit
    else:
        if not (math.isfinite(timestep) and timestep > 0):
            raise ValueError(f"timestep must be a positive number, got {timestep!r}")
        if (timestep > crit).any():
            rve = int(np.argmax(timestep > crit))
            raise ValueError(
                f"timestep {timestep:.4g} s is above the stable step {crit[rve]:.4g} s of "
                f"RVE {rve}"
            )
        dt = np.full(data.n_rve, float(timestep))
    _check_speeds(data, dt)
    r = data.radius.reshape(-1)
    mass = disc_mass(r, meta)
    inertia = 0.5 * mass * r**2
    mu = np.full(data.n_rve, math.tan(meta.friction_angle))
    constants = DeviceConstants(
        radius=wp.array(r, dtype=ft, device=device),
        inv_mass=wp.array(1.0 / mass, dtype=ft, device=device),
        inv_inertia=wp.array(1.0 / inertia, dtype=ft, device=device),
        timestep=wp.array(dt, dtype=ft, device=device),
        friction=wp.array(mu, dtype=ft, device=device),
    )
    skin = SKIN_FRACTION * 2.0 * float(np.mean(data.radius))
    return Model(
        device=device,
        dtype=dtype,
        n_rve=data.n_rve,
        n_disc=data.n_disc,
        meta=meta,
        radius=np.array(data.radius, dtype=np.float64),
        timestep=dt,
        explicit_timestep=timestep is not None,
        skin=skin,
        cutoff=2.0 * float(np.max(data.radius)) + skin,
        capacity=capacity,
        # about one disc a bin at most; bins are never narrower than the cut-off
        max_bins=max(3, math.ceil(math.sqrt(data.n_disc))),
        law=contact_law(meta),
        constants=constants,
    )
