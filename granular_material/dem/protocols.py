"""Loading protocols of DEM batches: strain-driven ∇u, stress servo, consolidation, biaxial.

Every protocol treats the RVEs of a batch independently: an RVE's result never depends on its
batch neighbours (an RVE that has finished its part is frozen while the others go on).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.linalg import logm
from tqdm.auto import tqdm

from granular_material.dem.batch import DEMBatch
from granular_material.dem.solver import CONTROL_STRAIN, CONTROL_STRESS

__all__ = [
    "BiaxialSummary",
    "biaxial_test",
    "consolidate",
    "drive_grad_u",
    "has_real_logarithm",
    "path_increment",
    "servo_steps",
    "summarize_biaxial",
]


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


def drive_grad_u(
    batch: DEMBatch,
    grad_u: np.ndarray,
    max_strain_per_step: float = 1.0e-5,
    min_steps: int = 2,
    progress: bool = False,
) -> int:
    """Apply the displacement gradient ∇u to every RVE, measured from its current state.

    RVE b is deformed over ``n_b = max(ceil(max|∇u_b| / max_strain_per_step), min_steps)``
    steps (Guo & Zhao 2014: at most 1e-5 strain a step) with the constant velocity gradient
    ``L = log(I + ∇u)/(n_b·dt)``, so a rigid rotation stays a rotation all along; at the end
    its cell is exactly ``(I + ∇u)·H``. Returns the largest ``n_b`` (steps run).

    Args:
        grad_u: ∇u [-], shape (B, 2, 2) or (2, 2) for all RVEs; ``grad_u[b, i, j] = ∂u_i/∂x_j``.
    """
    if not (math.isfinite(max_strain_per_step) and max_strain_per_step > 0):
        raise ValueError(f"max_strain_per_step must be positive, got {max_strain_per_step!r}")
    if min_steps < 1:
        raise ValueError(f"min_steps must be >= 1, got {min_steps}")
    g = _as_batch_grad(batch, grad_u)
    n_steps = np.maximum(np.ceil(np.abs(g).max(axis=(1, 2)) / max_strain_per_step), min_steps)
    n_steps = n_steps.astype(np.int64)
    dt = batch.dt
    vel_grad = np.empty_like(g)
    for b in range(batch.n_rve):
        log_f = logm(np.eye(2) + g[b])
        if np.iscomplexobj(log_f):
            if np.abs(log_f.imag).max() > 1e-12:
                raise ValueError(f"grad_u of RVE {b} has no real logarithm: {g[b].tolist()}")
            log_f = log_f.real
        vel_grad[b] = log_f / (n_steps[b] * dt[b])
    cell0 = batch.cell()
    batch.set_affine(vel_grad)
    done = 0
    bar = tqdm(total=int(n_steps.max()), desc="strain path", unit="step", disable=not progress)
    try:
        for stop in np.unique(n_steps):
            batch.set_active(n_steps > done)
            batch.run(int(stop) - done)
            bar.update(int(stop) - done)
            done = int(stop)
    finally:
        bar.close()
        batch.set_active(np.ones(batch.n_rve))
        batch.set_affine(np.zeros_like(g))
    # the cells already are (I + ∇u)·H up to rounding: make that exact, lists stay valid
    batch.set_cell(np.einsum("bij,bjk->bik", np.eye(2) + g, cell0), refresh=False)
    return int(n_steps.max())


def servo_steps(
    batch: DEMBatch,
    steps: int,
    target: np.ndarray,
    control: np.ndarray,
    gain: float = 0.2,
    max_strain: float = 1.0e-4,
    check_every: int = 200,
    callback: Callable[[int], bool | None] | None = None,
) -> int:
    """Run ``steps`` steps under mixed control of the diagonal components (see Solver)."""
    batch.set_servo(control, target, gain=gain, max_strain=max_strain)
    try:
        return batch.run(steps, check_every=check_every, callback=callback)
    finally:
        batch.set_affine(np.zeros((batch.n_rve, 2, 2)))


def consolidate(
    batch: DEMBatch,
    pressure: float,
    tolerance: float = 0.01,
    max_unbalanced: float = 0.02,
    max_steps: int = 400_000,
    max_strain: float = 1.0e-4,
    gain: float = 0.2,
    check_every: int = 500,
    stop_void_ratio: float | None = None,
    progress: bool = False,
) -> int:
    """Isotropic consolidation of every RVE to mean stress −``pressure`` [Pa].

    An RVE is done when both σxx and σyy are within ``tolerance``·pressure of −pressure and its
    unbalanced-force ratio is below ``max_unbalanced`` — or, with ``stop_void_ratio``, as soon
    as its void ratio falls to that value; it is then frozen while the others go on. Raises
    RuntimeError naming the RVEs that did not get there in ``max_steps``. Returns the steps run.
    """
    if not (math.isfinite(pressure) and pressure > 0):
        raise ValueError(f"pressure must be a positive number [Pa], got {pressure!r}")
    b = batch.n_rve
    target = np.full((b, 2), -float(pressure))
    control = np.full((b, 2), CONTROL_STRESS)
    done = np.zeros(b, dtype=bool)
    bar = tqdm(total=b, desc=f"consolidating to {pressure:.3g} Pa", unit="rve",
               disable=not progress)

    def converged(steps_done: int) -> bool:
        h = batch.homogenize()
        diag = np.stack([h.stress[:, 0, 0], h.stress[:, 1, 1]], axis=1)
        ok = (np.abs(diag + pressure) <= tolerance * pressure).all(axis=1)
        ok &= h.unbalanced_force <= max_unbalanced
        if stop_void_ratio is not None:
            ok |= h.void_ratio <= stop_void_ratio
        newly = ok & ~done
        done[newly] = True
        bar.update(int(newly.sum()))
        bar.set_postfix(p=f"{-h.mean_stress.mean():.4g}",
                        unbalanced=f"{h.unbalanced_force.max():.2g}")
        batch.set_active(~done)
        return bool(done.all())

    try:
        steps = servo_steps(batch, max_steps, target, control, gain=gain, max_strain=max_strain,
                            check_every=check_every, callback=converged)
    finally:
        bar.close()
        batch.set_active(np.ones(b))
    if not done.all():
        missing = np.flatnonzero(~done).tolist()
        raise RuntimeError(
            f"consolidation to {pressure:.4g} Pa did not converge in {max_steps} steps for "
            f"RVE(s) {missing}"
        )
    return steps


def biaxial_test(
    batch: DEMBatch,
    axial_strain: float = 0.1,
    confining: float = 100.0e3,
    strain_per_step: float = 1.0e-5,
    record_every: int = 100,
    gain: float = 0.5,
    progress: bool = False,
) -> pd.DataFrame:
    """Drained biaxial test: σxx held at −``confining`` while εyy is driven in compression.

    Args:
        axial_strain: final axial (yy) compressive strain [-], engineering.
        confining: lateral stress magnitude [Pa].
        strain_per_step: largest axial (logarithmic) strain per step [-].
        record_every: steps between recorded rows.
        gain: servo gain on σxx (0.5 holds it within 0.8 % of ``confining`` on the 400-disc
            Guo & Zhao RVE; YADE's PeriTriaxController holds 1.2–1.5 %).

    Returns:
        One row per record and RVE: ``rve``, ``step``, ``axial_strain`` (compression
        positive), ``lateral_strain``, ``volumetric_strain`` (area change, tension positive),
        ``sxx``, ``syy``, ``sxy`` [Pa] (tension positive), ``stress_ratio`` σ1/σ3 = syy/sxx,
        ``void_ratio``, ``coordination``.
    """
    for name, value in (("axial_strain", axial_strain), ("confining", confining),
                        ("strain_per_step", strain_per_step)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, got {value!r}")
    if axial_strain >= 0.9:
        raise ValueError(f"axial_strain must be below 0.9, got {axial_strain!r}")
    b = batch.n_rve
    cell0 = batch.cell()
    area0 = np.linalg.det(cell0)
    # n equal logarithmic steps ending exactly at the requested engineering strain
    total = math.ceil(-math.log1p(-axial_strain) / strain_per_step)
    step_strain = (1.0 - axial_strain) ** (1.0 / total) - 1.0
    rows: list[pd.DataFrame] = []

    def record(step: int) -> None:
        h = batch.homogenize()
        cell = batch.cell()
        rows.append(pd.DataFrame({
            "rve": np.arange(b),
            "step": step,
            "axial_strain": 1.0 - cell[:, 1, 1] / cell0[:, 1, 1],
            "lateral_strain": cell[:, 0, 0] / cell0[:, 0, 0] - 1.0,
            "volumetric_strain": np.linalg.det(cell) / area0 - 1.0,
            "sxx": h.stress[:, 0, 0],
            "syy": h.stress[:, 1, 1],
            "sxy": 0.5 * (h.stress[:, 0, 1] + h.stress[:, 1, 0]),
            "stress_ratio": h.stress[:, 1, 1] / h.stress[:, 0, 0],
            "void_ratio": h.void_ratio,
            "coordination": h.coordination,
        }))

    record(0)
    target = np.tile([-float(confining), step_strain], (b, 1))
    control = np.tile([CONTROL_STRESS, CONTROL_STRAIN], (b, 1))
    bar = tqdm(total=total, desc="biaxial", unit="step", disable=not progress)
    done = 0
    try:
        while done < total:
            chunk = min(record_every, total - done)
            servo_steps(batch, chunk, target, control, gain=gain,
                        max_strain=4.0 * strain_per_step, check_every=chunk)
            done += chunk
            record(done)
            bar.update(chunk)
            last = rows[-1]
            bar.set_postfix(q=f"{last['stress_ratio'].mean():.3f}")
    finally:
        bar.close()
    return pd.concat(rows, ignore_index=True)


@dataclass(frozen=True)
class BiaxialSummary:
    """Key figures of one RVE's biaxial curve (volumetric strain tension positive)."""

    peak_stress_ratio: float
    axial_strain_at_peak: float
    max_contraction: float
    final_void_ratio: float


def summarize_biaxial(curve: pd.DataFrame) -> BiaxialSummary:
    """Peak σ1/σ3 and its axial strain, the most negative εv, the last void ratio."""
    peak = int(np.argmax(curve["stress_ratio"].to_numpy()))
    return BiaxialSummary(
        peak_stress_ratio=float(curve["stress_ratio"].iloc[peak]),
        axial_strain_at_peak=float(curve["axial_strain"].iloc[peak]),
        max_contraction=float(curve["volumetric_strain"].min()),
        final_void_ratio=float(curve["void_ratio"].iloc[-1]),
    )
