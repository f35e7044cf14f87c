"""Stress-servo procedures of DEM batches: mixed stress/strain control, consolidation."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from granular_material.dem import CONTROL_STRAIN, CONTROL_STRESS, DEMBatch
from granular_material.progress import progress_bar

__all__ = ["CONTROL_STRAIN", "CONTROL_STRESS", "consolidate", "servo_steps"]


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
    bar = progress_bar(b, f"consolidating to {pressure:.3g} Pa", progress, unit="rve")

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
