"""Newton–Raphson load stepping for the equilibrium problem, in small strain or, as Guo &
Zhao's FEM×DEM code, updated-Lagrangian finite strain (:mod:`granular_material.fem.kinematics`).

Each load step follows Wu, Fu & Zhou (2025) §1.4: (a) the equivalent nodal forces of the
step, with prescribed displacements moved to the right-hand side by condensation;
(b)–(d) the committed tangent gives a predictor; (e)–(f) the material is evaluated with the
displacement gradient accumulated since the last commit; (g) the residual
R = ∫ Bᵀσ dV − f_ext is compared with the step's load, ‖R‖₂ / ‖R₀‖₂ ≤ TOL (0.005);
(h) otherwise the tangent of the current iterate gives the correction. A step that does not
converge is reverted (the material returns to its committed state) and retried with half the
increment, down to a limit.

The convergence tests and the other rules that end an increment (stall, small correction,
divergence, growth limit, iterations spent) are in :mod:`granular_material.fem.solver.convergence`;
the settings, :class:`NewtonSettings`, in :mod:`granular_material.fem.solver.settings`; the
step records, committed state and error in :mod:`granular_material.fem.solver.records`.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.sparse.linalg import factorized
from skfem import Basis, BilinearForm, condense, solve

from granular_material.fem.boundary_value.loading import Loading
from granular_material.fem.forms import gauss_points_grad, internal_force, stiffness
from granular_material.fem.kinematics import Kinematics
from granular_material.fem.materials.protocol import Material, MaterialResponse
from granular_material.fem.regularisation import (
    Regularisation,
    SecondGradient,
    check_element,
    initial_shear_modulus,
    second_gradient_modulus,
)
from granular_material.fem.solver.acceleration import AitkenRelaxation, SecantTangent
from granular_material.fem.solver.continuation import (
    ContinuationState,
    LoadParameter,
    Parameter,
    arc_roots,
    next_length,
)
from granular_material.fem.solver.convergence import (
    RULES,
    IterationState,
    Outcome,
    Verdict,
    judge,
    nothing_prescribed,
)
from granular_material.fem.solver.records import CommittedState, NewtonError, StepRecord
from granular_material.fem.solver.settings import CONVERGENCE_TESTS as CONVERGENCE_TESTS
from granular_material.fem.solver.settings import PREDICTORS as PREDICTORS
from granular_material.fem.solver.settings import RELAXATIONS as RELAXATIONS
from granular_material.fem.solver.settings import TANGENT_UPDATES as TANGENT_UPDATES
from granular_material.fem.solver.settings import NewtonSettings
from granular_material.progress import progress_bar
from granular_material.timing import PhaseTimes

__all__ = [
    "CommittedState",
    "Loading",
    "NewtonError",
    "NewtonSettings",
    "NewtonSolver",
    "StepRecord",
]


@dataclass
class _Attempt:
    """One try at an increment: the verdict that ended it and what it cost."""

    verdict: Verdict
    du: np.ndarray
    response: MaterialResponse
    f_int: np.ndarray | None
    history: list[float]
    corrections: list[float]
    iterations: int
    cost: dict[str, int | float]  # the material's costs, summed over the evaluations
    failures: dict[str, int] = field(default_factory=dict)  # failed points by reason


@BilinearForm
def _mass(u, v, _):
    return u[0] * v[0] + u[1] * v[1]


def _add_costs(total: dict[str, int | float], costs: Mapping[str, int | float]) -> None:
    """Add ``costs`` to ``total`` name by name (a name new to ``total`` starts at 0)."""
    for name, value in costs.items():
        total[name] = total.get(name, 0) + value


class NewtonSolver:
    """Load-stepping Newton solver for one basis, one material and one loading.

    The committed state (displacement ``u``, the material response and the internal
    force that belong to it) only changes when an increment converges.
    """

    def __init__(
        self,
        basis: Basis,
        material: Material,
        loading: Loading,
        settings: NewtonSettings | None = None,
        regularisation: Regularisation | None = None,
    ) -> None:
        self.basis = basis
        self.material = material
        self.loading = loading
        self.settings = settings or NewtonSettings()
        # a noisy material (the DEM) turns a change in the last digit of the tangent into
        # another converged path (the reduced footing's force at its first step moved 11 %):
        # its runs assemble as before issue 62, bit for bit; the others keep the stiffness's
        # pattern and form the finite-strain tangent by batched products (round-off)
        self._kept = not getattr(material, "noisy", False)
        self._assembly: dict[str, bool] = {} if self._kept else {"kept": False}
        self.kinematics = Kinematics(self.settings.formulation,
                                     self.settings.geometric_stiffness, batched=self._kept)
        n_points = basis.nelems * basis.X.shape[-1]
        if material.n_points == 0:
            material.allocate(n_points)
        if material.n_points != n_points:
            raise ValueError(
                f"material holds {material.n_points} points, the mesh has {n_points}"
            )
        self.u = np.zeros(basis.N)
        self._grad_committed = np.zeros((n_points, 2, 2))
        self.load_factor = 0.0
        self._run_start = 0.0
        self._last: tuple[float, np.ndarray] | None = None  # last converged (Δλ, Δu)
        self.records: list[StepRecord] = []
        # the committed state's stress and tangent (∇u = 0 until a step or a resume sets
        # them), read from the material when first asked for (:meth:`_initial`)
        self._response: MaterialResponse | None = None
        self._f_int: np.ndarray | None = None
        self._mass_matrix = None
        # the second gradient (fem.regularisation): its terms, made when first needed (their
        # modulus comes from the initial tangent), and its committed unknowns v and λ
        self.regularisation = regularisation or Regularisation()
        self._second_gradient: SecondGradient | None = None
        self._modulus: float | None = None
        self.extra = np.zeros(0)
        if self.regularisation.active:
            check_element(basis)  # linear elements are refused before any evaluation
        # the arc-length continuation's path (fem.solver.continuation): its next length,
        # peak and collapse; why its last run stopped ("completed", "collapse", "steps")
        self.continuation = ContinuationState()
        self.stopped_by = ""

    @property
    def second_gradient(self) -> SecondGradient | None:
        """The second-gradient terms of a regularised run (None otherwise); their modulus
        D = G₀ (ℓ/10)² [N] is set from the committed tangent when they are first asked for."""
        if not self.regularisation.active:
            return None
        if self._second_gradient is None:
            if self._modulus is None:
                self._modulus = second_gradient_modulus(
                    initial_shear_modulus(self.response.tangent),
                    self.regularisation.internal_length)
            self._second_gradient = SecondGradient(self.basis, self._modulus)
            if self.extra.size != self._second_gradient.n_extra:
                self.extra = np.zeros(self._second_gradient.n_extra)
        return self._second_gradient

    def regularisation_summary(self) -> dict[str, float | str] | None:
        """A regularised run's ``model``, ``internal_length`` [m] and the modulus D
        (``second_gradient_modulus`` [N]) for its summary; None for a run without one."""
        sg = self.second_gradient
        if sg is None:
            return None
        return {"model": self.regularisation.model,
                "internal_length": self.regularisation.internal_length,
                "second_gradient_modulus": sg.modulus}

    def _with_second_gradient(self, f_int: np.ndarray, u: np.ndarray,
                              extra: np.ndarray) -> np.ndarray:
        """``f_int`` [N/m] of the displacement's rows, with the second gradient's rows
        appended and its −∫ λ : ∇u* added (unchanged for a run without it)."""
        sg = self.second_gradient
        if sg is None:
            return f_int
        terms = sg.residual(u, extra)
        return np.concatenate([f_int + terms[: f_int.size], terms[f_int.size:]])

    def _initial(self) -> None:
        """The material's stress and tangent in its committed state (∇u = 0), asked of it
        once, when the solver first needs them; RuntimeError naming the points where it
        fails."""
        n_points = self.material.n_points
        response = self.material.evaluate(np.zeros((n_points, 2, 2)))
        self.material.revert()
        if not response.ok:
            raise RuntimeError(
                f"material fails in its initial state at points {response.failed_points()}"
            )
        self._response = response
        self._f_int = internal_force(self.basis, response.stress)  # (v and λ are 0 here)

    @property
    def response(self) -> MaterialResponse:
        """The material's response in the committed state (stress, tangent, fields)."""
        if self._response is None:
            self._initial()
        return self._response

    @response.setter
    def response(self, value: MaterialResponse) -> None:
        self._response = value

    @property
    def f_int(self) -> np.ndarray:
        """Internal force [N/m] of the committed state, shape (ndofs,)."""
        if self._f_int is None:
            self._initial()
        return self._f_int

    @f_int.setter
    def f_int(self, value: np.ndarray) -> None:
        self._f_int = value

    def _external(self, load_factor: float, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u_D, f_ext) at ``load_factor`` with the displacement ``u`` [m] (a follower load
        acts on the displaced configuration in the finite-strain formulation)."""
        return self.loading.at(load_factor, u if self.kinematics.finite else None)

    def l2_norm(self, v: np.ndarray) -> float:
        """‖v‖_L2 = (∫ v·v dV)^½ [m · m] of a nodal displacement field ``v`` (ndofs,), with a
        rule exact for the element (the Newton rule may be reduced)."""
        if self._mass_matrix is None:
            order = max(int(getattr(self.basis.elem, "maxdeg", 2)), 1)
            exact = Basis(self.basis.mesh, self.basis.elem, intorder=2 * order)
            self._mass_matrix = _mass.assemble(exact)
        v = v[: self.basis.N]  # a regularised run's increments carry v and λ after u
        return math.sqrt(max(float(v @ (self._mass_matrix @ v)), 0.0))

    def committed_state(self) -> CommittedState:
        """The solver's committed state (copies), to checkpoint a run."""
        last = None if self._last is None else (self._last[0], self._last[1].copy())
        sg = self.second_gradient
        return CommittedState(self.u.copy(), self.load_factor, self._run_start, last,
                              list(self.records), self.response, self.f_int.copy(),
                              None if sg is None else self.extra.copy(),
                              None if sg is None else sg.modulus,
                              self.continuation.as_dict() if self.continuation.values
                              else None)

    def resume(self, state: CommittedState) -> None:
        """Continue from ``state`` (from :meth:`committed_state`, perhaps of another process):
        the material must already hold the committed state that belongs to it."""
        if state.u.shape != self.u.shape:
            raise ValueError(f"the saved displacement has shape {state.u.shape}, this mesh "
                             f"{self.u.shape}")
        if state.response.stress.shape[0] != self.material.n_points:
            raise ValueError(f"the saved response has {state.response.stress.shape[0]} points, "
                             f"the material {self.material.n_points}")
        self.u = np.array(state.u, dtype=np.float64)
        self.load_factor = float(state.load_factor)
        self._run_start = float(state.run_start)
        self._last = state.last_increment
        self.records = list(state.records)
        self.response = state.response
        self.continuation = (ContinuationState() if state.continuation is None
                             else ContinuationState.from_dict(state.continuation))
        self._grad_committed = gauss_points_grad(self.basis, self.u)
        saved = state.second_gradient is not None
        if saved != self.regularisation.active:
            raise ValueError("the saved state was " + ("" if saved else "not ")
                             + "regularised by the second gradient, this run is "
                             + ("not" if saved else "so"))
        if saved:
            self._modulus = float(state.second_gradient_modulus)
            self._second_gradient = None
            sg = self.second_gradient
            if state.second_gradient.shape != (sg.n_extra,):
                raise ValueError(f"the saved second-gradient unknowns have shape "
                                 f"{state.second_gradient.shape}, this mesh ({sg.n_extra},)")
            self.extra = np.array(state.second_gradient, dtype=np.float64)
        # the force the step assembled (from ∇u of the step before plus its increment's, with
        # the second gradient's −∫ λ : ∇u*), not one from the total ∇u, which differs at
        # round-off and would move the next step
        if state.f_int is not None:
            self.f_int = np.array(state.f_int, dtype=np.float64)
        else:
            f_int = internal_force(self.basis, self.kinematics.assembled_stress(
                self.response.stress, self._grad_committed))
            self.f_int = self._with_second_gradient(f_int, self.u, self.extra)[: self.basis.N]

    def start_phase(self, loading: Loading, settings: NewtonSettings | None = None,
                    restart: bool = True) -> None:
        """Go on from the committed state under ``loading`` (the next phase of a staged run):
        the displacement, the material's state, the internal force and the step records are
        kept; the load factor starts again at 0, and the last increment is forgotten (the
        extrapolating predictor and an arc-length path start afresh). ``settings``: the
        phase's (e.g. its force tolerance; the formulation must stay the one the solver was
        made with).
        ``restart`` False: a phase resumed part-way (:meth:`resume` has set its load factor
        and last increment), only the loading and settings are set."""
        if loading.force_start.shape != self.loading.force_start.shape:
            raise ValueError(f"the phase's loading has {loading.force_start.size} dofs, the "
                             f"solver {self.loading.force_start.size}")
        if settings is not None:
            if settings.formulation != self.settings.formulation:
                raise ValueError("a phase cannot change the formulation "
                                 f"({self.settings.formulation} to {settings.formulation})")
            self.settings = settings
        self.loading = loading
        if restart:
            self.load_factor = 0.0
            self._run_start = 0.0
            self._last = None
            self.continuation = ContinuationState()  # an arc-length path starts afresh
            self.stopped_by = ""

    @property
    def reaction(self) -> np.ndarray:
        """f_int − f_ext [N/m] at the committed state, shape (ndofs,); nonzero at D only."""
        return self.f_int - self._external(self.load_factor, self.u)[1]

    def grad_u(self) -> np.ndarray:
        """Total ∇u [-] at the Gauss points, committed state, shape (n, 2, 2)."""
        return gauss_points_grad(self.basis, self.u)

    @property
    def committed_grad(self) -> np.ndarray:
        """The committed state's ∇u [-] at the Gauss points (n, 2, 2), as kept (not a copy:
        do not write to it)."""
        return self._grad_committed

    def begin_path(self) -> None:
        """Start a new arc-length path from the committed state: no peak, length or
        direction carried over from an earlier path or load step."""
        self.continuation = ContinuationState()
        self._last = None

    def follow(self, parameter: Parameter, value: float, end: float, most: float,
               budget: int, first_step: int,
               after: Callable[[StepRecord, float], None] | None = None,
               ) -> tuple[float, str]:
        """Arc-length steps (:meth:`arc_step`, each changing ``parameter`` by at most
        ``most``) from ``value`` until it reaches ``end`` ("completed"), the path collapses
        ("collapse") or ``budget`` steps are taken ("steps"), numbered from ``first_step``;
        ``after(record, value)`` runs after each. Returns the value reached and why it
        stopped (:class:`NewtonError` as :meth:`arc_step` raises it)."""
        def stop() -> str:
            if value >= end - 1e-12 * max(abs(end), 1.0):
                return "completed"
            return "collapse" if self.continuation.collapse is not None else ""

        for k in range(budget):
            if stop():
                return value, stop()
            record, value = self.arc_step(parameter, value, first_step + k, most, end)
            if after is not None:
                after(record, value)
        return value, stop() or "steps"

    def _tangents(self) -> Callable[[np.ndarray, MaterialResponse], np.ndarray]:
        """The tangent [Pa] of an increment's corrections, from its iterate's ∇u [-] and the
        material's response there, as ``tangent_update`` asks (a fresh one per increment)."""
        s = self.settings
        if s.tangent_update == "hold":
            hold_tangent = getattr(self.material, "hold_tangent", None)
            if callable(hold_tangent):
                hold_tangent(True)  # the material need not measure the later iterates' tangents
            held: list[np.ndarray] = []  # the first evaluation's

            def first(grad_u: np.ndarray, response: MaterialResponse) -> np.ndarray:
                if not held:
                    held.append(response.tangent)
                return held[0]
            return first
        if s.tangent_update == "secant":
            stress = self.response.stress
            secant = SecantTangent(np.zeros_like(stress), stress, self.response.tangent,
                                   s.secant_min_change)
            return lambda grad_u, response: secant.update(grad_u, response.stress)
        return lambda grad_u, response: response.tangent

    def _evaluate_at(self, du: np.ndarray, grad_n: np.ndarray, times: PhaseTimes,
                     cost: dict[str, int | float],
                     ) -> tuple[MaterialResponse, np.ndarray, np.ndarray,
                                tuple[str, dict[str, int]] | None]:
        """The material at the iterate ``du`` [m] from the committed ∇u ``grad_n``: its
        response, the ∇u that drove it, the total ∇u [-], and where it failed (the reason
        and the failed points by cause) or None; its seconds and costs added up."""
        grad_step = gauss_points_grad(self.basis, du[:self.basis.N])
        grad_u = self.kinematics.material_gradient(grad_n, grad_step)
        with times.phase("material"):
            response = self.material.evaluate(grad_u)
        times.add_all(response.timings)
        _add_costs(cost, response.costs)
        failure = None
        if not response.ok:
            causes = response.failure_causes()  # not the points aborted with them
            bad = causes if causes.size else response.failed_points()
            counts = response.failure_counts()
            why = ", ".join(f"{name}: {k}" for name, k in counts.items())
            failure = (f"material failed at points {bad[:8].tolist()} ({why})", counts)
        return response, grad_u, grad_n + grad_step, failure

    def _internal_at(self, response: MaterialResponse, grad_total: np.ndarray,
                     du: np.ndarray) -> np.ndarray:
        """f_int [N/m] of the iterate ``du`` whose material answered ``response`` (with a
        regularised run's rows of v and λ)."""
        n = self.basis.N
        f_int = internal_force(self.basis, self.kinematics.assembled_stress(response.stress,
                                                                             grad_total))
        if self.second_gradient is not None:
            f_int = self._with_second_gradient(f_int, self.u + du[:n], self.extra + du[n:])
        return f_int

    def _tangent_at(self, tangent: np.ndarray, response: MaterialResponse,
                    grad_n: np.ndarray, grad_total: np.ndarray):
        """The assembled tangent of an iterate (bordered by the second gradient's blocks)."""
        K = stiffness(self.basis, self.kinematics.assembled_tangent(tangent, response.stress,
                                                                    grad_n, grad_total),
                      **self._assembly)
        sg = self.second_gradient
        return K if sg is None else sg.augment(K)

    def _corrected(self, proposed: np.ndarray, du: np.ndarray, state: IterationState,
                   corrections: list[float]) -> Verdict:
        """The verdict of the rules that judge a correction from ``du`` to ``proposed``
        (its ‖δu‖/‖Δu‖ appended to ``corrections``)."""
        step_norm = self.l2_norm(proposed)
        moved = self.l2_norm(proposed - du)
        corrections.append(moved / step_norm if step_norm > 0 else 0.0)
        state = replace(state, corrections=tuple(corrections), step_norm=step_norm)
        return judge(RULES[self.settings.convergence].corrected, state, self.settings)

    def _increment(self, target: float, times: PhaseTimes) -> _Attempt:
        """One increment to load factor ``target`` from the committed state, ended by the
        first verdict of the convergence rules (:mod:`granular_material.fem.solver.convergence`);
        its phases' seconds are added to ``times``."""
        s, D, kin = self.settings, self.loading.dirichlet_dofs, self.kinematics
        grad_n = self._grad_committed
        response = self.response
        sg, n = self.second_gradient, self.basis.N
        with times.phase("assembly"):
            u_d, f_ext = self._external(target, self.u)
            du = np.zeros(n + (0 if sg is None else sg.n_extra))
            du[D] = u_d - self.u[D]
            K = self._tangent_at(response.tangent, response, grad_n, grad_n)
            rhs = f_ext - self.f_int
            if sg is not None:  # v and λ's rows (zero at a committed state, to round-off)
                rhs = np.concatenate([rhs, -sg.residual(self.u, self.extra)[n:]])
            A, b, x, interior = condense(K, rhs, x=du, D=D)
        # the residual's norm is that of the forces: the rows of v and λ are linear and
        # hold exactly after every solve
        r0 = float(np.linalg.norm(b if sg is None else b[interior < n]))
        forces = interior if sg is None else interior[interior < n]
        with times.phase("linear_solve"):
            du = solve(A, b, x, interior)
        if s.predictor == "extrapolate" and self._last is not None:
            last_step, last_du = self._last
            du[interior] = (target - self.load_factor) / last_step * last_du[interior]
        idle = nothing_prescribed(u_d - self.u[D], self.u[D], f_ext,
                                  self._external(self.load_factor, self.u)[1],
                                  converged=self._last is not None, r0=r0,
                                  force_scale=float(np.linalg.norm(self.f_int)), atol=s.atol)
        if idle:  # nothing to do: the iterate is the committed state (see convergence.py)
            du = np.zeros_like(du)
        predicted = self.l2_norm(du)  # the first iterate's increment, for max_growth
        history: list[float] = []
        corrections: list[float] = []
        cost: dict[str, int | float] = {}
        rules = RULES[s.convergence]
        aitken = AitkenRelaxation() if s.relaxation == "aitken" else None
        tangent_of = self._tangents()
        for it in itertools.count(1):  # the rule ``spent`` ends it at max_iterations
            response, grad_u, grad_total, failure = self._evaluate_at(du, grad_n, times, cost)
            if failure is not None:
                # as before, the corrections of an attempt the material failed are not kept
                return _Attempt(Verdict(Outcome.FAILED, reason=failure[0]), du, response,
                                None, history, [], it, cost, failures=failure[1])
            with times.phase("assembly"):
                f_int = self._internal_at(response, grad_total, du)
                if kin.finite:
                    f_ext = self._external(target, self.u + du[:n])[1]
            residual = f_int - (f_ext if sg is None else
                                np.concatenate([f_ext, np.zeros(sg.n_extra)]))
            r = float(np.linalg.norm(residual[forces]))
            history.append(r / r0 if r0 > 0 else r)
            state = IterationState(it, r0, r, tuple(history), tuple(corrections), predicted,
                                   idle=idle)
            verdict = judge(rules.evaluated, state, s)
            if verdict.outcome is not Outcome.GO_ON:
                return _Attempt(verdict, du, response, f_int[:n], history, corrections, it,
                                cost)
            tangent = tangent_of(grad_u, response)
            with times.phase("assembly"):
                K = self._tangent_at(tangent, response, grad_n, grad_total)
                A, b, x, interior = condense(K, -residual, D=D)
            with times.phase("linear_solve"):
                correction = solve(A, b, x, interior)
            proposed = du + correction if aitken is None else aitken.update(du, correction)
            verdict = self._corrected(proposed, du, state, corrections)
            if verdict.outcome is not Outcome.GO_ON:
                return _Attempt(verdict, du, response, f_int[:n], history, corrections, it,
                                cost)
            du = proposed
        raise AssertionError("unreachable: the rules end every increment")

    def _inner(self, x: np.ndarray, y: np.ndarray) -> float:
        """∫ x·y dV [m² · m] of two nodal displacement fields (their u rows)."""
        self.l2_norm(x)  # the mass matrix, made once
        n = self.basis.N
        return float(x[:n] @ (self._mass_matrix @ y[:n]))

    def _pad(self, f: np.ndarray) -> np.ndarray:
        """``f`` (ndofs,) with zeros for a regularised run's v and λ rows."""
        sg = self.second_gradient
        return f if sg is None else np.concatenate([f, np.zeros(sg.n_extra)])

    def _directional(self, K, parameter: Parameter, value: float, u: np.ndarray,
                     stress: np.ndarray, factor: Callable[[np.ndarray], np.ndarray] | None = None,
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                Callable[[np.ndarray], np.ndarray]]:
        """(δu_t, the condensed load q, the interior dofs, the factorised condensed ``K``):
        the displacement [m] of a unit change of the parameter from ``value`` at ``u`` under
        the tangent ``K``; q [N/m] is the unbalanced force a unit change brings (its norm sets
        an increment's R₀). ``factor``: ``K``'s condensed factorisation, if made already."""
        D = self.loading.dirichlet_dofs
        du_d, f_t = parameter.derivative(value, u, stress)
        x = np.zeros(K.shape[0])
        x[D] = du_d
        A, b, x, interior = condense(K, self._pad(f_t), x=x, D=D)
        if factor is None:
            factor = factorized(A.tocsc())
        x[interior] = factor(b)
        return x, b, interior, factor

    def _arc_increment(self, parameter: Parameter, start: float, length: float, most: float,
                       end: float, times: PhaseTimes) -> tuple[_Attempt, float, float]:
        """One arc-length increment from the committed state at parameter ``start``: its
        length in displacement at most ``length`` [m], its change of the parameter at most
        ``most``, never past ``end`` (an increment that would pass it goes to ``end`` with
        the parameter held). Returns the attempt, the parameter's change and the length
        used [m] (see :mod:`granular_material.fem.solver.continuation`)."""
        s, D = self.settings, self.loading.dirichlet_dofs
        grad_n = self._grad_committed
        response = self.response
        sg, n = self.second_gradient, self.basis.N
        with times.phase("assembly"):
            K = self._tangent_at(response.tangent, response, grad_n, grad_n)
        with times.phase("linear_solve"):
            try:
                du_t, q, interior, _ = self._directional(K, parameter, start, self.u,
                                                         response.stress)
            except RuntimeError as exc:  # the committed tangent has no stiffness left
                failed = Verdict(Outcome.FAILED, reason=f"the tangent is singular ({exc})")
                return (_Attempt(failed, np.zeros(K.shape[0]), response, None, [], [], 0, {}),
                        0.0, 0.0)
        forces = interior if sg is None else interior[interior < n]
        norm_t = self.l2_norm(du_t)
        # a parameter that moves the body by less than round-off (a strength nothing
        # mobilises yet) is held at its new value: an arc through it would be noise
        held = norm_t == 0 or norm_t * most <= 1e-9 * self.l2_norm(self.u)
        # the direction along the path: that of the increment before (its change of the
        # parameter where the parameter moves nothing), forward at the path's start
        sign = 1.0
        if self.continuation.values and self._last is not None:
            if held:
                sign = -1.0 if self._last[0] < 0 else 1.0
            else:
                sign = -1.0 if self._inner(self._last[1], du_t) < 0 else 1.0
        change = most if held else min(length / norm_t, most)
        if sign > 0 and start + change >= end - 1e-12 * max(abs(end), 1.0):
            change, held = end - start, True
        change *= sign
        used = 0.0 if held else abs(change) * norm_t
        du = change * du_t
        # R₀: the force a load-controlled increment of this change would bring, or the
        # committed state's own residual (accepted before) where that is smaller
        r_n = float(np.linalg.norm((self.f_int - parameter.external(start, self.u)[1])
                                   [forces]))
        r0 = max(abs(change) * float(np.linalg.norm(q[interior < n])), r_n / s.rtol)
        value = start + change
        history: list[float] = []
        corrections: list[float] = []
        cost: dict[str, int | float] = {}
        rules = RULES[s.convergence]
        tangent_of = self._tangents()
        for it in itertools.count(1):
            parameter.apply(value)
            response, grad_u, grad_total, failure = self._evaluate_at(du, grad_n, times, cost)
            if failure is not None:
                return (_Attempt(Verdict(Outcome.FAILED, reason=failure[0]), du, response,
                                 None, history, [], it, cost, failures=failure[1]),
                        change, used)
            with times.phase("assembly"):
                f_int = self._internal_at(response, grad_total, du)
                f_ext = parameter.external(value, self.u + du[:n])[1]
            residual = f_int - self._pad(f_ext)
            r = float(np.linalg.norm(residual[forces]))
            history.append(r / r0 if r0 > 0 else r)
            state = IterationState(it, r0, r, tuple(history), tuple(corrections), used)
            verdict = judge(rules.evaluated, state, s)
            if verdict.outcome is not Outcome.GO_ON:
                return (_Attempt(verdict, du, response, f_int[:n], history, corrections, it,
                                 cost), change, used)
            tangent = tangent_of(grad_u, response)
            with times.phase("assembly"):
                K = self._tangent_at(tangent, response, grad_n, grad_total)
                A, b, x, free = condense(K, -residual, D=D)
            with times.phase("linear_solve"):  # one factorisation for both right-hand sides
                try:
                    factor = factorized(A.tocsc())
                except RuntimeError as exc:  # a tangent with no stiffness left somewhere
                    return (_Attempt(Verdict(Outcome.FAILED, reason=f"the tangent is singular "
                                             f"({exc})"), du, response, f_int[:n], history,
                                     corrections, it, cost), change, used)
                du_r = x
                du_r[free] = factor(b)
                if held:
                    du_t = np.zeros_like(du_r)
                else:
                    du_t = self._directional(K, parameter, value, self.u + du[:n],
                                             response.stress, factor)[0]
            step_change = 0.0
            if not held:  # the root of ‖Δu + δu_r + δλ δu_t‖ = Δl nearest the path so far
                base = du + du_r
                a, b2 = self._inner(du_t, du_t), 2 * self._inner(du_t, base)
                roots = arc_roots(a, b2, self._inner(base, base) - used * used)
                if roots:
                    step_change = max(roots, key=lambda d: self._inner(base + d * du_t, du))
                elif a > 0:  # the arc misses the linearised path: its nearest point
                    step_change = -b2 / (2 * a)  # (Lam & Morley 1992)
                if abs(change + step_change) > most:
                    # where the parameter barely moves the body (δu_t ≈ 0: a strength
                    # nothing mobilises yet) the arc asks for a change beyond the nominal
                    # step: the parameter is held at the step's bound instead
                    step_change = math.copysign(most, change + step_change) - change
                    held = True
            proposed = du + du_r + step_change * du_t
            verdict = self._corrected(proposed, du, state, corrections)
            if verdict.outcome is not Outcome.GO_ON:
                return (_Attempt(verdict, du, response, f_int[:n], history, corrections, it,
                                 cost), change, used)
            du, change, value = proposed, change + step_change, value + step_change
        raise AssertionError("unreachable: the rules end every increment")

    @staticmethod
    def _tally(record: StepRecord, attempt: _Attempt) -> None:
        """Add an attempt's iterations, costs, failures and histories to its step's record."""
        record.iterations += attempt.iterations
        _add_costs(record.costs, attempt.cost)
        _add_costs(record.failures, attempt.failures)  # type: ignore[arg-type]
        record.residual_history.append(attempt.history)
        record.correction_history.append(attempt.corrections)

    def _commit(self, attempt: _Attempt, change: float) -> None:
        """Make the accepted ``attempt`` (a change of ``change`` in its parameter) the
        committed state: the material's, the displacement and the second gradient's
        unknowns, the response and internal force, the last increment."""
        self.material.commit()
        self.u = self.u + attempt.du[:self.basis.N]
        if self._second_gradient is not None:
            self.extra = self.extra + attempt.du[self.basis.N:]
        self._grad_committed = gauss_points_grad(self.basis, self.u)
        self.response, self.f_int = attempt.response, attempt.f_int
        self._last = (change, attempt.du)

    def arc_step(self, parameter: Parameter, start: float, step: int, most: float,
                 end: float = 1.0) -> tuple[StepRecord, float]:
        """One arc-length step from the committed state at parameter ``start``: the
        record (its ``load_factor`` the parameter reached) and the parameter's new value.
        Its change is at most ``most`` and stops at ``end``; a failed increment is retried
        at half the length, down to 2**-max_cutbacks of the first try, then
        :class:`NewtonError` (the committed state is kept)."""
        t0 = time.perf_counter()
        record = StepRecord(step=step, load_factor=start)
        times = PhaseTimes()
        path = self.continuation
        length = math.inf if path.length is None else path.length
        while True:
            attempt, change, used = self._arc_increment(parameter, start, length, most, end,
                                                        times)
            self._tally(record, attempt)
            if attempt.verdict.accepted:
                break
            self.material.revert()
            record.cutbacks += 1
            if record.cutbacks > self.settings.max_cutbacks or (used == 0 and change == 0):
                record.wall_time = time.perf_counter() - t0
                record.timings = times.as_dict()
                raise NewtonError(
                    f"arc-length step {step} (from {parameter.name} {start:.6g}) did not "
                    f"converge ({attempt.verdict.reason}) even with its length halved "
                    f"{self.settings.max_cutbacks} times; the state committed at "
                    f"{parameter.name} {start:.6g} is kept", [*self.records, record])
            # half the path tried; a held increment (no length: the parameter moved the body
            # by nothing, or it was clipped at its end) halves its change alone
            length, most = (used / 2 if used > 0 else length), abs(change) / 2
        record.converged_by.append(attempt.verdict.by)
        record.stalled += int(attempt.verdict.stalled)
        parameter.apply(start + change)
        self._commit(attempt, change)
        if used > 0:
            if path.largest is None:
                path.largest = 10.0 * used
            path.length = next_length(used, attempt.iterations, path.largest)
        record.load_factor = start + change
        path.commit(step, record.load_factor, change, used)
        record.wall_time = time.perf_counter() - t0
        record.timings = times.as_dict()
        self.records.append(record)
        return record, start + change

    def equilibrate(self, step: int) -> StepRecord:
        """Bring the committed state into equilibrium with the loads at the present load
        factor: one increment that keeps it (a start out of equilibrium settles before any
        load changes), committed as step ``step``. :class:`NewtonError` where it does not
        converge (the committed state is kept)."""
        t0 = time.perf_counter()
        record = StepRecord(step=step, load_factor=self.load_factor)
        times = PhaseTimes()
        attempt = self._increment(self.load_factor, times)
        self._tally(record, attempt)
        record.wall_time = time.perf_counter() - t0
        record.timings = times.as_dict()
        if not attempt.verdict.accepted:
            self.material.revert()
            raise NewtonError(f"the start did not settle into equilibrium at load factor "
                              f"{self.load_factor:.6g} ({attempt.verdict.reason}); the initial "
                              "state is kept", [*self.records, record])
        record.converged_by.append(attempt.verdict.by)
        record.stalled += int(attempt.verdict.stalled)
        self._commit(attempt, 0.0)
        self._last = None  # no load changed: nothing for the next predictor to extrapolate
        self.records.append(record)
        return record

    def step(self, target: float, step: int) -> StepRecord:
        """Advance the committed state to load factor ``target``, cutting back as needed.

        Raises :class:`NewtonError` (the committed state is left at the last converged
        increment) when the increment would have to fall below nominal / 2**max_cutbacks.
        """
        t0 = time.perf_counter()
        record = StepRecord(step=step, load_factor=target)
        times = PhaseTimes()
        nominal = target - self.load_factor
        increment = nominal
        smallest = nominal / 2 ** self.settings.max_cutbacks
        while self.load_factor < target - 1e-12 * max(abs(target), 1.0):
            end = min(self.load_factor + increment, target)
            attempt = self._increment(end, times)
            self._tally(record, attempt)
            if attempt.verdict.accepted:
                record.converged_by.append(attempt.verdict.by)
                self._commit(attempt, end - self.load_factor)
                record.stalled += int(attempt.verdict.stalled)
                self.load_factor = end
                increment = min(2 * increment, nominal) if record.cutbacks else increment
                continue
            self.material.revert()
            record.cutbacks += 1
            increment = (end - self.load_factor) / 2  # half of what was tried (maybe clipped)
            if increment < smallest * (1 - 1e-9):
                record.wall_time = time.perf_counter() - t0
                record.timings = times.as_dict()
                raise NewtonError(
                    f"load step {step} (load factor {self.load_factor:.6g} -> {target:.6g}) "
                    f"did not converge ({attempt.verdict.reason}) even with the increment halved "
                    f"{self.settings.max_cutbacks} times; the state committed at load factor "
                    f"{self.load_factor:.6g} is kept",
                    [*self.records, record],
                )
        record.wall_time = time.perf_counter() - t0
        record.timings = times.as_dict()
        self.records.append(record)
        return record

    def run(
        self,
        n_steps: int,
        on_step: Callable[[NewtonSolver, StepRecord], None] | None = None,
        progress: bool = False,
        description: str = "load steps",
        done: int = 0,
    ) -> list[StepRecord]:
        """Apply the loading in ``n_steps`` equal steps of λ from the current value to 1.

        ``on_step(solver, record)`` is called after every committed step (for output).
        ``done`` > 0 resumes a run (see :meth:`resume`) of which that many steps are
        committed: the remaining steps go to the same load factors as in one go.
        """
        if n_steps < 1:
            raise ValueError(f"n_steps must be >= 1, got {n_steps}")
        if self.settings.continuation == "arc-length":
            return self._run_arc(n_steps, on_step, progress, description, done)
        if not 0 <= done <= n_steps:
            raise ValueError(f"done must lie in [0, {n_steps}], got {done}")
        if done == 0:
            self._run_start = self.load_factor
        start = self._run_start
        first = len(self.records) + 1 - done
        with progress_bar(n_steps, description, progress) as bar:
            bar.update(done)
            for k in range(done, n_steps):
                target = start + (1.0 - start) * (k + 1) / n_steps
                record = self.step(target, first + k)
                if on_step is not None:
                    on_step(self, record)
                last = record.residual_history[-1][-1] if record.residual_history[-1] else 0.0
                bar.set_postfix({"it": record.iterations, "cut": record.cutbacks,
                                 "res": f"{last:.2g}", **record.costs,
                                 **self._material_progress()})
                bar.update()
        return self.records

    def _material_progress(self) -> dict[str, object]:
        """What the material adds to the progress bar (its optional ``progress_fields()``:
        an adaptive material's DEM points)."""
        fields = getattr(self.material, "progress_fields", None)
        return dict(fields()) if callable(fields) else {}

    def arc_length_budget(self, n_steps: int) -> int:
        """The most steps an arc-length run of ``n_steps`` nominal steps takes."""
        return math.ceil(self.settings.arc_length_steps * n_steps)

    def _run_arc(self, n_steps: int, on_step: Callable[[NewtonSolver, StepRecord], None] | None,
                 progress: bool, description: str, done: int) -> list[StepRecord]:
        """:meth:`run` by arc length: steps of the load factor at most (1 − start)/n_steps
        each, until it reaches 1, the path collapses (see
        :class:`~granular_material.fem.solver.continuation.ContinuationState`) or
        :meth:`arc_length_budget` steps are spent; ``stopped_by`` says which."""
        budget = self.arc_length_budget(n_steps)
        if not 0 <= done <= budget:
            raise ValueError(f"done must lie in [0, {budget}], got {done}")
        if done == 0:
            self._run_start = self.load_factor
        most = (1.0 - self._run_start) / n_steps
        parameter = LoadParameter(self.loading.at, self.kinematics.finite)
        self.stopped_by = ""
        with progress_bar(n_steps, description, progress) as bar:
            def reached() -> int:  # the nominal steps the load factor has covered
                return max(min(round((self.load_factor - self._run_start) / most), n_steps), 0)

            shown = reached()
            bar.update(shown)

            def after(record: StepRecord, value: float) -> None:
                nonlocal shown
                self.load_factor = value
                if on_step is not None:
                    on_step(self, record)
                bar.set_postfix({"λ": f"{value:.4g}", "it": record.iterations,
                                 "cut": record.cutbacks, **record.costs,
                                 **self._material_progress()})
                bar.update(reached() - shown)
                shown = reached()

            _, self.stopped_by = self.follow(parameter, self.load_factor, 1.0, most,
                                             budget - done, len(self.records) + 1, after)
        return self.records
