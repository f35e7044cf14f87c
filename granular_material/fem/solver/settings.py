"""The settings of the Newton driver (:class:`~granular_material.fem.solver.newton.NewtonSolver`):
tolerances, limits and the choices of convergence test, predictor, relaxation, tangent
update and formulation, each checked when the settings are made."""

from __future__ import annotations

import math
from dataclasses import dataclass

from granular_material.errors import ParameterError
from granular_material.fem.kinematics import FORMULATIONS
from granular_material.fem.solver.continuation import CONTINUATIONS

__all__ = [
    "CONVERGENCE_TESTS",
    "MAX_CUTBACKS",
    "PREDICTORS",
    "RELAXATIONS",
    "TANGENT_UPDATES",
    "NewtonSettings",
]

#: the Newton convergence tests (NewtonSettings.convergence)
CONVERGENCE_TESTS = ("force", "displacement", "residual-displacement")
#: the first guesses of a load step (NewtonSettings.predictor)
PREDICTORS = ("tangent", "extrapolate")
#: the relaxations of Newton corrections (NewtonSettings.relaxation)
RELAXATIONS = ("none", "aitken")
#: the updates of the points' tangents between evaluations (NewtonSettings.tangent_update)
TANGENT_UPDATES = ("none", "secant", "hold")
#: the most cut-backs of an increment: 2^-50 of a load step is at the resolution of a float
#: load factor (2^-52), and 2^-1024 overflows
MAX_CUTBACKS = 50


@dataclass(frozen=True)
class NewtonSettings:
    """Tolerances and limits of the Newton driver.

    Attributes:
        rtol: relative tolerance on ‖R‖₂ / ‖R₀‖₂ (0.005 after Wu et al. 2025, eq. 7).
        atol: absolute tolerance on ‖R‖₂ [N/m]; also the test when R₀ = 0.
        stall_rtol: 0 (off) or a looser relative tolerance for residuals that stall: an
            iterate with ‖R‖/‖R₀‖ ≤ stall_rtol is accepted once the smallest residual has
            not dropped by 10 % over ``stall_window`` iterations. Meant for materials whose
            stress carries noise (DEM RVEs inside a shear band), where ‖R‖ settles on a
            floor just above rtol; such increments are counted in ``StepRecord.stalled``.
        stall_window: iterations without progress that make a stall.
        max_iterations: material evaluations allowed per increment before a cut-back.
        max_cutbacks: how many times an increment may be halved (smallest increment =
            nominal / 2**max_cutbacks).
        divergence: an increment is abandoned as soon as ‖R‖ > divergence · ‖R₀‖.
        max_growth: an increment is abandoned as soon as a correction would take its
            displacement ‖Δu‖_L2 past max_growth times the first iterate's (the predictor's),
            before the material sees that iterate. Where the material stops answering a
            direction the corrections stop shrinking and Aitken's factor grows towards its
            cap: on a 400-disc single element past the peak (the perturbation tangent held)
            the iterates stretched the RVE laterally by up to 26 % in a step of 0.1 %, until
            it lost its confinement, 1.5×10⁶ DEM steps in that one step. The residual stays
            bounded there, so ``divergence`` does not see it. The commands' runs stay far
            below the limit (at most 2.2, docs/physics.md).
        predictor: "tangent" (solve with the committed tangent, Wu et al. step (b)–(d)) or
            "extrapolate" (the last converged increment, scaled to the new one, once there
            is one; the tangent predictor for the first step).
        relaxation: "none" (plain Newton steps) or "aitken" (Irons–Tuck dynamic relaxation
            of the corrections, for tangents that are too stiff, such as the
            Kruyt–Rothenburg one, which leaves out the particles' rearrangement; see
            :mod:`granular_material.fem.solver.acceleration`).
        tangent_update: "none" (the material's tangent at every iterate) or "secant" (each
            point's tangent, started from the committed one, is corrected after every
            evaluation by a Broyden update from the stress change the material gave; see
            :class:`~granular_material.fem.solver.acceleration.SecantTangent`) or "hold" (the
            tangent of the increment's first evaluation is kept for all its corrections:
            modified Newton. A tangent that switches with the iterate, such as the condensed
            one whose contacts flip between sticking and sliding, can make full Newton cycle
            between two iterates; a held tangent cannot switch. A material with a
            ``hold_tangent`` method is told, so that it need not measure the later ones).
        secant_min_change: smallest norm of a point's change of ∇u [-] that updates its
            secant tangent. Smaller changes carry mostly DEM noise: on 64-disc RVEs past the
            peak, 1e-6 let the updates learn the noise and Newton stalled; 1e-4 (default)
            updates mostly on the first iterate of an increment.
        convergence: "force" (‖R‖/‖R₀‖ ≤ rtol or ‖R‖ ≤ atol, default), "displacement"
            (Guo & Zhao: ‖δu‖_L2 / ‖Δu‖_L2 ≤ rtol of the correction just applied, then one
            more evaluation) or "residual-displacement" (that ratio of the correction the
            current iterate asks for, which is then not applied); see
            :mod:`granular_material.fem.solver.convergence`.
            With either displacement test atol is not used and the stall test, when on,
            applies to the displacement ratios.
        formulation: "small-strain" (default here: the textbook problem) or
            "updated-lagrangian" (finite strain as Guo & Zhao: equilibrium on the current
            configuration, the material driven by ∇Δu on the committed one, a follower
            pressure; see :mod:`granular_material.fem.kinematics`).
        geometric_stiffness: updated-Lagrangian: assemble the initial-stress stiffness
            with the material tangent (the exact linearisation); Guo & Zhao leave it out.
        accept_correction: 0 (off) or the largest Newton correction ‖δu‖_L2/‖Δu‖_L2 (Guo
            & Zhao's test, their 1e-2) with which an increment whose force residual has
            stalled (no 10 % drop over ``stall_window`` iterations) or has used
            ``max_iterations`` is accepted instead of cut back: a residual that sits at the
            DEM stress noise of its RVEs does not fall when the increment is halved (it
            shrinks R₀, not the noise). Counted in ``StepRecord.stalled``, converged_by
            "correction".
        continuation: "load" (each step prescribes the load factor: today's stepping) or
            "arc-length" (each step prescribes the length of its increment and the load
            factor follows, past limit points and snap-backs; see
            :mod:`granular_material.fem.solver.continuation`).
        arc_length_steps: the most arc-length steps of a run, as a multiple of its
            nominal steps (its path may be longer than the load's range: back and forth
            through a snap-back, or on along a collapse).
    """

    rtol: float = 0.005
    atol: float = 1e-9
    stall_rtol: float = 0.0
    stall_window: int = 8
    max_iterations: int = 25
    max_cutbacks: int = 6
    divergence: float = 1e3
    max_growth: float = 10.0
    predictor: str = "tangent"
    relaxation: str = "none"
    tangent_update: str = "none"
    secant_min_change: float = 1e-4
    convergence: str = "force"
    formulation: str = "small-strain"
    geometric_stiffness: bool = True
    accept_correction: float = 0.0
    continuation: str = "load"
    arc_length_steps: float = 5.0

    def __post_init__(self) -> None:
        if self.formulation not in FORMULATIONS:
            raise ParameterError("formulation", f"must be one of {', '.join(FORMULATIONS)}, "
                                                f"got {self.formulation!r}")
        if not (0 <= self.accept_correction < 1):
            raise ParameterError("accept_correction", "must be 0 (off) or lie in (0, 1), "
                                                      f"got {self.accept_correction!r}")
        if not (self.arc_length_steps >= 1 and math.isfinite(self.arc_length_steps)):
            raise ParameterError("arc_length_steps", "must be a finite number >= 1, got "
                                                     f"{self.arc_length_steps!r}")
        for name, choices in (("convergence", CONVERGENCE_TESTS), ("predictor", PREDICTORS),
                              ("continuation", CONTINUATIONS),
                              ("relaxation", RELAXATIONS), ("tangent_update", TANGENT_UPDATES)):
            if getattr(self, name) not in choices:
                raise ParameterError(name, f"must be one of {', '.join(choices)}, got "
                                           f"{getattr(self, name)!r}")
        if not (self.secant_min_change > 0 and math.isfinite(self.secant_min_change)):
            raise ParameterError("secant_min_change", "must be a finite number > 0, got "
                                                      f"{self.secant_min_change!r}")
        if not (0 < self.rtol < 1):
            raise ParameterError("rtol", f"must lie in (0, 1), got {self.rtol!r}")
        if not (self.stall_rtol == 0 or self.rtol <= self.stall_rtol < 1):
            raise ParameterError("stall_rtol", "must be 0 (off) or lie in [rtol, 1), got "
                                               f"{self.stall_rtol!r}")
        if self.stall_window < 2:
            raise ParameterError("stall_window", f"must be >= 2, got {self.stall_window!r}")
        if not (self.atol >= 0 and math.isfinite(self.atol)):
            raise ParameterError("atol", f"must be a finite number >= 0, got {self.atol!r}")
        if self.max_iterations < 1:
            raise ParameterError("max_iterations", f"must be >= 1, got {self.max_iterations!r}")
        if not 0 <= self.max_cutbacks <= MAX_CUTBACKS:
            raise ParameterError("max_cutbacks", f"must lie in [0, {MAX_CUTBACKS}] (the "
                                                 "smallest increment is 2^-max_cutbacks of a "
                                                 f"step), got {self.max_cutbacks!r}")
        if not self.divergence > 1:
            raise ParameterError("divergence", f"must be > 1, got {self.divergence!r}")
        if not self.max_growth > 1:
            raise ParameterError("max_growth", f"must be > 1, got {self.max_growth!r}")
