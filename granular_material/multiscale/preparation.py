"""The RVEs a DEM material starts from: loaded from a file or prepared as packings, at the
isotropic confining pressure or each at its Gauss point's initial stress."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from granular_material.dem import RVEData, load_rve
from granular_material.errors import ParameterError
from granular_material.multiscale.parameters import DEMMaterialParameters
from granular_material.procedures.anisotropic import (
    bring_to_stress,
    clamp_targets,
    group_targets,
    lowest_target_pressure,
    prepare_to_stress,
    start_pressure,
)
from granular_material.procedures.packing import (
    VOID_RATIO_TOLERANCE,
    PackingParameters,
    check_pressure_for_rves,
    prepare_packing,
)
from granular_material.procedures.servo import StressServoResult, stress_scale

#: how near its target the servo brings each RVE of a material's initial stress: every
#: component within 1 % of σv, the shear included (servo_to_stress's default is 2 %). Measured
#: on footing-geostatic.toml (128 points, 64 discs): at 2 % the mesh's initial residual was
#: 106 N/m, above Newton's tolerance of 98 N/m; at 1 %, 53 N/m; at 0.5 %, 26 N/m; the
#: preparation took 2.6-3.5 s at each
SERVO_TOLERANCES = {"tolerance": 0.01, "shear_tolerance": 0.01}

__all__ = ["SERVO_TOLERANCES", "StressPreparation", "initial_rves", "prepare_rves",
           "rves_at_stress"]


def initial_rves(parameters: DEMMaterialParameters, n_points: int,
                 progress: bool = False) -> RVEData:
    """The ``n_points`` RVEs of a material in their consolidated state: the file's (one
    replicated, or one per point), else packings prepared as ``parameters`` say (one
    replicated; one at a time with one CPU shard; else all together)."""
    p = parameters
    if n_points < 1:
        raise ValueError(f"n_points must be >= 1, got {n_points}")
    if p.initial_stress is not None:
        return rves_at_stress(p, n_points, progress).data
    if p.rve is not None:
        data = load_rve(p.rve)
        if p.isotropic:
            check_pressure_for_rves(data, p.confining, "confining")
        if p.replicate or data.n_rve == 1:
            return data.replicate(n_points)
        if data.n_rve != n_points:
            raise ValueError(f"rve file {p.rve} holds {data.n_rve} RVEs; {n_points} Gauss "
                             f"points need 1 (replicated) or {n_points}")
        return data
    if p.replicate:
        return prepare_rves(p, 1, p.seed, progress).replicate(n_points)
    if p.shards == 1:
        return RVEData.concatenate([prepare_rves(p, 1, p.seed + k, progress)
                                    for k in range(n_points)])
    return prepare_rves(p, n_points, p.seed, progress)


def prepare_rves(parameters: DEMMaterialParameters, n_rve: int, seed: int,
                 progress: bool = False) -> RVEData:
    """``n_rve`` packings of the parameters' material (seeds seed, seed + 1, …) at their
    confining pressure; ``RuntimeError`` naming the RVEs whose void ratio ends more than
    ``VOID_RATIO_TOLERANCE`` above the packing's ``target_void_ratio``."""
    p = parameters
    packing = p.packing
    batch = prepare_packing(n_disc=p.discs, n_rve=n_rve, seed=seed, pressure=p.confining,
                            meta=packing.meta, target_void_ratio=packing.target_void_ratio,
                            radius_range=packing.radius_range, device=p.device,
                            progress=progress)
    target = packing.target_void_ratio
    if target is not None:
        void_ratio = batch.homogenize().void_ratio
        missed = np.flatnonzero(void_ratio > target + VOID_RATIO_TOLERANCE)
        if missed.size:
            shown = ", ".join(f"seed {seed + i}: {void_ratio[i]:.4g}" for i in missed[:5])
            if missed.size > 5:
                shown += f" and {missed.size - 5} more"
            raise RuntimeError(
                f"target void ratio {target:g} not reached under the pressure "
                f"{p.confining:g} Pa: void ratio of the RVEs of {shown} (frictionless "
                "compaction reached the pressure first; a denser packing needs a higher "
                "pressure)")
    return batch.to_data()


@dataclass(frozen=True)
class StressPreparation:
    """The RVEs of a material with ``initial_stress``, and how they were made.

    Attributes:
        data: the RVE states, one per Gauss point.
        target: each point's target σ* [Pa] (n, 2, 2), as given.
        prepared: each point's prepared target [Pa] (n, 2, 2): clamped, and its group's.
        labels: each point's group (n,): the RVE it is a copy of.
        clamped: the points whose target was below the lowest prepared pressure (indices).
        servo: the servo's result per group.
        packings: packings made (0 when the RVEs came from a file).
    """

    data: RVEData
    target: np.ndarray
    prepared: np.ndarray
    labels: np.ndarray
    clamped: np.ndarray
    servo: StressServoResult
    packings: int

    @property
    def error(self) -> np.ndarray:
        """Each point's ``|σ − σ*|`` of xx, yy and xy over ``max(|σ*xx|, |σ*yy|)`` [-],
        (n, 3), against its own target as given (sharing and clamping included)."""
        stress = self.servo.stress[self.labels]
        diff = stress - self.target
        error = np.abs(np.stack([diff[:, 0, 0], diff[:, 1, 1], diff[:, 0, 1]], axis=1))
        return error / stress_scale(self.target)[:, None]


def rves_at_stress(parameters: DEMMaterialParameters, n_points: int,
                   progress: bool = False) -> StressPreparation:
    """The ``n_points`` RVEs of a material with ``initial_stress``, each at its point's
    target σ* [Pa]: targets below the lowest prepared pressure clamped (their ratios kept),
    grouped by ``share_tolerance`` (None: one group per point), one RVE per group from the
    file (its first point's, or the file's one RVE) or prepared (group k from seed + k, at
    the group's mean pressure; with ``replicate`` one packing at the groups' mean start
    pressure, copied to every group), brought to the group's target by the stress servo and
    copied to its points. ParameterError naming ``initial_stress`` when its shape is not
    (n_points, 2, 2); RuntimeError naming the points whose RVE the servo did not bring to
    its target."""
    p = parameters
    target = p.initial_stress_array
    if target is None:
        raise ParameterError("initial_stress", "is None: the RVEs start isotropic")
    if target.shape != (n_points, 2, 2):
        raise ParameterError("initial_stress", f"holds {len(target)} stress tensors; "
                                               f"{n_points} Gauss points need shape "
                                               f"({n_points}, 2, 2)")
    source = None if p.rve is None else load_rve(p.rve)
    packing = p.packing
    if source is not None:  # the file's own material sets the floor
        packing = PackingParameters(meta=source.meta, radius_range=(
            float(source.radius.min()), float(source.radius.max())))
    clamped_target, clamped = clamp_targets(target, lowest_target_pressure(packing))
    if p.share_tolerance is None:
        labels = np.arange(n_points)
        group_target, first = clamped_target, labels
    else:
        groups = group_targets(clamped_target, p.share_tolerance)
        labels, group_target, first = groups.labels, groups.targets, groups.first
    n_groups = len(first)
    packings = 0
    if source is not None:
        if p.replicate or source.n_rve == 1:
            source = source.replicate(n_groups)
        elif source.n_rve == n_points:
            source = source.take(first)
        else:
            raise ValueError(f"rve file {p.rve} holds {source.n_rve} RVEs; {n_points} Gauss "
                             f"points need 1 (replicated) or {n_points}")
        data, servo = bring_to_stress(source, group_target, device=p.device, shards=p.shards,
                                      strict=False, progress=progress, **SERVO_TOLERANCES)
    elif p.replicate:
        one = np.mean(start_pressure(group_target))
        data, _ = prepare_to_stress(-one * np.eye(2)[None], p.discs, p.seed, p.packing,
                                    device=p.device, shards=p.shards, progress=progress)
        packings = 1
        data, servo = bring_to_stress(data.replicate(n_groups), group_target, device=p.device,
                                      shards=p.shards, strict=False, progress=progress,
                                      **SERVO_TOLERANCES)
    else:
        data, servo = prepare_to_stress(group_target, p.discs, p.seed, p.packing,
                                        device=p.device, shards=p.shards, strict=False,
                                        progress=progress, **SERVO_TOLERANCES)
        packings = n_groups
    missed = np.flatnonzero(~servo.reached[labels])
    if missed.size:
        raise RuntimeError(
            f"{missed.size} of {n_points} points' RVEs did not reach their initial stress "
            f"(points {missed[:10].tolist()}{' …' if missed.size > 10 else ''}; largest "
            f"errors xx, yy, xy: {servo.error[labels[missed]].max(axis=0).round(4).tolist()} "
            "of σv): a larger max_steps of servo_to_stress, or a target nearer the packing's")
    return StressPreparation(data=data.take(labels), target=target,
                             prepared=group_target[labels], labels=labels, clamped=clamped,
                             servo=servo, packings=packings)
