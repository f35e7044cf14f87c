"""Where an RVE batch's condensed tangent is computed: on the batch's own device.

The condensation itself is :mod:`granular_material.dem.condensed.tangent` (scipy's sparse LU, on
the host), :mod:`granular_material.dem.condensed.cg` (warp's CG, systems assembled on the
host) and :mod:`granular_material.dem.condensed.device` (systems assembled on the device);
:func:`condense` chooses among them by the batch's device and dtype, so that a caller asks
for the tangent of some RVEs and never names a solver.
"""

from __future__ import annotations

import warnings

import numpy as np

from granular_material.dem.batch import DEMBatch
from granular_material.dem.condensed.cg import CGFallbackWarning, condensed_tangent_cg
from granular_material.dem.condensed.device import condensed_tangent_of_batch
from granular_material.dem.condensed.tangent import condensed_tangent

__all__ = ["condense"]


def condense(batch: DEMBatch, rves: np.ndarray, sliding: str) -> np.ndarray:
    """The condensed tangent [Pa] of the RVEs ``rves`` (indices) of ``batch`` in their
    current states, shape (len(rves), 2, 2, 2, 2), contacts at their Coulomb cap treated as
    ``sliding`` says ("free" or "stick").

    On the CPU by scipy's LU; on a CUDA batch by warp's CG on its device, the systems
    assembled there too (float64) or on the host (float32). An RVE whose CG does not converge
    (a nearly singular network: the paper's specimen on an H200 met one in 600 at 3.6 %)
    takes the LU's tangent, with a :class:`CGFallbackWarning`.
    """
    rves = np.asarray(rves, dtype=np.int64)
    if not str(batch.device).startswith("cuda"):
        return condensed_tangent(batch.to_data(), rves=rves, sliding=sliding).tangent
    data = None  # a host copy of the batch, made once where it is needed
    if batch.dtype == "float64":
        result = condensed_tangent_of_batch(batch, rves=rves, sliding=sliding,
                                            raise_unconverged=False)
    else:
        data = batch.to_data()
        result = condensed_tangent_cg(data, rves=rves, device=batch.device,
                                      sliding=sliding, raise_unconverged=False)
    tangent = np.array(result.tangent, dtype=np.float64, copy=True)
    unconverged = ~np.asarray(result.converged, dtype=bool)
    if unconverged.any():
        data = batch.to_data() if data is None else data
        tangent[unconverged] = condensed_tangent(data, rves=rves[unconverged],
                                                 sliding=sliding).tangent
        warnings.warn(
            f"condensed tangent: the CG on {batch.device} did not converge for "
            f"{int(unconverged.sum())} of {len(rves)} RVEs ({rves[unconverged].tolist()[:10]}, "
            f"relative residual up to {result.residual[unconverged].max():.2g}); their "
            "tangents are scipy's LU's, on the host", CGFallbackWarning, stacklevel=3)
    return tangent
