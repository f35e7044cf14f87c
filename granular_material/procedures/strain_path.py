"""Strain paths of DEM batches: a displacement gradient applied over Guo & Zhao's steps.

Every RVE of a batch is treated independently (an RVE that has finished its path is frozen
while the others go on), so an RVE's result never depends on its batch neighbours.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from granular_material.dem import DEMBatch, DEMInstabilityError
from granular_material.dem.loading import expm_2x2
from granular_material.dem.model import cell_heights
from granular_material.reference_values import (
    DEFAULT_MAX_DEM_STEPS,
    DEFAULT_STRAIN_PER_STEP,
    STEP_LIMIT,
)

__all__ = [
    "DEFAULT_MAX_DEM_STEPS",
    "DEFAULT_MIN_STEPS",
    "DEFAULT_STRAIN_PER_STEP",
    "STEP_LIMIT",
    "CellTooThinError",
    "DrivePlan",
    "RVECollapseError",
    "drive_grad_u",
    "drive_planned",
    "has_real_logarithm",
    "log_deformation",
    "over_step_cap",
    "path_increment",
    "path_steps",
    "plan_drive",
]




#: the fewest DEM steps of a path (its increments: the velocity gradient is then resolved)
DEFAULT_MIN_STEPS = 2


#: points along a path at which :func:`drive_grad_u` checks the cell's heights beforehand
PATH_CHECKS = 32


class CellTooThinError(DEMInstabilityError, ValueError):
    """A ∇u that :func:`drive_grad_u` refuses before any step: along its path a cell's
    perpendicular height would fall to twice the contact cut-off, where the engine stops.

    An input error (a ``ValueError``), and a :class:`DEMInstabilityError` naming the RVEs
    (``rve``), so that a caller that treats failed RVEs (the FEM's DEM material: Newton
    cuts the increment back) does so without a step having been run.
    """

    def __init__(self, rve: list[int], message: str) -> None:
        self.rve = rve
        self.reasons = [message]
        RuntimeError.__init__(self, message)


class RVECollapseError(DEMInstabilityError):
    """A ∇u that would press an RVE's cell to no more area than its discs' (void ratio
    e = det H / Σπr² − 1 ≤ 0: overlaps far beyond the contact law's validity): refused by
    :func:`drive_grad_u` before any step, a failed run (exit 1) naming the RVEs, as a blow-up
    is; a caller that treats failed RVEs (the FEM's DEM material) cuts back."""

    def __init__(self, rve: list[int], message: str) -> None:
        self.rve = rve
        self.reasons = [message]
        RuntimeError.__init__(self, message)


def _check_collapse(batch: DEMBatch, g: np.ndarray, active: np.ndarray) -> None:
    """``RVECollapseError`` naming the RVEs whose cell (I + ∇u)·H would leave no void."""
    solid = np.pi * np.concatenate([np.sum(s.model.radius**2, axis=1) for s in batch.shards])
    area = np.linalg.det(np.eye(2) + g) * np.linalg.det(batch.cell())
    void = area / solid - 1.0
    collapsed = ~(void > 0) & active
    if not collapsed.any():
        return
    rves = np.flatnonzero(collapsed)
    shown = ", ".join(f"{b} (e = {void[b]:.3g})" for b in rves[:5])
    raise RVECollapseError(
        rves.tolist(),
        f"grad_u would collapse RVE(s) {shown}{' ...' if rves.size > 5 else ''}: a void "
        f"ratio <= 0, its cell no larger than its discs (overlaps far beyond the contact "
        f"law); refused before any step ({rves.size} RVE(s) in all): apply less "
        "compression")


def _check_path_heights(batch: DEMBatch, log_f: np.ndarray, active: np.ndarray) -> None:
    """``CellTooThinError`` naming the RVEs whose cell H(s) = exp(s·log F)·H, s in (0, 1]
    (the path :func:`drive_grad_u` takes), gets a perpendicular height [m] not above twice
    the contact cut-off (checked at :data:`PATH_CHECKS` points and at the end)."""
    cell = batch.cell()
    s = np.arange(1, PATH_CHECKS + 1) / PATH_CHECKS
    maps = expm_2x2(s[:, None, None, None] * log_f[None])  # (S, B, 2, 2)
    heights = cell_heights(maps @ cell[None])  # (S, B)
    limit = 2.0 * batch.cutoff
    thin = ~(heights > limit[None]) & active[None]  # NaN included
    if not thin.any():
        return
    rves = np.flatnonzero(thin.any(axis=0))
    b = int(rves[0])
    first = int(np.argmax(thin[:, b]))
    raise CellTooThinError(
        rves.tolist(),
        f"grad_u of RVE {b} thins its cell below twice the contact cut-off: its "
        f"perpendicular height would fall from {cell_heights(cell[b]):.4g} m to "
        f"{heights[first, b]:.4g} m at {s[first]:.0%} of the path, where the engine needs "
        f"more than 2 × {batch.cutoff[b]:.4g} m (cell {cell[b].tolist()} m); refused before "
        f"any step ({len(rves)} RVE(s) in all): apply less in one path, or use more discs",
    )


def _as_batch_grad(batch: DEMBatch, grad_u: np.ndarray) -> np.ndarray:
    g = np.asarray(grad_u, dtype=np.float64)
    if g.shape == (2, 2):
        g = np.repeat(g[None], batch.n_rve, axis=0)
    if g.shape != (batch.n_rve, 2, 2):
        raise ValueError(f"grad_u must have shape (2, 2) or ({batch.n_rve}, 2, 2), got {g.shape}")
    if not np.isfinite(g).all():
        rve = int(np.argwhere(~np.isfinite(g))[0][0])
        raise ValueError(f"grad_u of RVE {rve} is not finite: {g[rve].tolist()}")
    det = np.linalg.det(np.eye(2) + g)
    if (det <= 0).any():
        rve = int(np.argmax(det <= 0))
        raise ValueError(
            f"grad_u of RVE {rve} inverts the cell: det(I + grad_u) = {det[rve]:.4g} <= 0"
        )
    return g


def has_real_logarithm(f: np.ndarray) -> np.ndarray:
    """Whether each F (B, 2, 2) has a real logarithm, i.e. the constant velocity gradient of
    :func:`drive_grad_u` exists: det F > 0 and no negative real eigenvalue."""
    trace, det = np.trace(f, axis1=1, axis2=2), np.linalg.det(f)
    discriminant = trace**2 - 4 * det
    # real eigenvalues (discriminant >= 0) share the sign of the trace when det > 0
    return (det > 0) & ((discriminant < 0) | (trace > 0))


def log_deformation(grad_u: np.ndarray) -> np.ndarray:
    """The real logarithm log(I + ∇u) [-] of every ∇u (B, 2, 2), in closed form.

    Where :func:`has_real_logarithm` holds. With F = m·I + A (m = tr F/2, A traceless, so
    A² = q·I, q = −det A), every function of F is a·I + c·A: log F = ½ log(det F)·I + c·A
    with c = atanh(√q/m)/√q for q > 0, atan2(√−q, m)/√−q for q < 0, and the series
    (1/m)·Σ (q/m²)ᵏ/(2k + 1) near q = 0. Everything is formed from ∇u itself (log1p of
    det F − 1), so an increment of 1e-7 keeps its digits; scipy's ``logm`` lost some, and
    cost 2–25 ms a matrix here, which 10 000 RVEs turned into minutes.
    """
    g = np.asarray(grad_u, dtype=np.float64)
    half_trace = 0.5 * (g[:, 0, 0] + g[:, 1, 1])
    m = 1.0 + half_trace
    a = g - half_trace[:, None, None] * np.eye(2)
    q = a[:, 0, 0] ** 2 + a[:, 0, 1] * a[:, 1, 0]
    det_minus_one = 2.0 * half_trace + g[:, 0, 0] * g[:, 1, 1] - g[:, 0, 1] * g[:, 1, 0]
    with np.errstate(all="ignore"):  # the branches not taken may divide by zero
        x = q / (m * m)
        root = np.sqrt(np.abs(q))
        series = (1.0 + x * (1.0 / 3.0 + x * (1.0 / 5.0 + x * (1.0 / 7.0 + x / 9.0)))) / m
        c = np.where(q > 0, np.arctanh(root / m) / root, np.arctan2(root, m) / root)
        c = np.where((m > 0) & (np.abs(x) < 1e-3), series, c)
    return 0.5 * np.log1p(det_minus_one)[:, None, None] * np.eye(2) + c[:, None, None] * a


def path_increment(grad_u: np.ndarray, k: int, increments: int) -> np.ndarray:
    """∇u of increment ``k`` (1…K) of a path to the total ``grad_u`` in K equal steps of F.

    Measured from the configuration after increment k − 1, as :func:`drive_grad_u` takes it:
    ``F_k F_(k-1)⁻¹ − I`` with ``F_k = I + (k/K)·grad_u``, so that the K increments compose
    to ``I + grad_u`` exactly. ``grad_u`` has shape (2, 2) or (B, 2, 2).
    """
    if not 1 <= k <= increments:
        raise ValueError(f"increment k must lie in [1, {increments}], got {k}")
    g = np.asarray(grad_u, dtype=np.float64)
    f_now = np.eye(2) + g * (k - 1) / increments
    f_next = np.eye(2) + g * k / increments
    return f_next @ np.linalg.inv(f_now) - np.eye(2)


def _wanted_steps(grad_u: np.ndarray, max_strain_per_step: float,
                  min_steps: int) -> np.ndarray:
    """Uncapped step counts ``max(ceil(max|∇u_b| / max_strain_per_step), min_steps)``, float."""
    if not (math.isfinite(max_strain_per_step) and max_strain_per_step > 0):
        raise ValueError(f"max_strain_per_step must be positive, got {max_strain_per_step!r}")
    if min_steps < 1:
        raise ValueError(f"min_steps must be >= 1, got {min_steps}")
    g = np.asarray(grad_u, dtype=np.float64)
    if g.size == 0:
        return np.zeros(0)
    return np.maximum(np.ceil(np.abs(g).max(axis=(1, 2)) / max_strain_per_step), min_steps)


def _cap(max_steps: int | None) -> int:
    return STEP_LIMIT if max_steps is None else min(int(max_steps), STEP_LIMIT)


def over_step_cap(grad_u: np.ndarray, max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
                  min_steps: int = DEFAULT_MIN_STEPS, max_steps: int | None = None) -> np.ndarray:
    """Which RVEs' paths to ∇u (B, 2, 2) would need more than ``max_steps`` DEM steps (or
    more than 10¹⁵, where the count stops being an integer), shape (B,), bool."""
    return _wanted_steps(grad_u, max_strain_per_step, min_steps) > _cap(max_steps)


def path_steps(grad_u: np.ndarray, max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
               min_steps: int = DEFAULT_MIN_STEPS, max_steps: int | None = None) -> np.ndarray:
    """DEM steps of each RVE's path to ∇u (B, 2, 2): ``max(ceil(max|∇u_b| / max_strain_per_step),
    min_steps)``, shape (B,), int64.

    ``ValueError`` naming the RVE when a path would need more than ``max_steps`` steps (or
    more than 10¹⁵, where the count stops being an integer).
    """
    g = np.asarray(grad_u, dtype=np.float64)
    wanted = _wanted_steps(g, max_strain_per_step, min_steps)
    cap = _cap(max_steps)
    if (wanted > cap).any():
        rve = int(np.argmax(wanted))
        raise ValueError(
            f"grad_u of RVE {rve} (max |grad_u| = {np.abs(g[rve]).max():.4g}) needs "
            f"{wanted[rve]:.4g} DEM steps at {max_strain_per_step:g} strain a step, more than "
            f"the cap of {cap} (max_dem_steps); apply it in load steps, or raise the cap"
        )
    return wanted.astype(np.int64)


def drive_grad_u(
    batch: DEMBatch,
    grad_u: np.ndarray,
    max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
    min_steps: int = DEFAULT_MIN_STEPS,
    active: np.ndarray | None = None,
    max_steps: int | None = None,
) -> int:
    """Apply the displacement gradient ∇u to every RVE, measured from its current state.

    RVE b is deformed over ``n_b`` steps (:func:`path_steps`; Guo & Zhao 2014: at most 1e-5
    strain a step) with the constant velocity gradient ``L = log(I + ∇u)/(n_b·dt)``, so a
    rigid rotation stays a rotation all along; at the end its cell is exactly ``(I + ∇u)·H``.
    Returns the largest ``n_b`` (steps run). It shows no progress (it runs on every Newton
    iteration); a caller that drives one long path in increments can show a bar over them.

    Refused before any step (``ValueError``): a non-finite ∇u, one that inverts the cell or
    has no real logarithm, a path over ``max_steps``, and (:class:`CellTooThinError`, which
    is also a :class:`DEMInstabilityError` naming the RVEs) a path that would thin a cell to
    twice its contact cut-off (a simple shear past |H01/H11| ≈ 2.2 for 64 discs of 3–7 mm,
    0.35 for 12).

    Args:
        grad_u: ∇u [-], shape (B, 2, 2) or (2, 2) for all RVEs; ``grad_u[b, i, j] = ∂u_i/∂x_j``.
        active: which RVEs are driven, shape (B,), bool; the others are left exactly as
            they are (not stepped, their ∇u ignored). None: all.
        max_steps: cap on any RVE's step count (``ValueError`` beyond it); None: no cap but
            the integer limit.
    """
    n_rve = batch.n_rve
    active = np.ones(n_rve, bool) if active is None else np.asarray(active, dtype=bool)
    if active.shape != (n_rve,):
        raise ValueError(f"active must have shape ({n_rve},), got {active.shape}")
    g = _as_batch_grad(batch, grad_u)
    g = np.where(active[:, None, None], g, 0.0)
    n_steps = np.where(active, path_steps(g, max_strain_per_step, min_steps, max_steps), 0)
    if not active.any():
        return 0
    real = has_real_logarithm(np.eye(2) + g)
    if not real.all():
        b = int(np.argmax(~real))
        raise ValueError(f"grad_u of RVE {b} has no real logarithm (I + grad_u turns by half a "
                         f"turn or more, or has a negative eigenvalue): {g[b].tolist()}")
    return drive_planned(batch, DrivePlan(g, n_steps.astype(np.int64), active,
                                          np.zeros(n_rve, bool), np.zeros(n_rve, bool)))


@dataclass(frozen=True)
class DrivePlan:
    """Each RVE's path to a ∇u, planned once before any step (:func:`plan_drive`) and handed
    to :func:`drive_planned`.

    Attributes:
        grad_u: ∇u [-] of the driven RVEs, zero for the others, shape (B, 2, 2), float64.
        steps: DEM steps of each driven RVE's path, 0 for the others, shape (B,), int64.
        driven: the RVEs that are stepped, shape (B,), bool.
        inverted: RVEs asked to move whose I + ∇u has no real logarithm (it inverts the
            cell or turns it by half a turn or more), shape (B,), bool.
        capped: RVEs asked to move, not inverted, whose path needs more DEM steps than the
            cap, shape (B,), bool.
    """

    grad_u: np.ndarray
    steps: np.ndarray
    driven: np.ndarray
    inverted: np.ndarray
    capped: np.ndarray

    def particle_steps(self, n_disc: int) -> int:
        """Disc-steps [-] of the plan: Σ over the driven RVEs of their steps × ``n_disc``."""
        return int(self.steps[self.driven].sum()) * n_disc


def plan_drive(grad_u: np.ndarray, active: np.ndarray,
               max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
               min_steps: int = DEFAULT_MIN_STEPS, max_steps: int | None = None) -> DrivePlan:
    """The paths of the ``active`` RVEs (B,) to ∇u [-] (B, 2, 2, finite): those that cannot
    take it (no real logarithm; over ``max_steps``) are marked instead of refused, and the
    others are planned as :func:`drive_grad_u` steps them."""
    g = np.asarray(grad_u, dtype=np.float64)
    active = np.asarray(active, dtype=bool)
    inverted = active & ~has_real_logarithm(np.eye(2) + g)
    capped = active & ~inverted & over_step_cap(g, max_strain_per_step, min_steps, max_steps)
    driven = active & ~inverted & ~capped
    g = np.where(driven[:, None, None], g, 0.0)
    steps = np.zeros(len(g), dtype=np.int64)
    if driven.any():
        steps = np.where(driven, path_steps(g, max_strain_per_step, min_steps, max_steps), 0)
    return DrivePlan(g, steps, driven, inverted, capped)


def drive_planned(batch: DEMBatch, plan: DrivePlan) -> int:
    """Step the driven RVEs of ``plan`` along their paths from their current states, each by
    the constant velocity gradient log(I + ∇u)/(n_b·dt) (see :func:`drive_grad_u`); the
    others are left exactly as they are. Returns the largest step count run (0: none).
    :class:`CellTooThinError` or :class:`RVECollapseError` before any step for a path the
    cell cannot take."""
    active, g, n_steps = plan.driven, plan.grad_u, plan.steps
    n_rve = batch.n_rve
    if not active.any():
        return 0
    dt = batch.dt
    _check_collapse(batch, g, active)
    log_f = log_deformation(g)
    _check_path_heights(batch, log_f, active)
    steps_dt = np.where(active, n_steps * dt, 1.0)
    vel_grad = log_f / steps_dt[:, None, None]
    cell0 = batch.cell()
    batch.set_affine(vel_grad)
    done = 0
    try:
        for stop in np.unique(n_steps[active]):
            batch.set_active(n_steps > done)
            batch.run(int(stop) - done)
            done = int(stop)
    finally:
        batch.set_active(np.ones(n_rve))
        batch.set_affine(np.zeros_like(g))
    # the cells already are (I + ∇u)·H up to rounding: make that exact, lists stay valid
    # (a frozen RVE's ∇u is 0 here: its cell is written back unchanged)
    batch.set_cell(np.einsum("bij,bjk->bik", np.eye(2) + g, cell0), refresh=False)
    return int(n_steps.max())
