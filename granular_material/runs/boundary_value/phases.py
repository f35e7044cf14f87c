"""The phases of a staged boundary-value run (``[[phases]]``,
:class:`~granular_material.runs.boundary_value.spec.PhaseSpec`): each phase as a one-phase
problem of its own, the state a phase hands to the next, and how the runner steps them
(:func:`run_phases`), reports them (:func:`with_phase`, :func:`phases_summary`,
:func:`phased_figure`) and resumes inside one (the checkpoint keeps each phase's start).

A phase is run as the scene without phases would run its conditions
(:func:`phase_view`), with two differences the runner makes when the phase starts from the
state the phase before committed:

- its loads start where the phase before left them: each pressure goes from the total that
  acted on its boundary at the end of the phase before to its own total (a boundary loaded
  before and not in this phase: to zero), gravity from the factor the phase before ended
  with to its own;
- its prescribed displacements are increments: u_D(λ) = u_start + λ·Δ
  (:class:`~granular_material.fem.boundary_value.loading.Loading`'s ``dirichlet_start``),
  so that a support is held where the phase finds it.

A phase with ``reset_displacements`` reports displacement and strain from its start: the
solver's displacement stays the total one (in the updated-Lagrangian formulation it is the
configuration x = X + u, which a reset must not move), and what is written is u − u_reset and
the strain of the deformation since then (:func:`reported_gradient`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from granular_material.fem.boundary_value.meshes import MeshData
from granular_material.fem.kinematics import Kinematics
from granular_material.results.bvp_plots import plot_phased_load_displacement
from granular_material.runs.boundary_value.resume import remember
from granular_material.runs.boundary_value.spec import BoundaryValueSpec, ConditionSpec
from granular_material.runs.spec import SpecError

if TYPE_CHECKING:
    from granular_material.fem import NewtonSolver, StepRecord

#: the runner's :class:`~granular_material.runs.boundary_value.runner.Built` (its plans, the
#: phase stepping, the reset displacement; not imported: the runner imports this module)
Built = Any

__all__ = ["PhasePlan", "ends_phase", "inward_direction", "phase_of_step", "phase_pressures",
           "phase_start_residual", "phase_view", "phased_figure", "phases_summary",
           "pressure_totals", "reported_gradient", "run_phases", "with_phase"]


def pressure_totals(spec: BoundaryValueSpec, index: int) -> dict[str, float]:
    """The pressure [Pa] on each boundary at the end of phase ``index`` (pressures on one
    boundary add up), in the order the boundaries are first loaded."""
    totals: dict[str, float] = {}
    phase = spec.phases[index]
    for c in (*spec.conditions, *phase.conditions):
        if c.type == "pressure":
            end = c.value if index > 0 or c.end is None else c.end
            totals[c.boundary] = totals.get(c.boundary, 0.0) + float(end)
    return totals


def _gravity_factors(spec: BoundaryValueSpec, index: int) -> tuple[float, float]:
    """γ's multiples at the start and the end of phase ``index``."""
    before = None
    for k in range(index + 1):
        start, end = spec.phases[k].factors(before)
        before = end
    return start, end


def phase_view(spec: BoundaryValueSpec, index: int) -> BoundaryValueSpec:
    """Phase ``index`` of the phased ``spec`` as a problem without phases: its conditions (the
    common ones, then its own; a later phase's pressures from the totals the phase before
    ended with to its own), its gravity factors and its steps. Its prescribed displacements
    are the increments of the phase."""
    phase = spec.phases[index]
    if index == 0:
        conditions = (*spec.conditions, *phase.conditions)
    else:
        before = pressure_totals(spec, index - 1)
        now = pressure_totals(spec, index)
        held = tuple(c for c in (*spec.conditions, *phase.conditions) if c.type != "pressure")
        loads = tuple(ConditionSpec(type="pressure", boundary=name,
                                    value=before.get(name, 0.0), end=now.get(name, 0.0))
                      for name in dict.fromkeys([*before, *now]))
        conditions = held + loads
    weighted = spec.unit_weight != 0.0 or any(m.unit_weight not in (None, 0.0)
                                              for m in spec.materials or ())
    factor = _gravity_factors(spec, index) if weighted else None
    return replace(spec, conditions=conditions, gravity_factor=factor, steps=phase.steps,
                   phases=())


def phase_of_step(steps: Sequence[int], step: int) -> tuple[int, int]:
    """(phase index, steps done in it) of a run of phases of ``steps`` load steps each whose
    last committed step is ``step``: a step that ends a phase is the next phase's start,
    with 0 done (the last phase's end: its index and all its steps)."""
    first = 0
    for k, n in enumerate(steps):
        if step < first + n or k == len(steps) - 1:
            return k, step - first
        first += n
    raise ValueError("a phased run has at least one phase")


def phase_pressures(view: BoundaryValueSpec) -> dict[str, tuple[float, float]]:
    """The pressure [Pa] on each boundary of a phase (:func:`phase_view`) at its start and
    at its end (pressures on one boundary add up)."""
    out: dict[str, tuple[float, float]] = {}
    for c in view.conditions:
        if c.type == "pressure":
            start, end = out.get(c.boundary, (0.0, 0.0))
            out[c.boundary] = (start + float(c.value),
                               end + float(c.value if c.end is None else c.end))
    return out


def inward_direction(mesh: MeshData, name: str) -> np.ndarray:
    """The unit vector (2,) into the body across the boundary ``name`` (the mean of its
    facets' inward normals, weighted by their lengths): the direction a pressure on it
    pushes."""
    m = mesh.mesh
    facets = mesh.boundaries[name]
    ends = m.p[:, m.facets[:, facets]]  # (2, 2 ends, n)
    tangent = ends[:, 1] - ends[:, 0]
    normal = np.array([tangent[1], -tangent[0]])  # length-weighted, either way round
    element = m.f2t[0, facets]
    centre = m.p[:, m.t[:, element]].mean(axis=1)
    inward = np.sign(np.einsum("in,in->n", normal, centre - ends.mean(axis=1)))
    total = (normal * inward).sum(axis=1)
    return total / max(float(np.linalg.norm(total)), 1e-300)


@dataclass
class PhasePlan:
    """One phase as the runner steps it.

    Attributes:
        index: its position (0: the first).
        name: its name (None: a problem without phases).
        steps: its load steps.
        first_step: the run's step number before its first step (its steps are
            first_step + 1 …).
        problem: its problem (mesh, conditions, loading; prescribed displacements as
            increments).
        settings: Newton's settings for it (the force tolerance follows its free dofs).
        view: the phase as a problem without phases (:func:`phase_view`).
        reset: report displacement and strain from the phase's start.
        pressures: the pressure [Pa] on each loaded boundary at the phase's start and end.
    """

    index: int
    name: str | None
    steps: int
    first_step: int
    problem: Any
    settings: Any
    view: BoundaryValueSpec
    reset: bool = False
    pressures: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def last_step(self) -> int:
        """The run's step number of its last step."""
        return self.first_step + self.steps


def reported_gradient(kinematics: Kinematics, grad_u: np.ndarray,
                      grad_offset: np.ndarray | None) -> np.ndarray:
    """The displacement gradient [-] (n, 2, 2) whose strain is reported: ∇_X u, or, after a
    reset at displacement u_r (``grad_offset`` = ∇_X u_r), that of the deformation since:
    ∇_X(u − u_r) (small strain) or ∇_X(u − u_r)·F_r⁻¹, so that I + it = F·F_r⁻¹ (finite
    strain)."""
    if grad_offset is None:
        return grad_u
    return kinematics.material_gradient(grad_offset, grad_u - grad_offset)


def phase_start_residual(solver: NewtonSolver) -> float:
    """‖R‖ over the free dofs at the start of the solver's phase (λ = 0), relative to the
    load there (or, without one, to ‖f_int‖): about zero where the state the phase before
    committed is in equilibrium with the phase's start; a released support leaves its
    reaction here."""
    _, f_ext = solver.loading.at(0.0, solver.u if solver.kinematics.finite else None)
    residual = solver.f_int - f_ext
    free = np.ones(residual.size, dtype=bool)
    free[solver.loading.dirichlet_dofs] = False
    norm = float(np.linalg.norm(residual[free]))
    scale = float(np.linalg.norm(f_ext[free])) or float(np.linalg.norm(solver.f_int)) or 1.0
    return norm / scale


def with_phase(b: Built, row: dict[str, Any], points: pd.DataFrame,
                ) -> tuple[dict[str, Any], pd.DataFrame]:
    """``row`` and ``points`` with the stepping phase's name after ``step``; in ``row``,
    for every boundary a pressure acts on in any phase, the pressure [Pa] on it
    ``{name}_pressure`` and (unless a condition moves it) its mean displacement along the
    pressure ``{name}_displacement`` [m] (into the body)."""
    plan = b.plans[b.phase]
    row = {"step": row["step"], "phase": plan.name, **row}
    lam = float(row["load_factor"])
    for name, inward in b.pressed.items():
        start, end = plan.pressures.get(name, (0.0, 0.0))
        row[f"{name}_pressure"] = (1.0 - lam) * start + lam * end
        if name not in b.moved:
            row[f"{name}_displacement"] = float(
                inward @ np.array([row[f"{name}_displacement_x"],
                                   row[f"{name}_displacement_y"]]))
    points.insert(1, "phase", plan.name)
    return row, points


def ends_phase(b: Built, step: int) -> bool:
    """Whether ``step`` is the last of a phase (its state is saved: a resume there starts
    the next phase as an uninterrupted run does)."""
    return any(step == plan.last_step for plan in b.plans)


def _enter_phase(b: Built, solver: NewtonSolver, plan: PhasePlan,
                 checkpoint: Any) -> None:
    """Start ``plan`` from the solver's committed state: its prescribed displacements from
    where the state holds them, its reported displacement reset where it asks, and what a
    resume needs kept in ``checkpoint`` (the start and the reset displacement)."""
    u_start = solver.u.copy()
    loading = replace(plan.problem.loading,
                      dirichlet_start=u_start[plan.problem.loading.dirichlet_dofs])
    if plan.reset:
        b.offset = u_start.copy()
    solver.start_phase(loading, plan.settings)
    b.phase = plan.index
    residual = phase_start_residual(solver)
    b.start_residuals[plan.index] = residual
    if checkpoint is not None:
        offset = np.zeros_like(u_start) if b.offset is None else b.offset
        checkpoint.save_table(f"phase_{plan.index}", pd.DataFrame({"u_start": u_start,
                                                                    "offset": offset}))
        remember(checkpoint, f"phase_{plan.index}_start",
                 {"index": plan.index, "first_step": plan.first_step,
                  "start_residual": residual, "offset": float(b.offset is not None)})


def _saved_phase(b: Built, checkpoint: Any, index: int) -> np.ndarray:
    """The displacement [m] phase ``index`` started from, as its start kept it; the reset
    displacement in force from it set on ``b`` (SpecError: the checkpoint lacks them)."""
    table = None if checkpoint is None else checkpoint.load_table(f"phase_{index}")
    start = remember(checkpoint, f"phase_{index}_start")
    if table is None or not start:
        raise SpecError("out", f"cannot resume: the checkpoint lacks the start of phase "
                               f"{index + 1} ({b.plans[index].name!r}) (nothing in the "
                               "folder was changed)")
    b.offset = table["offset"].to_numpy(dtype=float).copy() if start["offset"] else None
    b.start_residuals[index] = start["start_residual"]
    return table["u_start"].to_numpy(dtype=float).copy()


def run_phases(b: Built, solver: NewtonSolver,
               collect: Callable[[NewtonSolver, StepRecord], None], checkpoint: Any,
               resumed: int | None) -> None:
    """Step every phase of ``b`` in turn from the state the one before committed; a run
    ``resumed`` after its committed step goes on inside the phase that step belongs to
    (NewtonError: the phase ``b.phase`` failed, the earlier ones' steps kept)."""
    spec = b.spec
    first, done = (0, 0) if resumed is None else phase_of_step(
        [plan.steps for plan in b.plans], resumed)
    for index in range(1, first):  # the phases before: their resets and start residuals
        _saved_phase(b, checkpoint, index)
    b.phase = first
    if first > 0 and done > 0:  # inside a later phase: its loading from where it started
        plan = b.plans[first]
        u_start = _saved_phase(b, checkpoint, first)
        loading = replace(plan.problem.loading,
                          dirichlet_start=u_start[plan.problem.loading.dirichlet_dofs])
        solver.start_phase(loading, plan.settings, restart=False)
    for plan in b.plans[first:]:
        steps_done = done if plan.index == first else 0
        if plan.index > 0 and steps_done == 0:
            _enter_phase(b, solver, plan, checkpoint)
        b.phase = plan.index
        solver.run(plan.steps, on_step=collect, progress=spec.progress,
                   description=f"{spec.name}: {plan.name} ({plan.problem.basis.nelems} "
                               "elements)", done=steps_done)


def phases_summary(b: Built, solver: NewtonSolver, steps: pd.DataFrame, error: str | None,
                    interrupted: bool) -> dict[str, Any]:
    """A phased run's summary: every phase with its status ("completed", "failed",
    "stopped" by an interrupt, or "not started"), its steps and the load factor it reached
    (of a failed one, the last committed, perhaps between steps after cut-backs); the phase
    that failed."""
    phases = []
    failed = None
    for plan in b.plans:
        rows = steps[(steps["step"] > 0) & (steps["phase"] == plan.name)] if len(steps) \
            else steps
        reached = float(rows["load_factor"].iloc[-1]) if len(rows) else 0.0
        status = "not started"
        if len(rows) == plan.steps:
            status = "completed"
        elif error is not None and plan.index == b.phase:
            status = "stopped" if interrupted else "failed"
            if not interrupted:
                reached = max(reached, float(solver.load_factor))
                failed = plan.name
        entry: dict[str, Any] = {
            "name": plan.name, "status": status, "steps": plan.steps,
            "steps_done": len(rows), "first_step": plan.first_step + 1,
            "load_factor": reached,
            "gravity_factor": (None if plan.view.gravity_factor is None
                               else list(plan.view.gravity_factor)),
            "reset_displacements": plan.reset,
            "start_residual": b.start_residuals.get(plan.index),
        }
        if status in ("failed", "stopped"):
            entry["error"] = error
        phases.append(entry)
    return {"phases": phases, "failed_phase": failed, "gravity_factor": None,
            "steps_planned": sum(plan.steps for plan in b.plans)}


def phased_figure(b: Built, steps: pd.DataFrame, bodies: list[tuple[str, str, float]],
                  out: Path, size: float = 0.0) -> None:
    """load_displacement.png of a phased run: every moved body's mean pressure (force over
    its length) and every pressure's value against the displacement along them, each phase
    a line (``size``: the domain's larger extent [m], for the unit of length)."""
    frame = steps.copy()
    curves = []
    for name, axis, width in bodies:
        force = frame[f"{name}_force_{axis}"].to_numpy(dtype=float)
        sign = -1.0 if np.nanmean(force[1:]) < 0 else 1.0
        frame[f"{name}_mean_pressure"] = sign * force / width
        curves.append((name, f"{name}_mean_pressure", f"{name}_displacement"))
    curves += [(name, f"{name}_pressure", f"{name}_displacement") for name in b.pressed
               if name not in b.moved]
    if curves:
        plot_phased_load_displacement(frame, curves, out / "load_displacement.png",
                                      resets={plan.name for plan in b.plans if plan.reset},
                                      size=size)
