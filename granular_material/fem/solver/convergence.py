"""The rules that end a Newton increment
(:class:`~granular_material.fem.solver.newton.NewtonSolver`):
its convergence tests, the stall and small-correction acceptances, and the failures
(divergence, the growth limit, iterations spent).

The convergence test is a choice (:attr:`NewtonSettings.convergence
<granular_material.fem.solver.settings.NewtonSettings.convergence>`):

- ``force`` (default): ‖R‖₂ ≤ rtol·‖R₀‖₂ on the free degrees of freedom, or ‖R‖₂ ≤ atol
  (the commands set atol from a stress floor, ``--stress-tol``);
- ``displacement`` (Guo & Zhao's FEM×DEM code): ‖δu‖ ≤ rtol·‖Δu‖, δu the Newton correction
  of the iteration and Δu the increment of the load step so far (δu included), both in the
  L² norm over the specimen (‖v‖² = ∫ v·v dV, as escript's ``util.L2`` that Guo & Zhao
  use). As in their code, the material is evaluated once more at the corrected
  displacement and that evaluation is the converged state: the test judges the correction,
  not the residual left after it, and takes at least two evaluations per increment;
- ``residual-displacement`` (the commands' default): the same ratio, taken of the correction
  the current iterate's residual asks for (relaxed, when a relaxation is on) before it is
  applied; when it is within rtol, that iterate, already evaluated, is the converged state.
  The tolerance then bounds the accepted state's own equilibrium error (as the displacement
  it would take to remove it), and the evaluation that ``displacement`` spends on a
  correction already known to be within rtol is saved: one DEM run per increment. An
  increment can converge on its predictor.

An increment that prescribes nothing (its load factor changes neither the prescribed
displacements nor the external forces, e.g. a footing held at [0, 0]) from a converged state
has nothing to do: :func:`nothing_prescribed` says so before any correction is solved, the
iterate is the committed state itself (no predictor), and the rule :func:`idle` accepts its
one evaluation ("nothing-to-do"). Without it the force test would judge the round-off left
by the last increment (‖R₀‖ near zero) against itself, and fail a step where nothing moves.

Every rule has one signature, ``rule(state, settings) -> Verdict``: it reads the increment so
far (an :class:`IterationState`, a frozen value) and the settings, and says that the
increment converged, stalled (accepted all the same), failed (with the reason), or has to go
on (the rule has nothing to say). The driver asks the rules of its test (:data:`RULES`) at two
points of every iteration, once the iterate is evaluated and once the correction it asks for
is known; the first verdict other than "go on" ends the increment (:func:`judge`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import Enum

import numpy as np

from granular_material.fem.solver.settings import CONVERGENCE_TESTS, NewtonSettings

__all__ = [
    "GO_ON",
    "IDLE_RTOL",
    "RULES",
    "ZERO_RESIDUAL",
    "IterationState",
    "Outcome",
    "Rule",
    "Rules",
    "Verdict",
    "correction_small",
    "correction_stalled",
    "displacement_converged",
    "diverged",
    "force_atol",
    "force_converged",
    "idle",
    "judge",
    "nothing_prescribed",
    "overgrown",
    "residual_displacement_converged",
    "residual_stalled",
    "spent",
]


class Outcome(Enum):
    """How a rule judges an increment."""

    GO_ON = "go on"  # nothing to say: the next rule, or the next iteration
    CONVERGED = "converged"  # within the tolerance of a convergence test
    STALLED = "stalled"  # accepted on a stalled ratio or a small correction
    FAILED = "failed"  # abandoned: the increment is reverted and cut back


@dataclass(frozen=True)
class Verdict:
    """What a rule says of an increment.

    Attributes:
        outcome: converged, stalled, failed or go on.
        by: the rule that accepted the increment (:attr:`StepRecord.converged_by
            <granular_material.fem.solver.newton.StepRecord.converged_by>`), "" unless accepted.
        reason: why the increment failed, "" unless it did.
    """

    outcome: Outcome
    by: str = ""
    reason: str = ""

    @property
    def accepted(self) -> bool:
        """The increment is accepted (converged or stalled)."""
        return self.outcome in (Outcome.CONVERGED, Outcome.STALLED)

    @property
    def stalled(self) -> bool:
        """The increment is accepted on a stall (counted in ``StepRecord.stalled``)."""
        return self.outcome is Outcome.STALLED


#: the verdict of a rule that has nothing to say
GO_ON = Verdict(Outcome.GO_ON)


@dataclass(frozen=True)
class IterationState:
    """An increment so far, as its rules see it.

    Attributes:
        iteration: material evaluations of the increment so far, 1-based.
        r0: ‖R₀‖₂ [N/m], the residual of the increment's load at the committed state, on
            the free degrees of freedom.
        residual: ‖R‖₂ [N/m] of the current iterate, on the free degrees of freedom.
        history: ‖R‖₂ / ‖R₀‖₂ [-] of every iterate, the current one last (‖R‖₂ [N/m] when
            R₀ = 0).
        corrections: ‖δu‖_L2 / ‖Δu‖_L2 [-] of every Newton correction so far.
        predicted: ‖Δu‖_L2 [m · m] of the increment's first iterate (the predictor's).
        step_norm: ‖Δu‖_L2 [m · m] of the iterate the current iterate's correction proposes;
            None until that correction is solved.
        idle: the increment prescribes nothing from a converged state
            (:func:`nothing_prescribed`): its iterate is the committed state.
    """

    iteration: int
    r0: float
    residual: float
    history: tuple[float, ...]
    corrections: tuple[float, ...]
    predicted: float
    step_norm: float | None = None
    idle: bool = False


#: a change of the prescribed displacements or external forces at most this fraction of
#: their size is none (the round-off of a load factor that scales a zero load)
IDLE_RTOL = 1e-12


#: a residual at most this fraction of the internal forces is none (an initial state in
#: equilibrium to round-off, a geostatic start)
ZERO_RESIDUAL = 1e-10


def nothing_prescribed(du_dirichlet: np.ndarray, u_dirichlet: np.ndarray,
                       f_ext: np.ndarray, f_ext_committed: np.ndarray,
                       converged: bool, r0: float = math.inf, force_scale: float = 0.0,
                       atol: float = 0.0) -> bool:
    """Whether an increment has nothing to do: it changes neither the prescribed
    displacements (``du_dirichlet`` [m], against their values ``u_dirichlet``) nor the
    external forces (``f_ext`` [N/m] against ``f_ext_committed``) beyond :data:`IDLE_RTOL`
    of their size, and it starts from a ``converged`` state (one an earlier increment was
    accepted at) or from one in equilibrium: its residual ``r0`` [N/m] within ``atol`` or
    within :data:`ZERO_RESIDUAL` of ``force_scale`` (‖f_int‖ [N/m], over all dofs). An
    initial state out of equilibrium has something to do: the increment solves for it."""
    def unchanged(change: np.ndarray, size: np.ndarray) -> bool:
        return float(np.linalg.norm(change)) <= IDLE_RTOL * float(np.linalg.norm(size))

    if not (unchanged(du_dirichlet, u_dirichlet)
            and unchanged(f_ext - f_ext_committed, f_ext_committed)):
        return False
    return converged or r0 <= max(atol, ZERO_RESIDUAL * force_scale)


def idle(state: IterationState, settings: NewtonSettings) -> Verdict:
    """Converged, "nothing-to-do": the increment prescribes nothing from a converged state,
    and its first iterate (the committed state) is evaluated without failing."""
    if state.idle and state.iteration == 1 and math.isfinite(state.residual):
        return Verdict(Outcome.CONVERGED, by="nothing-to-do")
    return GO_ON


#: the one signature of the rules
Rule = Callable[[IterationState, NewtonSettings], Verdict]


def _no_progress(history: Sequence[float], window: int) -> bool:
    """The smallest value of ``history`` has not dropped by 10 % over its last ``window``."""
    return len(history) > window and min(history[-window:]) >= 0.9 * min(history[:-window])


def _stalled(history: Sequence[float], settings: NewtonSettings) -> bool:
    """The last relative residual is within stall_rtol, and the smallest one has not dropped
    by 10 % over the last stall_window iterations."""
    if settings.stall_rtol <= 0 or not history or history[-1] > settings.stall_rtol:
        return False
    return _no_progress(history, settings.stall_window)


def force_converged(state: IterationState, settings: NewtonSettings) -> Verdict:
    """Converged, "force": ‖R‖₂ ≤ rtol·‖R₀‖₂ (R₀ ≠ 0)."""
    if state.r0 > 0 and state.residual <= settings.rtol * state.r0:
        return Verdict(Outcome.CONVERGED, by="force")
    return GO_ON


def force_atol(state: IterationState, settings: NewtonSettings) -> Verdict:
    """Converged, "force-atol": ‖R‖₂ ≤ atol [N/m], the stress floor."""
    if state.residual <= settings.atol:
        return Verdict(Outcome.CONVERGED, by="force-atol")
    return GO_ON


def residual_stalled(state: IterationState, settings: NewtonSettings) -> Verdict:
    """Stalled, "stall" of the force test: ‖R‖/‖R₀‖ within stall_rtol, no longer falling."""
    if _stalled(state.history, settings):
        return Verdict(Outcome.STALLED, by="stall")
    return GO_ON


def correction_small(state: IterationState, settings: NewtonSettings) -> Verdict:
    """Stalled, "correction" (``accept_correction``): the last correction is within it, and
    the force residual has stalled (no 10 % drop over ``stall_window`` iterations) or the
    iterations are spent."""
    if settings.accept_correction <= 0 or not state.corrections:
        return GO_ON
    if state.corrections[-1] > settings.accept_correction:
        return GO_ON
    if (state.iteration >= settings.max_iterations
            or _no_progress(state.history, settings.stall_window)):
        return Verdict(Outcome.STALLED, by="correction")
    return GO_ON


def displacement_converged(state: IterationState, settings: NewtonSettings) -> Verdict:
    """Converged, "displacement": the correction just applied had ‖δu‖/‖Δu‖ ≤ rtol."""
    if state.corrections and state.corrections[-1] <= settings.rtol:
        return Verdict(Outcome.CONVERGED, by="displacement")
    return GO_ON


def residual_displacement_converged(state: IterationState,
                                    settings: NewtonSettings) -> Verdict:
    """Converged, "residual-displacement": the correction the iterate asks for has
    ‖δu‖/‖Δu‖ ≤ rtol."""
    if state.corrections and state.corrections[-1] <= settings.rtol:
        return Verdict(Outcome.CONVERGED, by="residual-displacement")
    return GO_ON


def correction_stalled(state: IterationState, settings: NewtonSettings) -> Verdict:
    """Stalled, "stall" of either displacement test: ‖δu‖/‖Δu‖ within stall_rtol, no
    longer falling."""
    if _stalled(state.corrections, settings):
        return Verdict(Outcome.STALLED, by="stall")
    return GO_ON


def diverged(state: IterationState, settings: NewtonSettings) -> Verdict:
    """Failed: ‖R‖₂ is not finite or exceeds divergence·‖R₀‖₂."""
    if not math.isfinite(state.residual) or (
            state.r0 > 0 and state.residual > settings.divergence * state.r0):
        return Verdict(Outcome.FAILED, reason="diverged")
    return GO_ON


def overgrown(state: IterationState, settings: NewtonSettings) -> Verdict:
    """Failed: the correction would take ‖Δu‖_L2 past max_growth times the predictor's."""
    if (state.step_norm is not None and state.predicted > 0
            and state.step_norm > settings.max_growth * state.predicted):
        return Verdict(Outcome.FAILED,
                       reason=f"diverged: the corrections grew the increment to "
                              f"{state.step_norm / state.predicted:.3g} times the first "
                              f"iterate's (max_growth {settings.max_growth:g})")
    return GO_ON


def spent(state: IterationState, settings: NewtonSettings) -> Verdict:
    """Failed: max_iterations evaluations used without an acceptance."""
    if state.iteration >= settings.max_iterations:
        return Verdict(Outcome.FAILED,
                       reason=f"not converged in {settings.max_iterations} iterations")
    return GO_ON


@dataclass(frozen=True)
class Rules:
    """The rules of one convergence test, in the order they are asked.

    Attributes:
        evaluated: asked once the iterate is evaluated (its residual known).
        corrected: asked once the correction it asks for is solved (before it is applied).
    """

    evaluated: tuple[Rule, ...]
    corrected: tuple[Rule, ...]


#: the rules of each convergence test (NewtonSettings.convergence)
RULES: dict[str, Rules] = {
    "force": Rules((idle, force_converged, force_atol, residual_stalled, correction_small,
                    diverged, spent),
                   (overgrown,)),
    "displacement": Rules((idle, displacement_converged, correction_stalled, diverged, spent),
                          (overgrown,)),
    "residual-displacement": Rules((idle, diverged),
                                   (overgrown, residual_displacement_converged,
                                    correction_stalled, spent)),
}
assert tuple(RULES) == CONVERGENCE_TESTS


def judge(rules: Sequence[Rule], state: IterationState, settings: NewtonSettings) -> Verdict:
    """The first verdict of ``rules`` on ``state`` other than go on; go on if none."""
    for rule in rules:
        verdict = rule(state, settings)
        if verdict.outcome is not Outcome.GO_ON:
            return verdict
    return GO_ON
