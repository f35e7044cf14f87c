"""RVEs prepared to per-RVE stress tensors (a geostatic K0 state, say): the targets' start
pressures, the low-pressure rule, groups of nearly equal targets, and the preparation.

A packing is made as :func:`~granular_material.procedures.packing.prepare_packing` makes it
(frictionless gas consolidated isotropically, friction set, consolidated again), but each
RVE at its own start pressure, and then brought by
:func:`~granular_material.procedures.servo.servo_to_stress` to its own target σ* (all three
in-plane components, the shear included).

Low pressures. :func:`~granular_material.procedures.packing.min_pressure` (750 Pa for
kn = 3e6 N/m, t = 0.1 m) is where the *frictionless gas* stops settling under the
consolidation servo near its jamming point: a limit of that procedure, not of the contact
law or of the numbers (float64 resolves an overlap of 1e-7 of a radius in a 0.1 m cell; the
timestep √(m/kn) does not depend on the pressure). A jammed frictional packing can be
unloaded far below it: measured here (64 discs, seeds 1–4, K0 = 0.5, prepared at 750 Pa),
the servo brought σv to 300, 100, 30 and 10 Pa in 7 400, 3 700, 17 100 and 66 200 steps,
every component within 0.2 % of σv and the shear within 1 %, the void ratio unchanged to
1e-4 (0.197–0.206); 400 discs (seeds 1–2) reached 15 Pa in 38 350 steps (3.5 s), 100 Pa in
7 550. So a target below the floor is prepared at the floor and unloaded to
it, down to :data:`LOWEST_FRACTION` of the floor (15 Pa for kn = 3e6 N/m: the steps grow as
the pressure falls); a target whose least compressive principal stress is below that is
*clamped*: scaled up, its ratios (K0) kept, until it is; :func:`clamp_targets` says which.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from granular_material.dem import DEMBatch, RVEData
from granular_material.errors import ParameterError
from granular_material.procedures.packing import (
    PackingParameters,
    _check_drawn_radii,
    check_packing,
    min_pressure,
    random_gas,
)
from granular_material.procedures.servo import (
    StressServoResult,
    check_stress_targets,
    consolidate,
    servo_to_stress,
)

__all__ = ["LOWEST_FRACTION", "STARTS", "StressGroups", "bring_to_stress", "clamp_targets",
           "group_targets", "lowest_target_pressure", "prepare_to_stress", "start_pressure"]

#: the lowest target a prepared RVE is unloaded to, as a fraction of
#: :func:`~granular_material.procedures.packing.min_pressure` (10 Pa = 1/75 of it measured,
#: see the module's docstring)
LOWEST_FRACTION = 0.02
#: the isotropic pressure a packing is consolidated to before its servo to the target:
#: the target's mean pressure −tr σ*/2 (the default: fewer servo steps), or its major
#: principal compression. Measured (32 RVEs of 64 discs, σv 20–28 kPa, mean / major servo
#: steps per RVE): K0 = 0.5: 594 / 1131; K0 = 0.4: 2914 / 3747; K0 = 0.7: 436 / 475
STARTS = ("mean", "major")


def lowest_target_pressure(packing: PackingParameters) -> float:
    """The lowest least-compressive principal stress [Pa, compression positive] an RVE of
    ``packing`` is prepared to: :data:`LOWEST_FRACTION` of its
    :func:`~granular_material.procedures.packing.min_pressure`."""
    return LOWEST_FRACTION * min_pressure(packing.meta, packing.radius_range)


def clamp_targets(target: np.ndarray, lowest: float) -> tuple[np.ndarray, np.ndarray]:
    """The targets σ* [Pa] (n, 2, 2), compressive, with every one whose least compressive
    principal stress is below ``lowest`` [Pa, compression positive] scaled up until it is
    that (its ratios, K0, kept); and the indices of those clamped."""
    least = -np.linalg.eigvalsh(target)[:, 1]
    clamped = np.flatnonzero(least < lowest)
    out = target.copy()
    out[clamped] *= (lowest / least[clamped])[:, None, None]
    return out, clamped


def start_pressure(target: np.ndarray, start: str = "mean") -> np.ndarray:
    """The isotropic pressure [Pa, compression positive] each target's packing is first
    consolidated to (:data:`STARTS`): its mean pressure or its major principal compression."""
    if start not in STARTS:
        raise ParameterError("start", f"must be one of {', '.join(STARTS)}, got {start!r}")
    if start == "mean":
        return -0.5 * (target[:, 0, 0] + target[:, 1, 1])
    return -np.linalg.eigvalsh(target)[:, 0]


@dataclass(frozen=True)
class StressGroups:
    """Targets that share one preparation.

    Attributes:
        labels: the group of each target, (n,), int; groups numbered in the order of their
            first target.
        targets: each group's target [Pa], (g, 2, 2): the midrange of its members' components.
        first: each group's first member, (g,), int.
    """

    labels: np.ndarray
    targets: np.ndarray
    first: np.ndarray

    @property
    def n_groups(self) -> int:
        """Number of groups (preparations)."""
        return len(self.first)


def group_targets(target: np.ndarray, tolerance: float) -> StressGroups:
    """Group the targets σ* [Pa] (n, 2, 2) whose components agree within ``tolerance`` [-]
    of the group's scale s = ``max(|σ*xx|, |σ*yy|)`` (σv for K0 <= 1): every component of a
    group spans at most ``tolerance``·s, and the group is prepared to the midrange, so each
    member's target is missed by at most ``tolerance``/2 · s (plus the servo's tolerance).
    Greedy, in order of increasing mean pressure. ``tolerance`` 0: equal targets only share.
    """
    if not (math.isfinite(tolerance) and tolerance >= 0):
        raise ParameterError("share_tolerance", f"must be a finite fraction >= 0, got "
                                                f"{tolerance!r}")
    n = len(target)
    flat = np.stack([target[:, 0, 0], target[:, 1, 1], target[:, 0, 1]], axis=1)
    order = np.argsort(-(flat[:, 0] + flat[:, 1]), kind="stable")
    raw = np.full(n, -1)
    members: list[list[int]] = []
    low = high = flat[0]
    for p in order:
        if members:
            new_low, new_high = np.minimum(low, flat[p]), np.maximum(high, flat[p])
            scale = max(abs(new_low[0]), abs(new_low[1]))
            if (new_high - new_low <= tolerance * scale).all():
                members[-1].append(int(p))
                raw[p], low, high = len(members) - 1, new_low, new_high
                continue
        members.append([int(p)])
        raw[p], low, high = len(members) - 1, flat[p], flat[p]
    first = np.array([min(m) for m in members])
    renumber = np.empty(len(members), dtype=np.int64)
    renumber[np.argsort(first, kind="stable")] = np.arange(len(members))
    labels = renumber[raw]
    reps = np.empty((len(members), 2, 2))
    for g, m in enumerate(members):
        mid = 0.5 * (flat[m].min(axis=0) + flat[m].max(axis=0))
        reps[renumber[g]] = [[mid[0], mid[2]], [mid[2], mid[1]]]
    return StressGroups(labels=labels, targets=reps, first=np.sort(first))


def bring_to_stress(data: RVEData, target: np.ndarray, device: str | None = None,
                    dtype: str = "float64", shards: int | None = None,
                    **servo: float | bool) -> tuple[RVEData, StressServoResult]:
    """The RVEs of ``data`` (B of them; a file's, say) brought to the targets σ* [Pa]
    (B, 2, 2) by :func:`~granular_material.procedures.servo.servo_to_stress` (``servo``: its
    tolerances and settings); their states and the servo's result."""
    batch = DEMBatch(data, device=device, dtype=dtype, shards=shards)
    result = servo_to_stress(batch, target, **servo)
    return batch.to_data(), result


def prepare_to_stress(
    target: np.ndarray,
    n_disc: int,
    seed: int = 1,
    packing: PackingParameters | None = None,
    start: str = "mean",
    device: str | None = None,
    dtype: str = "float64",
    shards: int | None = None,
    progress: bool = False,
    **servo: float | bool,
) -> tuple[RVEData, StressServoResult]:
    """B packings of ``n_disc`` discs of ``packing`` (RVE b from seed + b), each brought to
    its own target σ* [Pa] (B, 2, 2), compressive, tension positive.

    Each is consolidated (frictionless, then with friction, as
    :func:`~granular_material.procedures.packing.prepare_packing` does) to its start
    pressure (:func:`start_pressure`; at least
    :func:`~granular_material.procedures.packing.min_pressure`: below it the target is
    reached by unloading), then servoed to σ* (``servo``: the keywords of
    :func:`~granular_material.procedures.servo.servo_to_stress`). Targets below
    :func:`lowest_target_pressure` must be clamped first (:func:`clamp_targets`):
    ParameterError. Returns the RVE states and the servo's result.
    """
    packing = packing or PackingParameters()
    meta = packing.meta
    goal = check_stress_targets(target, len(np.asarray(target)))
    lowest = lowest_target_pressure(packing)
    least = -np.linalg.eigvalsh(goal)[:, 1]
    if (least < lowest * (1 - 1e-12)).any():
        raise ParameterError("target", f"has stresses below the lowest an RVE is prepared "
                                       f"to, {lowest:.4g} Pa (clamp_targets)")
    floor = min_pressure(meta, packing.radius_range)
    pressure = np.maximum(start_pressure(goal, start), floor)
    for extreme in (float(pressure.min()), float(pressure.max())):
        check_packing(n_disc, extreme, meta, packing.radius_range, dtype)
    _check_drawn_radii(n_disc, len(goal), seed, packing.radius_range)
    gas = random_gas(n_disc, len(goal), seed, packing.radius_range,
                     meta=replace(meta, friction_angle=0.0))
    batch = DEMBatch(gas, device=device, dtype=dtype, shards=shards)
    e0 = packing.target_void_ratio
    if e0 is not None:
        consolidate(batch, pressure, stop_void_ratio=e0, check_every=10, max_strain=5.0e-5,
                    progress=progress)
    else:
        consolidate(batch, pressure, progress=progress)
    batch.set_friction(meta.friction_angle)
    consolidate(batch, pressure, progress=progress)
    result = servo_to_stress(batch, goal, progress=progress, **servo)
    return batch.to_data(), result
