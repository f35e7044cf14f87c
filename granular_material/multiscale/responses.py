"""What the DEM material answers: the response of a backend's evaluation (the symmetrised
Love stress, the tangent, the fields and costs of every point, failed points at their
committed state) and the response of RVE states as they are (a committed state's)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from granular_material.dem import RVEData
from granular_material.fem.materials.protocol import FailureReason, MaterialResponse, PointStatus
from granular_material.multiscale.evaluation import Evaluation

__all__ = ["measured_response", "response_of", "sym"]


def sym(stress: np.ndarray) -> np.ndarray:
    """The symmetric part of stresses (n, 2, 2) [Pa]."""
    return 0.5 * (stress + np.swapaxes(stress, 1, 2))


def response_of(ev: Evaluation, committed: Callable[[], MaterialResponse]) -> MaterialResponse:
    """The material response of a backend's evaluation ``ev``: the symmetrised Love stress,
    the tangent, the fields and costs; failed points (all points of an incomplete one) get
    the response of their committed state (``committed()``, asked only then) and a
    reason."""
    h = ev.homogenized
    reasons = ev.failure_reasons()
    failed = np.asarray(ev.failed, dtype=bool).copy()
    if not ev.complete:
        reasons[~failed] = FailureReason.ABORTED.value
        failed[:] = True
    status = np.where(failed, PointStatus.FAILED, PointStatus.OK).astype(np.int8)

    def f64(values: np.ndarray) -> np.ndarray:
        return np.asarray(values, dtype=np.float64)

    love = f64(h.stress)
    stress, tangent = sym(love), f64(h.tangent).copy()
    fields = {"void_ratio": f64(h.void_ratio).copy(),
              "coordination": f64(h.coordination).copy(),
              "stress_skew": 0.5 * (love[:, 0, 1] - love[:, 1, 0])}
    if failed.any():
        held = committed()
        stress[failed] = held.stress[failed]
        tangent[failed] = held.tangent[failed]
        for name, values in fields.items():
            values[failed] = np.asarray(held.fields[name])[failed]
    return MaterialResponse(
        stress=stress, tangent=tangent, status=status,
        costs={"dem_steps": ev.dem_steps, "rve_evaluations": ev.rve_evaluations,
               "particle_steps": ev.particle_steps},
        fields=fields, reasons=reasons, timings=ev.timings,
    )


def measured_response(rves: RVEData, device: str | None, shards: int | None
                      ) -> MaterialResponse:
    """The response of the RVE states ``rves`` as they are (homogenised, not stepped; the
    objective tangent, which needs no condensation): a committed state's."""
    from granular_material.dem import DEMBatch
    from granular_material.dem.homogenization import objective_tangent

    batch = DEMBatch(rves, device=device, shards=shards)
    h = batch.homogenize()
    love = np.asarray(h.stress, dtype=np.float64)
    stress = sym(love)
    n = len(stress)
    return MaterialResponse(
        stress=stress,
        tangent=np.asarray(objective_tangent(np.asarray(h.tangent, dtype=np.float64),
                                             stress), dtype=np.float64),
        status=np.zeros(n, dtype=np.int8),
        fields={"void_ratio": np.asarray(h.void_ratio, dtype=np.float64),
                "coordination": np.asarray(h.coordination, dtype=np.float64),
                "stress_skew": 0.5 * (love[:, 0, 1] - love[:, 1, 0])})
