"""The factor of safety by strength reduction, followed by arc length to the collapse.

Strength reduction (Zienkiewicz, Humpheson & Lewis 1975; Griffiths & Lane 1999,
Géotechnique 49:387) divides the strength of the soil by a factor F, tan φ_F = tan φ / F and
c_F = c / F (the Mohr–Coulomb materials' ``reduce_strength``), under its own weight and
loads held at their values, and the factor of safety is the F at which the slope cannot
stand. Read from "the last F at which Newton converged", it moves with the number of
cut-backs and with Newton's own failures (a false early failure at an F the slope carries).
Here F is the parameter of the arc-length continuation
(:mod:`granular_material.fem.solver.continuation`): each step prescribes a length of
displacement and F follows, and the collapse is the plateau of F while the displacement runs
on; the factor of safety is the path's peak. The derivative of the internal force in F is a
forward difference (:data:`RELATIVE_STEP` of F) of the material's stress at the iterate.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from granular_material.errors import ParameterError
from granular_material.fem.forms import gauss_points_grad, internal_force
from granular_material.fem.solver.newton import NewtonSolver
from granular_material.fem.solver.records import NewtonError, StepRecord
from granular_material.progress import progress_bar

__all__ = ["RELATIVE_STEP", "StrengthParameter", "StrengthReductionResult", "strength_reduction"]

#: the forward difference of F in the derivative of the internal force
RELATIVE_STEP = 1e-6


@dataclass
class StrengthParameter:
    """The strength-reduction factor F of ``solver``'s material (which must have
    ``reduce_strength``), with its loads held at the solver's load factor."""

    solver: NewtonSolver
    name: str = "strength_factor"

    def __post_init__(self) -> None:
        if not callable(getattr(self.solver.material, "reduce_strength", None)):
            raise ParameterError("material", f"{type(self.solver.material).__name__} has no "
                                             "strength to reduce (Mohr–Coulomb has)")

    def apply(self, value: float) -> None:
        """Divide the material's tan φ and c by ``value``."""
        self.solver.material.reduce_strength(value)

    def external(self, value: float, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The loads of the solver's committed load factor (F does not change them)."""
        s = self.solver
        return s.loading.at(s.load_factor, u if s.kinematics.finite else None)

    def derivative(self, value: float, u: np.ndarray, stress: np.ndarray,
                   ) -> tuple[np.ndarray, np.ndarray]:
        """(0, −∂f_int/∂F): the internal force's change [N/m] per unit F at ``u``, by a
        forward difference of the material's stress; the material is left evaluated at
        ``value`` again."""
        s = self.solver
        grad_step = gauss_points_grad(s.basis, u - s.u)
        grad_u = s.kinematics.material_gradient(s.committed_grad, grad_step)
        grad_total = s.committed_grad + grad_step
        h = RELATIVE_STEP * value
        s.material.reduce_strength(value + h)
        shifted = s.material.evaluate(grad_u)
        s.material.reduce_strength(value)
        s.material.evaluate(grad_u)  # the iterate's own state, should it be accepted as is
        if not shifted.ok:
            return np.zeros(s.loading.dirichlet_dofs.size), np.zeros(s.basis.N)
        change = internal_force(s.basis, s.kinematics.assembled_stress(
            shifted.stress - stress, grad_total))
        return np.zeros(s.loading.dirichlet_dofs.size), -change / h


@dataclass
class StrengthReductionResult:
    """What a strength reduction found.

    Attributes:
        factor_of_safety: the peak of F along the path (the collapse), or, when the path
            did not collapse, the largest F reached (a lower bound: see ``stopped_by``).
        stopped_by: "collapse" (F's plateau), "end" (``factor_end`` reached: F ≥ it) or
            "steps" (the step budget spent), "failed" (Newton; ``error`` says why).
        factors: F after each step; records: their Newton records.
        error: the Newton failure's message, if any.
        collapse_step: the step of the collapse's peak (None without a collapse).
    """

    factor_of_safety: float
    stopped_by: str
    factors: list[float] = field(default_factory=list)
    records: list[StepRecord] = field(default_factory=list)
    error: str | None = None
    collapse_step: int | None = None


def strength_reduction(solver: NewtonSolver, factor_end: float = 3.0, steps: int = 20,
                       on_step: Callable[[NewtonSolver, StepRecord], None] | None = None,
                       progress: bool = False, resume: bool = False,
                       ) -> StrengthReductionResult:
    """Reduce the strength of ``solver``'s material from its committed state (F = 1, loads
    at the committed load factor) by arc length until the slope collapses.

    Args:
        solver: a solver at equilibrium (e.g. after its gravity steps), with a material
            that has ``reduce_strength`` (Mohr–Coulomb, or regions of it).
        factor_end: the largest F tried (> 1): a slope that stands at it has F ≥ it.
        steps: nominal steps from 1 to ``factor_end`` (the largest change of F a step);
            the path may take up to ``NewtonSettings.arc_length_steps`` times as many.
        on_step: called after every committed step with the solver and its record.
        progress: show a progress bar.
        resume: go on with a reduction the solver (restored from a checkpoint) and its
            material had begun: its path and F are theirs.
    """
    if not (math.isfinite(factor_end) and factor_end > 1):
        raise ParameterError("factor_end", f"must be a finite number > 1, got {factor_end!r}")
    if steps < 1:
        raise ParameterError("steps", f"must be an integer >= 1, got {steps!r}")
    parameter = StrengthParameter(solver)
    if not resume:
        solver.begin_path()
    budget = solver.arc_length_budget(steps)
    factor = float(getattr(solver.material, "strength_factor", 1.0))
    done = len(solver.continuation.values)
    result = StrengthReductionResult(factor, "steps",
                                     factors=list(solver.continuation.values))
    with progress_bar(budget, "strength reduction", progress) as bar:
        bar.update(done)

        def after(record: StepRecord, value: float) -> None:
            result.factors.append(value)
            result.records.append(record)
            if on_step is not None:
                on_step(solver, record)
            bar.set_postfix({"F": f"{value:.4g}", "it": record.iterations})
            bar.update()

        try:
            _, stopped = solver.follow(parameter, factor, factor_end,
                                       (factor_end - 1.0) / steps, budget - done,
                                       len(solver.records) + 1, after)
            result.stopped_by = "end" if stopped == "completed" else stopped
        except NewtonError as exc:
            parameter.apply(result.factors[-1] if result.factors else factor)
            result.stopped_by, result.error = "failed", str(exc)
    path = solver.continuation
    result.factor_of_safety = (float(path.collapse["value"]) if path.collapse is not None
                               else max(result.factors, default=factor))
    result.collapse_step = None if path.collapse is None else int(path.collapse["step"])
    return result
