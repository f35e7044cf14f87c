"""What the Newton driver (:class:`~granular_material.fem.solver.newton.NewtonSolver`) hands out:
the record of each load step, the committed state it carries from one step to the next (to
checkpoint and resume a run), and the error of a step it cannot converge."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from granular_material.fem.materials.protocol import MaterialResponse

__all__ = ["CommittedState", "NewtonError", "StepRecord"]


@dataclass
class StepRecord:
    """What one load step cost and how it converged.

    Attributes:
        step: load step number, 1-based.
        load_factor: λ at the end of the step.
        iterations: material evaluations used, all attempts and sub-increments included.
        costs: the material's costs (:attr:`MaterialResponse.costs
            <granular_material.fem.materials.protocol.MaterialResponse.costs>`) of every evaluation,
            all attempts and sub-increments included, summed name by name; a name no
            evaluation reported is absent (empty for a material that counts nothing).
        cutbacks: how many times an increment of this step was halved.
        stalled: increments accepted on a stalled residual (``NewtonSettings.stall_rtol``)
            or on a small correction once the residual stalled
            (``NewtonSettings.accept_correction``).
        residual_history: ‖R‖₂ / ‖R₀‖₂ of every iteration, one list per attempt.
        wall_time: seconds spent on the step.
        converged_by: the test that accepted each converged increment of the step:
            "force" (‖R‖/‖R₀‖ ≤ rtol), "force-atol" (‖R‖ ≤ atol, the stress floor),
            "displacement" (‖δu‖/‖Δu‖ ≤ rtol), "residual-displacement" (the same ratio of
            the correction the iterate asked for), "stall" (a stalled ratio, see stall_rtol)
            or "correction" (a stalled residual with a small correction, see
            accept_correction).
        correction_history: ‖δu‖_L2 / ‖Δu‖_L2 of every Newton correction, one list per
            attempt (recorded whatever the test; the predictor is not a correction; with
            "residual-displacement" the last one is the correction that was not needed).
        failures: points whose evaluation failed, by reason
            (:class:`~granular_material.fem.materials.protocol.FailureReason` values, e.g.
            ``{"max_dem_steps": 4}``), summed over the failed evaluations of the step;
            empty when none failed.
        timings: wall-clock seconds [s] of the step by phase: ``material`` (its evaluations,
            whole), the phases the material reports inside them (e.g. ``dem``,
            ``homogenization``, ``tangent``), ``assembly`` (stiffness, forces, boundary
            conditions) and ``linear_solve`` (see :data:`granular_material.timing.RUN_PHASES`);
            what ``wall_time`` holds beyond them is the solver's own bookkeeping.
    """

    step: int
    load_factor: float
    iterations: int = 0
    costs: dict[str, int | float] = field(default_factory=dict)
    cutbacks: int = 0
    stalled: int = 0
    residual_history: list[list[float]] = field(default_factory=list)
    wall_time: float = 0.0
    converged_by: list[str] = field(default_factory=list)
    correction_history: list[list[float]] = field(default_factory=list)
    failures: dict[str, int] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)


@dataclass
class CommittedState:
    """What a :class:`~granular_material.fem.solver.newton.NewtonSolver` carries from one load step
    to the next, beside the material's own committed state: enough to resume a run exactly (see
    :mod:`granular_material.runs.checkpoint`).

    Attributes:
        u: nodal displacement [m], shape (ndofs,), float64.
        load_factor: λ of the committed state.
        run_start: λ at which the current
            :meth:`~granular_material.fem.solver.newton.NewtonSolver.run` began.
        last_increment: the last converged (Δλ, Δu [m]) for the extrapolating predictor, or
            None before the first.
        records: the committed steps' records.
        response: the material response of the committed state.
        f_int: the internal force [N/m] (ndofs,) of the committed state as the step that
            committed it assembled it (with a regularised run's −∫ λ : ∇u*); None: assembled
            anew on resume (a checkpoint written before it was kept, whose next step may
            then differ at round-off).
        second_gradient: a run regularised by the second gradient
            (:mod:`granular_material.fem.regularisation`): its unknowns v [-] and λ [Pa] of
            the committed state, shape (extra,); None for a run without it.
        second_gradient_modulus: its modulus D [N] (None without it).
        continuation: an arc-length run's path so far
            (:meth:`~granular_material.fem.solver.continuation.ContinuationState.as_dict`);
            None for a run stepped by load.
    """

    u: np.ndarray
    load_factor: float
    run_start: float
    last_increment: tuple[float, np.ndarray] | None
    records: list[StepRecord]
    response: MaterialResponse
    f_int: np.ndarray | None = None
    second_gradient: np.ndarray | None = None
    second_gradient_modulus: float | None = None
    continuation: dict[str, object] | None = None


class NewtonError(RuntimeError):
    """A load step could not be converged even with the smallest increment allowed."""

    def __init__(self, message: str, records: list[StepRecord]) -> None:
        super().__init__(message)
        self.records = records
