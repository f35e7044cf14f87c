"""The adaptive material of a biaxial specimen (:attr:`RunSpec.adaptivity
<granular_material.runs.spec.RunSpec.adaptivity>`), and what a summary says of any adaptive
run.

The all-DEM specimen prepares one RVE per Gauss point (seed, seed + 1, … or an RVE file's).
With adaptivity those RVEs are prepared the same way, but each is held back as its point's
*source*: the point answers by the Mohr–Coulomb twin, calibrated from the first point's RVE
at the confining pressure (or read from a ``calibration.json``), until it meets a threshold,
and then by its own RVE, the one the all-DEM run gives it, started from its deformation or
its twin stress (:class:`~granular_material.multiscale.adaptive.AdaptiveMaterial`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from granular_material.runs.spec_sections import AdaptivitySpec

__all__ = ["adaptive_specimen", "adaptivity_summary"]


def adaptive_specimen(dem: Any, adaptivity: AdaptivitySpec, n_points: int, nqp: int,
                      confining: float, progress: bool = False) -> Any:
    """The adaptive material of a specimen of ``n_points`` Gauss points, ``nqp`` an element,
    under ``confining`` [Pa] (compression positive), from the run's DEM material ``dem``
    (not allocated): its RVEs prepared (one a point, as the all-DEM run's) become the
    points' sources, the twin is calibrated from the first at ``confining`` (or read from
    ``adaptivity.calibration``), every point starting on it at −confining·I. Not allocated;
    its ``calibration`` says how the twin was made, with the seconds it took."""
    from granular_material.multiscale.adaptive import (
        AdaptiveMaterial,
        twin_from_calibration,
        twin_from_rve,
    )

    dem.allocate(n_points)
    source = dem.committed_rves()
    sigma0 = np.repeat(-float(confining) * np.eye(2)[None], n_points, axis=0)
    began = time.perf_counter()
    if adaptivity.calibration is not None:
        twin, calibration = twin_from_calibration(adaptivity.calibration, sigma0)
    else:
        twin, calibration = twin_from_rve(source, confining, sigma0,
                                          device=dem.parameters.device, progress=progress,
                                          elastic_window=adaptivity.elastic_window)
    calibration = {**calibration, "seconds": round(time.perf_counter() - began, 3)}
    material = AdaptiveMaterial(twin, calibration["parameters"]["friction_angle"],
                                dem.parameters, source, adaptivity.criterion(), nqp=nqp,
                                start=adaptivity.start, progress=progress)
    material.calibration = calibration
    return material


def adaptivity_summary(material: Any, adaptivity: AdaptivitySpec) -> dict[str, Any]:
    """What an adaptive run's ``material`` did under ``adaptivity``: its criterion, its twin,
    its DEM points and every switch (the summary's ``adaptivity``)."""
    return {
        "mobilised_fraction": adaptivity.mobilised_fraction,
        "shear_strain": adaptivity.shear_strain, "neighbours": adaptivity.neighbours,
        "start": adaptivity.start, "switch": adaptivity.switch, "twin": material.calibration,
        "dem_points_final": int(material.dem_points), "gauss_points": int(material.n_points),
        "missed_points": material.missed.tolist(),
        "switches": [{"after_commit": s.commit, "points": int(s.points.size),
                      "missed": int(s.missed.size), "lifted": s.lifted, "capped": s.capped,
                      "particle_steps": s.particle_steps, "seconds": round(s.seconds, 3),
                      "largest_error": s.error} for s in material.switches],
    }
