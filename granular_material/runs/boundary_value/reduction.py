"""The factor of safety of a boundary-value run (``[strength_reduction]``,
:class:`~granular_material.runs.boundary_value.spec.StrengthReductionSpec`): after the
loading, the strength of its Mohr–Coulomb regions is reduced by arc length
(:func:`~granular_material.fem.solver.strength_reduction.strength_reduction`) until the
ground collapses. Its steps follow the loading's in the tables, with the factor F
(``strength_factor``) and the largest displacement of any node (``max_displacement`` [m])
in every row, and a figure of F against that displacement; a stopped run resumes inside
the reduction (F is kept with the material's state, the path with the solver's)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.fem.solver.newton import NewtonSolver
from granular_material.fem.solver.records import StepRecord
from granular_material.fem.solver.strength_reduction import (
    StrengthReductionResult,
    strength_reduction,
)
from granular_material.results.bvp_plots import plot_strength_reduction
from granular_material.runs.boundary_value.spec import BoundaryValueSpec

__all__ = ["PHASE", "reduction_columns", "reduction_figure", "reduction_summary",
           "run_reduction"]

#: the name of the reduction's rows in a phased run's ``phase`` column
PHASE = "strength-reduction"


def reduction_columns(solver: NewtonSolver) -> dict[str, float]:
    """A row's ``strength_factor`` F [-] (1 during the loading) and ``max_displacement``
    [m], the largest displacement of any node."""
    u = solver.u.reshape(-1, 2)  # (x, y) of each node's displacement
    return {"strength_factor": float(getattr(solver.material, "strength_factor", 1.0)),
            "max_displacement": float(np.sqrt((u * u).sum(axis=1)).max(initial=0.0))}


def run_reduction(spec: BoundaryValueSpec, solver: NewtonSolver,
                  collect: Callable[[NewtonSolver, StepRecord], None],
                  resumed: bool) -> StrengthReductionResult:
    """Reduce the strength from the loading's committed end (``resumed``: from the step a
    stopped reduction committed) until the collapse; the steps numbered after the
    loading's."""
    sr = spec.strength_reduction
    return strength_reduction(solver, factor_end=sr.factor_end, steps=sr.steps,
                              on_step=collect, progress=spec.progress, resume=resumed)


def reduction_summary(result: StrengthReductionResult | None, spec: BoundaryValueSpec,
                      ) -> dict[str, Any]:
    """The summary's ``strength_reduction``: the factor of safety, why the reduction
    stopped (a factor of safety is a bound unless it stopped by ``collapse``), its steps."""
    sr = spec.strength_reduction
    if result is None:
        return {"factor_of_safety": None, "stopped_by": "not started",
                "factor_end": sr.factor_end, "steps": 0, "error": None}
    bound = {"collapse": "", "end": " (the ground stands at factor_end: F is at least it)",
             "steps": " (the step budget ran out before a collapse: F is at least it)",
             "failed": " (Newton failed before a collapse: F is at least it)"}
    return {"factor_of_safety": result.factor_of_safety, "stopped_by": result.stopped_by,
            "meaning": "the peak of F along the path" + bound.get(result.stopped_by, ""),
            "factor_end": sr.factor_end, "steps": len(result.factors),
            "collapse_step": None if result.collapse_step is None else result.collapse_step,
            "error": result.error}


def reduction_figure(steps: pd.DataFrame, summary: dict[str, Any], out: Path) -> None:
    """``strength_reduction.png`` of the reduction's rows of ``steps``: F against the largest
    nodal displacement, the factor of safety marked."""
    if "strength_factor" not in steps or steps.empty:
        return
    plot_strength_reduction(steps["strength_factor"], steps["max_displacement"],
                            out / "strength_reduction.png", summary.get("factor_of_safety"),
                            summary.get("stopped_by", ""))
