"""Model (static parameters, read-only once built) and State (what evolves) of a DEM batch."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import warp as wp

from granular_material.dem.kernels import LAW_CONSTANT, LAW_FRICTMAT, kernels_for
from granular_material.dem.rve_file import RVEData, RVEMeta

__all__ = [
    "DEFAULT_CAPACITY",
    "DEFAULT_SAFETY",
    "Model",
    "State",
    "build_model",
    "critical_timestep",
    "disc_mass",
    "resolve_device",
    "state_from_data",
]

DEFAULT_CAPACITY = 16  #: neighbour-list slots per disc (a dense 400-disc packing uses <= 8)
DEFAULT_SAFETY = 0.3  #: default time step as a fraction of the critical one
SKIN_FRACTION = 0.25  #: Verlet skin as a fraction of the mean disc diameter


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


def _float_type(dtype: str) -> Any:
    if dtype == "float64":
        return wp.float64
    if dtype == "float32":
        return wp.float32
    raise ValueError(f"dtype must be 'float64' or 'float32', got {dtype!r}")


def disc_mass(radius: np.ndarray, meta: RVEMeta) -> np.ndarray:
    """Mass [kg] of discs of ``radius`` [m]: cylinders ρ·t·π·r² (DESIGN §3), same shape."""
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


@dataclass(frozen=True, eq=False)
class Model:
    """Static description of B RVEs of N discs on one device.

    Attributes:
        device: warp device name ("cpu", "cuda", "cuda:0").
        dtype: "float64" or "float32".
        n_rve: B. n_disc: N.
        meta: material parameters (friction, damping, stiffness law, density, thickness).
        dt: time step per RVE [s], numpy, shape (B,), float64; ``timestep`` the same on
            the device. explicit_timestep: True when given (argument or file), not derived.
        skin: Verlet skin [m]. cutoff: largest pair reach 2·r_max + skin [m].
        capacity: neighbour slots per disc.
        max_bins: largest number of contact-detection bins per cell axis.
        radius: disc radii [m], shape (B·N,), float. inv_mass [1/kg], inv_inertia
            [1/(kg·m²)]: shape (B·N,).
        friction: μ = tan φ per RVE, shape (B,).
        radius_host: radii [m] as numpy, shape (B, N), float64.
        replica: which copy of the kernel module this model's launches use (one per
            CPU shard, see :func:`kernels_for`).
    """

    device: str
    dtype: str
    n_rve: int
    n_disc: int
    meta: RVEMeta
    dt: np.ndarray
    timestep: wp.array
    explicit_timestep: bool
    skin: float
    cutoff: float
    capacity: int
    max_bins: int
    radius: wp.array
    inv_mass: wp.array
    inv_inertia: wp.array
    friction: wp.array
    radius_host: np.ndarray
    replica: int = 0

    @property
    def kernels(self) -> Any:
        """The kernel set for this model's float type and replica."""
        return kernels_for(_float_type(self.dtype), self.replica)

    @property
    def law_args(self) -> list:
        """Stiffness-law arguments of the force kernels: law id, kn, kt, E, kt/kn."""
        s = self.meta.stiffness
        if s["law"] == "frictmat":
            return [LAW_FRICTMAT, 0.0, 0.0, float(s["young"]), float(s["kt_over_kn"])]
        return [LAW_CONSTANT, float(s["kn"]), float(s["kt"]), 0.0, 0.0]

    def with_friction(self, friction_angle: float) -> Model:
        """A model sharing every array but with friction angle ``friction_angle`` [rad]."""
        meta = RVEMeta(**{**_meta_dict(self.meta), "friction_angle": friction_angle})
        meta.validate()
        mu = np.full(self.n_rve, math.tan(friction_angle))
        friction = wp.array(mu, dtype=self.kernels.float_type, device=self.device)
        return Model(**{**_field_dict(self), "meta": meta, "friction": friction})


def _meta_dict(meta: RVEMeta) -> dict:
    return {f.name: getattr(meta, f.name) for f in fields(meta)}


def _field_dict(obj: Any) -> dict:
    return {f.name: getattr(obj, f.name) for f in fields(obj)}


def build_model(
    data: RVEData,
    device: str | None = None,
    dtype: str = "float64",
    timestep: float | None = None,
    safety: float = DEFAULT_SAFETY,
    capacity: int = DEFAULT_CAPACITY,
    replica: int = 0,
) -> Model:
    """Build the static model of ``data`` on ``device``.

    The time step is ``timestep`` if given, else ``data.meta.timestep`` if present, else
    ``safety`` × :func:`critical_timestep` of each RVE's own discs. A step above the critical
    one raises ValueError.
    """
    data.validate()
    device = resolve_device(device)
    ft = kernels_for(_float_type(dtype), replica).float_type
    meta = data.meta
    # per RVE, so that an RVE's time step (and result) never depends on its batch neighbours
    crit = np.array([critical_timestep(r, meta) for r in data.radius])
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
    r = data.radius.reshape(-1)
    mass = disc_mass(r, meta)
    inertia = 0.5 * mass * r**2
    skin = SKIN_FRACTION * 2.0 * float(np.mean(data.radius))
    cutoff = 2.0 * float(np.max(data.radius)) + skin
    mu = np.full(data.n_rve, math.tan(meta.friction_angle))
    return Model(
        device=device,
        dtype=dtype,
        n_rve=data.n_rve,
        n_disc=data.n_disc,
        meta=meta,
        dt=dt,
        timestep=wp.array(dt, dtype=ft, device=device),
        explicit_timestep=timestep is not None,
        skin=skin,
        cutoff=cutoff,
        capacity=capacity,
        # about one disc a bin at most; bins are never narrower than the cut-off
        max_bins=max(3, math.ceil(math.sqrt(data.n_disc))),
        radius=wp.array(r, dtype=ft, device=device),
        inv_mass=wp.array(1.0 / mass, dtype=ft, device=device),
        inv_inertia=wp.array(1.0 / inertia, dtype=ft, device=device),
        friction=wp.array(mu, dtype=ft, device=device),
        radius_host=np.array(data.radius, dtype=np.float64),
        replica=replica,
    )


@dataclass(eq=False)
class State:
    """Everything that evolves, on the model's device. Flat particle index ``b·N + j``.

    Attributes:
        frac: fractional positions s = H⁻¹x in [0, 1)², shape (B·N,), vec2.
        vel: fluctuating velocities [m/s], (B·N,), vec2. ang_vel: [rad/s], (B·N,).
        cell: cell matrices H [m] (columns = cell vectors), (B,), mat22.
        nbr: neighbour slots (partner's index within its RVE), (B·N·K,), int32;
            nbr_count: used slots per disc, (B·N,), int32.
        shear: tangential spring force per slot [N], (B·N·K,).
        disp: fluctuating displacement since the last list build [m], (B·N,), vec2.
        cell_ref: cell at the last list build, (B,), mat22.
        force_rebuild: 1 where the next step must rebuild the lists, (B,), int32.
        status: error bits per RVE (kernels.STATUS_*), (B,), int32.
    """

    frac: wp.array
    vel: wp.array
    ang_vel: wp.array
    cell: wp.array
    nbr: wp.array
    nbr_count: wp.array
    shear: wp.array
    disp: wp.array
    cell_ref: wp.array
    force_rebuild: wp.array
    status: wp.array

    def clone(self) -> State:
        """A device copy of every array."""
        return State(**{f.name: wp.clone(getattr(self, f.name)) for f in fields(self)})

    def assign(self, other: State) -> None:
        """Copy ``other``'s arrays into this state's arrays, in place."""
        for f in fields(self):
            wp.copy(getattr(self, f.name), getattr(other, f.name))


#: further arrays of the RVE file that make a resumed run bit-identical to an uninterrupted one
HISTORY_KEYS = (
    "contact_partner",  # (B, N, K) int32, partner index within the RVE, -1 = empty slot
    "contact_count",  # (B, N) int32, used slots
    "contact_shear_force",  # (B, N, K) float64, tangential spring force [N]
    "fractional_position",  # (B, N, 2) float64, s = H⁻¹x in [0, 1)
    "verlet_displacement",  # (B, N, 2) float64, displacement since the last list build [m]
    "cell_at_list_build",  # (B, 2, 2) float64, H at the last list build [m]
)


def state_from_data(model: Model, data: RVEData) -> State:
    """Upload the dynamic arrays of ``data`` (and its contact history if present)."""
    ks = model.kernels
    dev = model.device
    b, n, k = model.n_rve, model.n_disc, model.capacity
    inv = np.linalg.inv(data.cell)
    frac = np.einsum("bij,bnj->bni", inv, data.position)
    frac -= np.floor(frac)
    nbr = np.full((b, n, k), -1, dtype=np.int32)
    count = np.zeros((b, n), dtype=np.int32)
    shear = np.zeros((b, n, k))
    disp = np.zeros((b, n, 2))
    cell_ref = np.array(data.cell)
    resume = all(key in data.extra for key in HISTORY_KEYS)
    if resume:
        stored = np.asarray(data.extra["fractional_position"], dtype=np.float64)
        drift = np.abs(np.einsum("bij,bnj->bni", data.cell, stored) - data.position).max()
        if stored.shape != frac.shape or drift > 1e-9:
            raise ValueError("fractional_position does not match position and cell")
        frac = stored
        disp = np.asarray(data.extra["verlet_displacement"], dtype=np.float64)
        cell_ref = np.asarray(data.extra["cell_at_list_build"], dtype=np.float64)
        partner = np.asarray(data.extra["contact_partner"], dtype=np.int32)
        width = min(partner.shape[-1], k)
        if partner.shape[:2] != (b, n):
            raise ValueError(
                f"contact_partner has shape {partner.shape}, expected ({b}, {n}, K)"
            )
        nbr[..., :width] = partner[..., :width]
        count[:] = np.minimum(np.asarray(data.extra["contact_count"], dtype=np.int32), width)
        shear[..., :width] = np.asarray(data.extra["contact_shear_force"])[..., :width]
    return State(
        frac=wp.array(frac.reshape(-1, 2), dtype=ks.vec2, device=dev),
        vel=wp.array(data.velocity.reshape(-1, 2), dtype=ks.vec2, device=dev),
        ang_vel=wp.array(data.angular_velocity.reshape(-1), dtype=ks.float_type, device=dev),
        cell=wp.array(data.cell, dtype=ks.mat22, device=dev),
        nbr=wp.array(nbr.reshape(-1), dtype=wp.int32, device=dev),
        nbr_count=wp.array(count.reshape(-1), dtype=wp.int32, device=dev),
        shear=wp.array(shear.reshape(-1), dtype=ks.float_type, device=dev),
        disp=wp.array(disp.reshape(-1, 2), dtype=ks.vec2, device=dev),
        cell_ref=wp.array(cell_ref, dtype=ks.mat22, device=dev),
        force_rebuild=wp.array(np.full(b, 0 if resume else 1), dtype=wp.int32, device=dev),
        status=wp.zeros(b, dtype=wp.int32, device=dev),
    )
