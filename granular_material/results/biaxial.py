"""What a biaxial run produces (:func:`granular_material.runs.run_biaxial`): its tables, in a
:class:`BiaxialResult`, written, plotted and summarised by the rest of this floor.

Tables (tension positive unless the column says otherwise):

``steps`` — one row per load step (step 0 is the initial state):
    step, load_factor, axial_strain (compression +, the top platen's displacement over the
    initial height), platen_stress [Pa] (axial stress from the top platen reaction over the
    platen's width — its current width in the finite-strain formulation — compression +),
    confining [Pa] (compression +), stress_ratio (platen_stress / confining), sxx, syy, sxy
    [Pa] (averages over the Gauss points' current volumes of the Cauchy stress),
    volumetric_strain (small strain: tr ε volume average; finite strain: the specimen's area
    change A/A0 − 1; contraction negative), void_ratio (mean, NaN if
    the material has none), iterations, the cost columns :data:`COST_COLUMNS` (the step's
    :attr:`StepRecord.costs <granular_material.fem.StepRecord.costs>` of those names,
    0 for a name the material does not report: the DEM material's dem_steps (DEM steps run:
    each evaluation's longest RVE path, summed), rve_evaluations (RVE paths run) and
    particle_steps (DEM disc-steps run)), cutbacks, stalled (increments accepted on a
    stalled residual), wall_time [s],
    residual_history (JSON list of lists of ‖R‖/‖R₀‖), converged_by (the test that accepted
    each increment of the step, joined by "+": force, force-atol, displacement or stall; empty
    for step 0), correction_history (JSON list of lists of ‖δu‖_L2/‖Δu‖_L2, one per
    Newton correction).

``points`` — one row per load step and Gauss point:
    step, axial_strain, point (``element · nqp + q``, nqp = gauss² points per element, see
    :mod:`granular_material.fem.boundary_value.biaxial`), element, x, y [m] (the Gauss point's
    reference coordinates), sxx, syy, sxy [Pa] (Cauchy), exx, eyy, exy (sym ∇u in small strain, the
    Hencky strain ½ ln(F Fᵀ) in finite strain), volumetric_strain (tr ε; finite strain:
    J − 1, the area change), shear_strain (γ = √((ε_xx − ε_yy)² + (2ε_xy)²)), plus the
    material's own fields (void_ratio, coordination, stress_skew, ...).

``tracked`` — with a :class:`~granular_material.fem.tracking.Tracking`: one row per tracked
    step, point and post-processor (see :mod:`granular_material.fem.tracking`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

if TYPE_CHECKING:
    from granular_material.fem import BiaxialProblem, StepRecord

__all__ = ["COST_COLUMNS", "BiaxialResult"]

#: the cost columns that every ``steps`` table carries, in this order, after
#: ``iterations``: each is the step's ``StepRecord.costs`` entry of that name, 0 when the
#: material does not report it (so the tables of every material have the same columns).
#: Costs of other names stay in the records and make no column.
COST_COLUMNS: tuple[str, ...] = ("dem_steps", "rve_evaluations", "particle_steps")


@dataclass
class BiaxialResult:
    """Everything a biaxial run produced.

    Attributes:
        problem: the boundary-value problem.
        steps: global table (see module docstring).
        points: Gauss-point table (see module docstring).
        displacements: nodal displacement [m] after every step, shape (S + 1, ndofs).
        records: the Newton records of the committed steps.
        error: why the run stopped early (the :class:`NewtonError` message, or an
            interrupt), if it did.
        tracked: the tracked post-processors' rows (empty without tracking).
        resumed_from: the load step of the checkpoint the run was resumed from, or None.
        interrupt: the ``KeyboardInterrupt`` (Ctrl-C, or SIGTERM where the caller maps it
            to one) that stopped the run, or None.
        failures: failed point-evaluations by reason over the run, the step that did not
            converge included (the records' ``failures`` summed; empty when no point
            failed). A failed point never reaches ``points``: a step commits only when
            every point succeeded.
        timings: wall-clock seconds [s] by phase of the load steps (the records'
            ``timings`` summed, the step that did not converge included, with ``steps``
            their whole wall time) and of what this process did between them
            (``initial_state``, ``tables``, ``tracking``, ``checkpoint``); a resumed run's
            steps before the resume count with the time they took then.
            :func:`granular_material.timing.phase_table` makes the run's table of them.
        regularisation: a regularised run's model, internal length [m] and modulus D [N]
            (:meth:`~granular_material.fem.NewtonSolver.regularisation_summary`); None
            without one.
    """

    problem: BiaxialProblem
    steps: pd.DataFrame
    points: pd.DataFrame
    displacements: np.ndarray
    records: list[StepRecord] = field(default_factory=list)
    error: str | None = None
    tracked: pd.DataFrame = field(default_factory=pd.DataFrame)
    resumed_from: int | None = None
    interrupt: KeyboardInterrupt | None = None
    failures: dict[str, int] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    regularisation: dict[str, Any] | None = None

    def row_nearest(self, axial_strain: float) -> int:
        """Row of ``steps`` (and of ``displacements``) whose axial strain [-] is nearest."""
        return int(np.argmin(np.abs(self.steps["axial_strain"].to_numpy() - axial_strain)))
