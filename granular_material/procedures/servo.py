"""Stress-servo procedures of DEM batches: mixed stress/strain control, consolidation, and
the servo of every stress component to a per-RVE target tensor."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from granular_material.dem import CONTROL_STRAIN, CONTROL_STRESS, DEMBatch
from granular_material.dem.homogenization import Homogenized
from granular_material.errors import ParameterError
from granular_material.progress import progress_bar

__all__ = ["CONTROL_STRAIN", "CONTROL_STRESS", "StressServoResult", "check_stress_targets",
           "consolidate", "servo_steps", "servo_to_stress", "stress_scale"]


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
    pressure: float | np.ndarray,
    tolerance: float = 0.01,
    max_unbalanced: float = 0.02,
    max_steps: int = 400_000,
    max_strain: float = 1.0e-4,
    gain: float = 0.2,
    check_every: int = 500,
    stop_void_ratio: float | None = None,
    progress: bool = False,
) -> int:
    """Isotropic consolidation of every RVE to mean stress −``pressure`` [Pa]: one number,
    or one per RVE (shape (B,)).

    An RVE is done when both σxx and σyy are within ``tolerance``·pressure of −pressure and its
    unbalanced-force ratio is below ``max_unbalanced`` — or, with ``stop_void_ratio``, as soon
    as its void ratio falls to that value; it is then frozen while the others go on. Raises
    RuntimeError naming the RVEs that did not get there in ``max_steps``. Returns the steps run.
    """
    b = batch.n_rve
    if np.ndim(pressure) == 0:
        if not (math.isfinite(pressure) and pressure > 0):
            raise ValueError(f"pressure must be a positive number [Pa], got {pressure!r}")
        target = np.full((b, 2), -float(pressure))
        label, shown = f"{pressure:.3g} Pa", f"{pressure:.4g} Pa"
        each: float | np.ndarray = pressure
    else:
        each = np.asarray(pressure, dtype=np.float64)
        if each.shape != (b,) or not (np.isfinite(each).all() and (each > 0).all()):
            raise ValueError(f"pressure must be a positive number [Pa] or one per RVE, shape "
                             f"({b},), got {pressure!r}")
        target = np.repeat(-each[:, None], 2, axis=1)
        label = shown = f"{each.min():.4g}–{each.max():.4g} Pa"
        each = each[:, None]
    control = np.full((b, 2), CONTROL_STRESS)
    done = np.zeros(b, dtype=bool)
    bar = progress_bar(b, f"consolidating to {label}", progress, unit="rve")

    def converged(steps_done: int) -> bool:
        h = batch.homogenize()
        diag = np.stack([h.stress[:, 0, 0], h.stress[:, 1, 1]], axis=1)
        ok = (np.abs(diag + each) <= tolerance * each).all(axis=1)
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
            f"consolidation to {shown} did not converge in {max_steps} steps for "
            f"RVE(s) {missing}"
        )
    return steps


@dataclass(frozen=True)
class StressServoResult:
    """What :func:`servo_to_stress` reached, per RVE.

    Attributes:
        steps: DEM steps run (the slowest RVE's).
        rve_steps: the steps each RVE ran before it was done and frozen (``steps`` for those
            never done), shape (B,), int.
        reached: whether each RVE met its target (shape (B,), bool).
        stress: the symmetrised Love stress at the end [Pa], shape (B, 2, 2).
        error: ``|σ − σ*|`` of xx, yy and xy over the target's scale
            ``max(|σ*xx|, |σ*yy|)`` [-], shape (B, 3).
        unbalanced_force: the unbalanced-force ratio at the end [-], shape (B,).
    """

    steps: int
    rve_steps: np.ndarray
    reached: np.ndarray
    stress: np.ndarray
    error: np.ndarray
    unbalanced_force: np.ndarray


def check_stress_targets(target: np.ndarray, n_rve: int, name: str = "target") -> np.ndarray:
    """The targets σ* [Pa] as a float64 array (n_rve, 2, 2), symmetric and compressive (both
    principal stresses < 0, tension positive); else a ParameterError naming ``name``."""
    given = np.asarray(target, dtype=np.float64)
    if given.shape != (n_rve, 2, 2):
        raise ParameterError(name, f"must be an array of stress tensors of shape ({n_rve}, 2, "
                                   f"2) [Pa], one per RVE, got shape {given.shape}")
    if not np.isfinite(given).all():
        raise ParameterError(name, "must be finite [Pa]")
    if not np.allclose(given[:, 0, 1], given[:, 1, 0], rtol=1e-9, atol=0.0):
        raise ParameterError(name, "must be symmetric (σxy = σyx)")
    given = 0.5 * (given + np.swapaxes(given, 1, 2))
    major = np.linalg.eigvalsh(given)[:, 1]  # the least compressive principal stress
    bad = np.flatnonzero(major >= 0)
    if bad.size:
        raise ParameterError(name, f"must be compressive (both principal stresses < 0 Pa, "
                                   f"tension positive): not at {bad.size} of {n_rve}, e.g. "
                                   f"index {bad[0]} with {given[bad[0]].tolist()}")
    return given


def stress_scale(target: np.ndarray) -> np.ndarray:
    """The scale of each target's errors: ``max(|σ*xx|, |σ*yy|)`` [Pa] (σv for K0 <= 1)."""
    return np.maximum(np.abs(target[:, 0, 0]), np.abs(target[:, 1, 1]))


def servo_to_stress(
    batch: DEMBatch,
    target: np.ndarray,
    tolerance: float = 0.02,
    shear_tolerance: float = 0.02,
    max_unbalanced: float = 0.02,
    max_steps: int = 200_000,
    gain: float = 0.2,
    shear_gain: float = 0.5,
    max_strain: float = 1.0e-4,
    check_every: int = 50,
    aim: float = 0.5,
    strict: bool = True,
    progress: bool = False,
) -> StressServoResult:
    """Bring every RVE to its own stress tensor σ* [Pa] (``target``, (B, 2, 2), tension
    positive, compressive), the shear stress included, by stress-controlled cell deformation.

    σxx and σyy are held by the engine's servo on the cell's diagonal (``gain``,
    ``max_strain`` per step); σxy by a symmetric shear of the cell, H ← (I + dγ (e₁⊗e₂ +
    e₂⊗e₁)) H, every ``check_every`` steps, with dγ = ``shear_gain``·(σ*xy − σxy)/G, G the
    shear stiffness D_xyxy + D_xyyx of the RVE's Kruyt–Rothenburg tangent (an upper bound:
    the correction undershoots rather than overshoots), capped at ``max_strain``.

    An RVE is done, and frozen, when ``|σxx − σ*xx|`` and ``|σyy − σ*yy|`` are within
    ``tolerance``·s, ``|σxy − σ*xy|`` within ``shear_tolerance``·s (s =
    ``max(|σ*xx|, |σ*yy|)``, σv for K0 <= 1) and its unbalanced-force ratio is at most
    ``max_unbalanced`` (the symmetrised Love stress is measured). The servo stops an RVE
    at ``aim`` times those tolerances (default half), so that what the RVE does when
    released (it is not in perfect equilibrium) stays within them: its error drifted by up
    to 0.3 % of σv in 2000 free steps (64 discs, 50 kPa, K0 = 0.5). RVEs not done in
    ``max_steps`` raise RuntimeError naming them (``strict``), or are flagged in the result
    (``reached``; the ``error`` of every RVE is measured at the end).
    """
    if not 0 < aim <= 1:
        raise ParameterError("aim", f"must lie in (0, 1], got {aim!r}")
    b = batch.n_rve
    goal = check_stress_targets(target, b)
    scale = stress_scale(goal)
    diagonal = np.stack([goal[:, 0, 0], goal[:, 1, 1]], axis=1)
    control = np.full((b, 2), CONTROL_STRESS)
    done = np.zeros(b, dtype=bool)
    rve_steps = np.zeros(b, dtype=np.int64)
    bar = progress_bar(b, "servo to the target stresses", progress, unit="rve")

    def measure() -> tuple[np.ndarray, np.ndarray, np.ndarray, Homogenized]:
        h = batch.homogenize()
        stress = 0.5 * (h.stress + np.swapaxes(h.stress, 1, 2))
        diff = stress - goal
        error = np.abs(np.stack([diff[:, 0, 0], diff[:, 1, 1], diff[:, 0, 1]], axis=1))
        return stress, diff, error / scale[:, None], h

    def step(steps_done: int) -> bool:
        _, diff, error, h = measure()
        ok = (error[:, :2] <= aim * tolerance).all(axis=1)
        ok &= (error[:, 2] <= aim * shear_tolerance) & (h.unbalanced_force <= max_unbalanced)
        newly = ok & ~done
        done[newly] = True
        rve_steps[newly] = steps_done
        bar.update(int(newly.sum()))
        batch.set_active(~done)
        if done.all():
            return True
        d = np.asarray(h.tangent, dtype=np.float64)
        shear_modulus = np.maximum(d[:, 0, 1, 0, 1] + d[:, 0, 1, 1, 0], 1.0e-30)
        shear = np.clip(-shear_gain * diff[:, 0, 1] / shear_modulus, -max_strain, max_strain)
        shear[done] = 0.0
        if np.any(shear != 0.0):
            stretch = np.repeat(np.eye(2)[None], b, axis=0)
            stretch[:, 0, 1] += shear
            stretch[:, 1, 0] += shear
            batch.set_cell(stretch @ batch.cell())
            # a cell sheared near the engine's limit takes its least skewed basis (the same
            # packing), so that a target far from the start is reached without stopping
            batch.rebase_thin_cells()
        return False

    try:
        steps = servo_steps(batch, max_steps, diagonal, control, gain=gain,
                            max_strain=max_strain, check_every=check_every, callback=step)
    finally:
        bar.close()
        batch.set_active(np.ones(b))
    stress, _, error, h = measure()
    rve_steps[~done] = steps
    done &= (error[:, :2] <= tolerance).all(axis=1) & (error[:, 2] <= shear_tolerance)
    result = StressServoResult(steps=steps, rve_steps=rve_steps, reached=done.copy(),
                               stress=stress, error=error,
                               unbalanced_force=np.asarray(h.unbalanced_force))
    if strict and not done.all():
        missing = np.flatnonzero(~done)
        raise RuntimeError(
            f"the stress servo did not bring RVE(s) {missing[:10].tolist()}"
            f"{' and more' if missing.size > 10 else ''} to their targets in {max_steps} "
            f"steps (largest errors xx, yy, xy: {error[missing].max(axis=0).round(4).tolist()} "
            f"of the target's scale; tolerances {tolerance:g}, {tolerance:g}, "
            f"{shear_tolerance:g})")
    return result
