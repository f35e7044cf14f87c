"""The RVEs a DEM material starts from: loaded from a file or prepared as packings."""

from __future__ import annotations

import numpy as np

from granular_material.dem import RVEData, load_rve
from granular_material.multiscale.parameters import DEMMaterialParameters
from granular_material.procedures.packing import VOID_RATIO_TOLERANCE, prepare_packing

__all__ = ["initial_rves", "prepare_rves"]


def initial_rves(parameters: DEMMaterialParameters, n_points: int,
                 progress: bool = False) -> RVEData:
    """The ``n_points`` RVEs of a material in their consolidated state: the file's (one
    replicated, or one per point), else packings prepared as ``parameters`` say (one
    replicated; one at a time with one CPU shard; else all together)."""
    p = parameters
    if n_points < 1:
        raise ValueError(f"n_points must be >= 1, got {n_points}")
    if p.rve is not None:
        data = load_rve(p.rve)
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
