"""A boundary-value run's continuum start: each region's material's continuum twin (its
class's ``continuum_twin`` hook: E, ν and, where it has one, a friction angle; a DEM region's
calibrated from its own RVEs) carries the loads at step 0 on the problem's mesh, and its
stress, floored, capped and settled
(:mod:`~granular_material.fem.boundary_value.continuum_start`), is the initial stress every
point's material starts from (each DEM RVE prepared at its own point's)."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.continuum_start import mobilised_friction, settle
from granular_material.fem.boundary_value.ground import overburden
from granular_material.runs.boundary_value.material import region_elements
from granular_material.runs.boundary_value.spec import STRENGTH_FRACTION, BoundaryValueSpec
from granular_material.runs.spec import SpecError

__all__ = ["ContinuumStartWarning", "continuum_stress", "settles"]


def continuum_stress(spec: BoundaryValueSpec, problem: Any, gamma: np.ndarray,
                      floor: np.ndarray, floors: Any) -> tuple[np.ndarray, dict[str, Any]]:
    """The continuum start (:func:`~granular_material.fem.boundary_value.continuum_start.settle`)
    of ``problem`` with each region's material's continuum twin (E, ν, φ: its class's
    ``continuum_twin`` hook, a DEM region's calibrated from its RVEs at the median overburden
    pressure of the mesh's points), the floor [Pa] ``floor`` per point and the friction cap
    ``initial.strength_fraction`` times each twin's φ; and what the summary says of it."""
    s = spec.initial
    mesh = problem.mesh_data
    xy = problem.points
    n = xy.shape[0]
    nqp = n // mesh.n_elements
    try:
        pressure = float(np.median(overburden(mesh.mesh, xy, gamma, 0.0).sigma_v))
    except ParameterError:  # an overhang: no column, a representative pressure instead
        pressure = spec.reference_pressure
    if not pressure > 0:  # no weight: the scene's representative pressure
        pressure = spec.reference_pressure
    fraction = STRENGTH_FRACTION if s.strength_fraction is None else s.strength_fraction
    if spec.materials is None:
        pairs = [(None, spec.material, np.arange(n))]
    else:
        elements = region_elements(spec, mesh)
        pairs = [(m.region, m.material,
                  (elements[m.region][:, None] * nqp + np.arange(nqp)).ravel())
                 for m in spec.materials]
    young, poisson, cap = np.zeros(n), np.zeros(n), np.full(n, np.inf)
    twins: dict[str, Any] = {}
    from granular_material.dem import resolve_device

    device = resolve_device(spec.device)
    for region, material, points in pairs:
        hook = getattr(material.cls, "continuum_twin", None)
        where = "" if region is None else f" (region {region!r})"
        if hook is None:
            raise SpecError("initial.state", f'"continuum" needs a linear-elastic stand-in of '
                                             f"each material; {material.name}{where} offers "
                                             "none (its class has no continuum_twin hook): "
                                             "start geostatic or uniform")
        twin = hook(material.parameters, pressure, device)
        young[points], poisson[points] = twin["young"], twin["poisson"]
        if twin["friction_angle"] is not None:
            cap[points] = fraction * twin["friction_angle"]
        twins["" if region is None else region] = twin
    _, force = problem.loading.at(0.0)
    start = settle(problem.basis, force, problem.loading.dirichlet_dofs, young, poisson,
                   floor, cap)
    elastic_floor = int((-np.linalg.eigvalsh(start.elastic)[:, 1] < floor).sum())
    elastic_cap = int((mobilised_friction(start.elastic) > cap).sum())
    info = {"twin": twins if spec.materials is not None else twins[""],
            "strength_fraction": fraction, "minimum_pressure": floors,
            "elastic_below_floor": elastic_floor, "elastic_beyond_cap": elastic_cap,
            "limited_residual": start.residual_limited, "settled_residual": start.residual,
            "settle_iterations": start.iterations, "at_floor": int(start.lifted.size),
            "at_cap": int(start.capped.size)}
    if elastic_floor or elastic_cap:
        warnings.warn(f"the continuum start's elastic state had {elastic_floor} of {n} points "
                      f"below the floor (initial.minimum_pressure) and {elastic_cap} mobilising "
                      f"more than {fraction:g} of their friction angle "
                      "(initial.strength_fraction); they were limited and the state settled "
                      f"back to {start.residual:.2g} of the load from equilibrium "
                      f"({start.lifted.size} points end at the floor, {start.capped.size} at "
                      "the cap: summary.json's initial says more)",
                      ContinuumStartWarning, stacklevel=5)
    return start.stress, info


class ContinuumStartWarning(UserWarning):
    """A continuum start limited points of its elastic state: raised to the floor, or brought
    inside the friction cap (their counts are in the summary's ``initial``)."""


def settles(spec: BoundaryValueSpec, initial_residual: dict[str, float], resumed: bool) -> bool:
    """Whether a run takes a settling step before its load steps: a continuum start (not
    phased, not resumed) whose initial residual [N/m] is above Newton's force tolerance (its
    RVEs meet their targets within the servo's tolerance, and its floor unbalances the free
    surface). The step keeps the load factor: the start carries its own weight first."""
    return (spec.initial.state == "continuum" and not resumed and not spec.phases
            and initial_residual.get("norm", 0.0) > initial_residual.get("newton_atol",
                                                                          float("inf")))
