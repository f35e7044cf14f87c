"""The material of a boundary-value run: built by the material class's ``for_problem`` hook
with the initial stress of every Gauss point, and the unit weight of its soil.

A material class offers ``for_problem(parameters, context, initial_stress) -> Material``
(``initial_stress`` [Pa] (n, 2, 2), tension positive, one tensor per Gauss point; ``context``
a :class:`~granular_material.fem.materials.run_context.RunContext` with
``test = "boundary-value"`` and
the problem's representative pressure as ``confining``). The shipped materials have it;
another is refused with a message that says so.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from granular_material.fem.materials.run_context import RunContext
from granular_material.runs.boundary_value.spec import BoundaryValueSpec
from granular_material.runs.spec import SpecError

__all__ = ["GRAVITY", "material_for_problem", "problem_context", "unit_weight_of"]

#: standard gravity [m/s²]
GRAVITY = 9.81


def problem_context(spec: BoundaryValueSpec, n_points: int) -> RunContext:
    """The run context a material of ``spec`` is built for (the device resolved: None is
    CUDA where present, else the CPU)."""
    from granular_material.dem import resolve_device

    return RunContext(test="boundary-value", n_points=n_points,
                      confining=spec.reference_pressure, axial_strain=0.0, steps=spec.steps,
                      scale_discs=None, device=resolve_device(spec.device), shards=spec.shards,
                      backend="inprocess", progress=spec.progress,
                      convergence=spec.newton.convergence_test(spec.material.noisy))


def material_for_problem(spec: BoundaryValueSpec, n_points: int,
                         initial_stress: np.ndarray, allocate: bool = True) -> Any:
    """The material of ``spec`` at ``n_points`` Gauss points starting from
    ``initial_stress`` [Pa] (n, 2, 2), allocated (its RVEs prepared) unless ``allocate`` is
    False."""
    cls = spec.material.cls
    hook = getattr(cls, "for_problem", None)
    if hook is None:
        raise SpecError("material", f"{spec.material.name} cannot start a boundary-value "
                                    "problem (its class has no for_problem hook taking an "
                                    "initial stress per Gauss point)")
    context = problem_context(spec, n_points)
    check = getattr(cls, "check_run", None)
    if check is not None:
        check(spec.material.parameters, context)
    material = hook(spec.material.parameters, context, np.asarray(initial_stress, float))
    if allocate and material.n_points == 0:
        material.allocate(n_points)
    return material


def unit_weight_of(spec: BoundaryValueSpec) -> float:
    """γ [N/m³] of the problem's body force: the spec's number, or with ``"rve"`` the dry
    unit weight of the DEM material's RVEs, ρ_s·g/(1 + e) (grain density ρ_s, void ratio e of
    the RVE file, or the target of the RVEs the run prepares; the discs' thickness cancels:
    the solid fraction of a layer of discs of one thickness is 1/(1 + e))."""
    if spec.unit_weight != "rve":
        return float(spec.unit_weight)
    hook = getattr(spec.material.cls, "unit_weight", None)
    if hook is None:
        raise SpecError("gravity.unit_weight", f'"rve" needs a material of RVEs (dem), not '
                                               f"{spec.material.name}: give a number [N/m³]")
    return float(hook(spec.material.parameters, GRAVITY))
