"""The run loop: drive any material through a biaxial problem and collect its per-step
tables (:mod:`granular_material.results.biaxial` says what each column is) into a
:class:`~granular_material.results.BiaxialResult`, shown to an observer as they come, with
the tracked points' post-processors run and the run's checkpoint kept
(:mod:`granular_material.runs.checkpoint`).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import replace
from typing import Any, Protocol

import numpy as np
import pandas as pd

from granular_material.fem import (
    BiaxialProblem,
    BiaxialSetup,
    Material,
    NewtonError,
    NewtonSettings,
    NewtonSolver,
    Regularisation,
    StepRecord,
    Tracking,
    build_biaxial,
    to_points,
)
from granular_material.results.biaxial import COST_COLUMNS, BiaxialResult
from granular_material.runs.checkpoint import RunCheckpoint, SavedRun
from granular_material.runs.run_folder import interrupted_error
from granular_material.timing import PhaseTimes

__all__ = ["RunObserver", "run_biaxial"]


class RunObserver(Protocol):
    """Something that follows a run as it goes (e.g. the writers of
    :class:`granular_material.results.BiaxialWriter`)."""

    def start(self, problem: BiaxialProblem) -> None:
        """Called once, before the initial state is recorded."""
        ...

    def record(self, row: dict[str, Any], points: pd.DataFrame, u: np.ndarray,
               tracked: pd.DataFrame | None = None) -> None:
        """Called with every committed step (step 0 first): its ``steps`` row, its Gauss-point
        table, the nodal displacement [m] (ndofs,) and the step's tracked rows (None when
        the step is not tracked)."""
        ...

    def finish(self, result: BiaxialResult) -> None:
        """Called once with what the run produced, however it ended."""
        ...


def _rows(solver: NewtonSolver, problem: BiaxialProblem, record: StepRecord | None):
    kinematics = solver.kinematics
    grad = solver.grad_u()
    strain = kinematics.strain(grad)
    stress = solver.response.stress
    jacobian = kinematics.current_volume(grad)
    w = problem.weights * jacobian / (problem.weights @ jacobian)
    s = problem.setup
    eps_a = solver.load_factor * s.axial_strain
    platen = problem.axial_stress(solver.reaction, solver.u if kinematics.finite else None)
    volumetric = (np.trace(strain, axis1=1, axis2=2) if not kinematics.finite
                  else jacobian - 1.0)
    w_reference = problem.weights / problem.weights.sum()
    fields = {k: np.asarray(v, dtype=float) for k, v in solver.response.fields.items()}
    step = record.step if record else 0
    mean_stress = np.einsum("p,pij->ij", w, stress)
    row = {
        "step": step, "load_factor": solver.load_factor, "axial_strain": eps_a,
        "platen_stress": platen, "confining": s.confining,
        "stress_ratio": platen / s.confining if s.confining > 0 else np.nan,
        "sxx": mean_stress[0, 0], "syy": mean_stress[1, 1], "sxy": mean_stress[0, 1],
        "volumetric_strain": float(w_reference @ volumetric),
        "void_ratio": float(w @ fields["void_ratio"]) if "void_ratio" in fields else np.nan,
        "iterations": record.iterations if record else 0,
        **{name: record.costs.get(name, 0) if record else 0 for name in COST_COLUMNS},
        "cutbacks": record.cutbacks if record else 0,
        "stalled": record.stalled if record else 0,
        "wall_time": record.wall_time if record else 0.0,
        "residual_history": json.dumps(record.residual_history if record else []),
        "converged_by": "+".join(record.converged_by) if record else "",
        "correction_history": json.dumps(record.correction_history if record else []),
    }
    dem_points = getattr(solver.material, "dem_points", None)
    if dem_points is not None:  # an adaptive material: its DEM points after the step, and
        row["dem_points"] = int(dem_points)  # the work of the switches (beside the steps')
        row["switch_particle_steps"] = (record.costs.get("switch_particle_steps", 0)
                                        if record else 0)
    xy = to_points(np.asarray(problem.basis.global_coordinates()))
    n = stress.shape[0]
    nqp = problem.basis.X.shape[-1]
    points = pd.DataFrame({
        "step": step, "axial_strain": eps_a, "point": np.arange(n),
        "element": np.arange(n) // nqp, "x": xy[:, 0], "y": xy[:, 1],
        "sxx": stress[:, 0, 0], "syy": stress[:, 1, 1], "sxy": stress[:, 0, 1],
        "exx": strain[:, 0, 0], "eyy": strain[:, 1, 1], "exy": strain[:, 0, 1],
        "volumetric_strain": volumetric,
        "shear_strain": np.hypot(strain[:, 0, 0] - strain[:, 1, 1], 2 * strain[:, 0, 1]),
        **fields,
    })
    return row, points


def _timings(records: list[StepRecord], between: PhaseTimes) -> dict[str, float]:
    """Seconds by phase of ``records`` (``steps``: their wall time) and ``between`` them."""
    times = PhaseTimes(between.seconds)
    for record in records:
        times.add_all(record.timings)
        times.add("steps", record.wall_time)
    return times.as_dict()


def _failures(records: list[StepRecord]) -> dict[str, int]:
    """Failed point-evaluations by reason over ``records``."""
    out: dict[str, int] = {}
    for record in records:
        for reason, count in record.failures.items():
            out[reason] = out.get(reason, 0) + int(count)
    return dict(sorted(out.items()))


class _Collector:
    """The tables of a run as its steps commit: kept here, shown to the observer, saved in
    the checkpoint (with the committed state when one is due), tracked points analysed."""

    def __init__(self, problem: BiaxialProblem, material: Material, n_steps: int,
                 observer: RunObserver | None, tracking: Tracking | None,
                 checkpoint: RunCheckpoint | None,
                 on_step: Callable[[NewtonSolver, StepRecord, pd.DataFrame], None] | None,
                 ) -> None:
        self.problem, self.material, self.n_steps = problem, material, n_steps
        self.observer, self.tracking, self.checkpoint = observer, tracking, checkpoint
        self.on_step = on_step
        self.rows: list[dict[str, Any]] = []
        self.tables: list[pd.DataFrame] = []
        self.displacements: list[np.ndarray] = []
        self.tracked: list[pd.DataFrame] = []
        self.times = PhaseTimes()  # what this process spends between the load steps

    def keep(self, row: dict[str, Any], points: pd.DataFrame, u: np.ndarray,
             tracked: pd.DataFrame | None) -> None:
        """One committed step's row, Gauss-point table, displacement and tracked rows."""
        self.rows.append(row)
        self.tables.append(points)
        self.displacements.append(u.copy())
        if tracked is not None:
            self.tracked.append(tracked)
        if self.observer is not None:
            self.observer.record(row, points, u, tracked)

    def collect(self, solver: NewtonSolver, record: StepRecord | None) -> None:
        """The step ``solver`` has just committed (``record`` None: the initial state)."""
        times = self.times
        if record is None:
            with times.phase("initial_state"):
                solver.response  # noqa: B018 (the material's first evaluation, timed here)
        with times.phase("tables"):
            row, points = _rows(solver, self.problem, record)
        tracked = None
        n_points = self.problem.setup.n_points
        if self.tracking is not None and self.tracking.due(row["step"]):
            with times.phase("tracking"):
                tracked = self.tracking.rows(self.material, row["step"], row["axial_strain"],
                                             n_points)
        with times.phase("tables"):
            self.keep(row, points, solver.u, tracked)
            if self.checkpoint is not None:
                self.checkpoint.save_step(row, points, solver.u, tracked)
        if self.checkpoint is not None and self.checkpoint.due(row["step"], self.n_steps):
            with times.phase("checkpoint"):
                self.checkpoint.save_state(row["step"], solver, self.material)
        if self.on_step is not None and record is not None:
            self.on_step(solver, record, points)

    def result(self, solver: NewtonSolver, error: str | None, saved: SavedRun | None,
               interrupt: KeyboardInterrupt | None,
               unfinished: list[StepRecord]) -> BiaxialResult:
        """What the run produced (``unfinished``: the records of the step a Newton failure
        stopped, whose failed points count too)."""
        return BiaxialResult(
            problem=self.problem, steps=pd.DataFrame(self.rows),
            points=pd.concat(self.tables, ignore_index=True),
            displacements=np.array(self.displacements), records=list(solver.records),
            error=error,
            tracked=(pd.concat(self.tracked, ignore_index=True) if self.tracked
                     else pd.DataFrame()),
            resumed_from=None if saved is None else saved.step, interrupt=interrupt,
            failures=_failures([*solver.records, *unfinished]),
            timings=_timings([*solver.records, *unfinished], self.times),
            regularisation=solver.regularisation_summary(),
        )


def run_biaxial(
    setup: BiaxialSetup,
    material: Material,
    n_steps: int,
    settings: NewtonSettings | None = None,
    *,
    stress_tol: float = 0.0,
    observer: RunObserver | None = None,
    tracking: Tracking | None = None,
    checkpoint: RunCheckpoint | None = None,
    resume: bool = False,
    restored: bool = False,
    progress: bool = False,
    on_step: Callable[[NewtonSolver, StepRecord, pd.DataFrame], None] | None = None,
    regularisation: Regularisation | None = None,
) -> BiaxialResult:
    """Drive ``material`` through a drained biaxial test in ``n_steps`` load steps.

    ``stress_tol`` [Pa] > 0 sets the absolute Newton tolerance to the residual of that stress
    error (:meth:`BiaxialProblem.force_tolerance`): DEM stress carries noise that a cut-back
    does not reduce, while the relative test ‖R‖/‖R₀‖ tightens with every halving.

    A :class:`NewtonError` does not propagate: the committed steps are returned with
    ``error`` set. Nor does an interrupt (Ctrl-C): a long run stopped by hand returns the
    steps committed so far. ``observer`` (e.g. :class:`granular_material.results.BiaxialWriter`)
    sees every committed step as it comes and the result at the end, in both cases.
    ``on_step(solver, record, points)`` is called after every committed load step.
    ``tracking`` runs post-processors on chosen points' committed RVEs (``result.tracked``).
    ``regularisation`` (:class:`~granular_material.fem.regularisation.Regularisation`) adds
    the second gradient's terms; None or model "none": the classical medium.

    ``checkpoint`` saves every committed step and, when it says a save is due (every
    ``checkpoint.every`` steps, or by elapsed time), the committed state of solver and
    material. ``resume``
    continues from its last whole checkpoint (the material is restored from it: it need not
    be allocated) and gives the same steps, tables and final state as a run that never
    stopped; with no state saved yet the run starts from the beginning. The observer sees the
    saved steps again first. ``restored``: the caller has already restored ``material`` from
    that checkpoint (so that one it refuses is refused before anything is written).
    """
    problem = build_biaxial(setup)
    if tracking is not None:
        tracking.check_points(setup.n_points)
    if stress_tol < 0 or not np.isfinite(stress_tol):
        raise ValueError(f"stress_tol must be a stress >= 0 Pa, got {stress_tol!r}")
    if stress_tol > 0:
        settings = replace(settings or NewtonSettings(),
                           atol=problem.force_tolerance(stress_tol))
    saved: SavedRun | None = None
    if resume and checkpoint is not None and checkpoint.has_state():
        saved = checkpoint.load()
        if not restored:
            material.restore(saved.material_path)
    solver = NewtonSolver(problem.basis, material, problem.loading, settings,
                          regularisation)
    if saved is not None:
        solver.resume(saved.state)
    steps = _Collector(problem, material, n_steps, observer, tracking, checkpoint, on_step)
    if observer is not None:
        observer.start(problem)
    error = None
    interrupt = None
    unfinished: list[StepRecord] = []  # the record of the step a NewtonError stopped
    try:
        if saved is None:
            steps.collect(solver, None)
        else:
            for step in saved.steps:
                steps.keep(step.row, step.points, step.u, step.tracked)
        solver.run(n_steps, on_step=steps.collect, progress=progress,
                   description=f"biaxial {setup.nx}x{setup.ny}",
                   done=0 if saved is None else saved.step)
    except NewtonError as exc:
        error = str(exc)
        unfinished = exc.records[len(solver.records):]
    except KeyboardInterrupt as exc:
        error = interrupted_error(len(steps.rows) - 1, n_steps)
        interrupt = exc
    result = steps.result(solver, error, saved, interrupt, unfinished)
    if observer is not None:
        observer.finish(result)
    return result
