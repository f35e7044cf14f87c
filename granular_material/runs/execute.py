"""Run a :class:`~granular_material.runs.spec.RunSpec`: the library's one entry point for a
FEM run, which the command line, scenes, studies and the reproduction all call; a DEM run's
spec (:mod:`granular_material.runs.dem`) is handed to
:func:`~granular_material.runs.dem.run_dem`.

:func:`check` makes every check a run makes before any work (nothing is allocated, written
or locked) and returns the :class:`RunPlan`; :func:`run` checks, then runs into the output
folder (locked while it runs, checkpointed, resumable) and returns a :class:`RunOutcome`.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.checks import (
    DISC_BYTES,
    check_memory,
    check_output_dir,
    cleanup_on_rejection,
)
from granular_material.errors import ParameterError
from granular_material.fem import BiaxialSetup, Material, Tracking
from granular_material.fem.materials.run_context import RunContext
from granular_material.results import (
    BiaxialResult,
    BiaxialWriter,
    band_summary,
    find_peak,
    run_summary,
    write_csv,
    write_json,
    write_outputs,
)
from granular_material.results.lock import FolderLock
from granular_material.runs.checkpoint import RunCheckpoint
from granular_material.runs.dem import DemOutcome, DemPlan, DemSpec, is_dem, run_dem
from granular_material.runs.dem import check as check_dem
from granular_material.runs.resume import (
    FailedRunError,
    StoppedRunError,
    open_checkpoint,
    start_checkpoint,
)
from granular_material.runs.run_folder import starting
from granular_material.runs.runner import RunObserver, run_biaxial
from granular_material.runs.spec import (
    FULL_SCALE,
    MAX_TRACKED_ROWS,
    REDUCED_SCALE,
    RunSpec,
    SpecError,
)
from granular_material.timing import PhaseTimes, phase_table

__all__ = ["RunOutcome", "RunPlan", "check", "run"]

#: memory of one element of the mesh beside its RVEs, about [bytes]: its stiffness entries
#: in assembly, its Gauss points' tables and tangents, with room for the solver
_ELEMENT_BYTES = 16_384
#: memory of one Gauss point's row of one load step, kept for the tables [bytes]
_POINT_ROW_BYTES = 400


@dataclass(frozen=True)
class RunPlan:
    """What a checked spec will run: the device chosen, the mesh, the material's context."""

    spec: RunSpec
    device: str
    setup: BiaxialSetup
    context: RunContext
    discs: int
    tracking: Tracking | None


@dataclass
class RunOutcome:
    """What :func:`run` produced: the result, its summary (as ``summary.json``), and the
    pure-DEM reference curve of a single element where the material gave one."""

    result: BiaxialResult
    summary: dict[str, Any]
    reference: pd.DataFrame | None = None
    plan: RunPlan | None = field(default=None, repr=False)
    #: seconds by phase of the whole run (the summary's ``timing_s``): preparation,
    #: reference, the load steps' parts, tables, checkpoints, outputs
    timing: dict[str, float] = field(default_factory=dict)

    @property
    def interrupt(self) -> KeyboardInterrupt | None:
        """The interrupt that stopped the run early, if one did."""
        return self.result.interrupt


def _device(spec: RunSpec) -> str:
    """The DEM device of the run. A material that holds no RVEs (no ``check_run`` hook) runs
    on the CPU where no other device is asked for and the mesh does not depend on it: warp is
    then not loaded at all (issue 62)."""
    problem = spec.problem
    by_device = problem.test == "biaxial" and not problem.elements and not problem.scale
    if (spec.device in (None, "cpu") and not by_device
            and not hasattr(spec.material.cls, "check_run")):
        return "cpu"
    from granular_material.dem import resolve_device

    return resolve_device(spec.device)


def _tracking(spec: RunSpec, n_points: int) -> Tracking | None:
    track = spec.output.track
    if track is None:
        return None
    if not hasattr(spec.material.cls, "committed_rves"):
        raise ParameterError("track", f"needs `material` dem (its Gauss points carry RVEs), "
                                      f"not {spec.material.name}")
    tracking = Tracking.parse(spec.output.postprocessors(), track, spec.output.every)
    tracking.check_points(n_points)
    rows = spec.output.tracked_rows(n_points, spec.problem.steps)
    if rows > MAX_TRACKED_ROWS:
        points = n_points if "all" in track else len(track)
        raise SpecError("track", f"would post-process {rows} RVEs ({points} points × "
                                 f"{len(spec.output.postprocessors())} post-processors × "
                                 f"{spec.problem.steps // spec.output.every + 1} tracked "
                                 f"steps), at most {MAX_TRACKED_ROWS}: track fewer points, "
                                 "fewer post-processors or a larger every")
    return tracking


def _check_size(spec: RunSpec, setup: BiaxialSetup, discs: int) -> None:
    """The mesh, its RVEs and the tables of every step fit in memory; a specimen has the 4
    Gauss points its shear-band measures need."""
    steps = spec.problem.steps
    if spec.problem.test == "biaxial" and setup.n_points < 4:
        raise ParameterError("element", f"{setup.element} on `elements` {setup.nx} {setup.ny} "
                                        f"has {setup.n_points} Gauss points; the shear-band "
                                        "measures of a biaxial run need at least 4 (more "
                                        "elements)")
    needed = (float(setup.n_elements) * _ELEMENT_BYTES
              + float(setup.n_points) * discs * DISC_BYTES
              + float(setup.n_points) * (steps + 1) * _POINT_ROW_BYTES)
    held = f" of {discs}-disc RVEs" if discs else ""
    check_memory(needed, f"{setup.n_elements} {setup.element} elements ({setup.n_points} "
                         f"Gauss points{held}) over {steps} load steps")


def check(spec: RunSpec | DemSpec) -> RunPlan | DemPlan:
    """Every check of the run before any work (its output folder, memory, the material's
    inputs, tracked points); nothing is allocated or written. The plan of the run (a DEM
    run's: :func:`granular_material.runs.dem.check`)."""
    if is_dem(spec):
        return check_dem(spec)
    check_output_dir(spec.output.out)
    device = _device(spec)
    elements, scale_discs = spec.problem.mesh(device)
    setup = spec.problem.setup(elements)
    context = RunContext(test=spec.problem.test, n_points=setup.n_points,
                         confining=spec.problem.confining,
                         axial_strain=spec.problem.axial_strain, steps=spec.problem.steps,
                         scale_discs=scale_discs, device=device, shards=spec.shards,
                         backend=spec.backend, progress=spec.output.progress,
                         convergence=spec.newton.convergence_test(spec.material.noisy))
    cls = spec.material.cls
    hook = getattr(cls, "check_run", None)
    discs = hook(spec.material.parameters, context) if hook is not None else 0
    _check_size(spec, setup, discs)
    tracking = _tracking(spec, setup.n_points)
    calibration = None if spec.adaptivity is None else spec.adaptivity.calibration
    if calibration is not None and not calibration.is_file():
        raise SpecError("calibration", f"{calibration} is no file (a calibration.json written "
                                       "by granular-material calibrate)")
    if hasattr(cls, "for_run"):  # the material's own checks of what it is built from
        _built(spec, context)
    return RunPlan(spec=spec, device=device, setup=setup, context=context, discs=discs,
                   tracking=tracking)


def _built(spec: RunSpec, context: RunContext) -> Material:
    """The material of the run, not yet allocated."""
    cls = spec.material.cls
    if hasattr(cls, "for_run"):
        return cls.for_run(spec.material.parameters, context)
    return cls(**spec.material.values())


def _adaptive(plan: RunPlan, dem: Material, saved: Path | None = None) -> Material:
    """The adaptive material of the specimen from its DEM material ``dem`` (not allocated):
    the RVEs the all-DEM run would give its points (seed, seed + 1, … or the file's) become
    the points' sources, the Mohr–Coulomb twin is calibrated from the first at the
    confining pressure (or read from ``adaptivity.calibration``), and every point starts on
    it at −confining·I
    (:class:`~granular_material.multiscale.adaptive.AdaptiveMaterial`). A resumed run
    (``saved``: its material's checkpoint) makes the same material from the calibration and
    sources its checkpoint holds, preparing and calibrating nothing (a checkpoint from
    before it held them: prepared and calibrated again), then takes every point's state
    from it. Not allocated; its ``calibration`` says how the twin was made, with the
    seconds it took."""
    from granular_material.multiscale.adaptive import adaptive_for_resume, calibrated_adaptive

    spec, setup = plan.spec, plan.setup
    adaptivity, confining = spec.adaptivity, float(spec.problem.confining)
    sigma0 = np.repeat(-confining * np.eye(2)[None], setup.n_points, axis=0)
    if saved is not None:
        material = adaptive_for_resume(saved, dem.parameters, sigma0, adaptivity.criterion(),
                                       nqp=setup.points_per_element, start=adaptivity.start,
                                       progress=spec.output.progress)
        if material is not None:
            return material
    dem.allocate(setup.n_points)
    began = time.perf_counter()
    material = calibrated_adaptive(dem.committed_rves(), dem.parameters, confining, sigma0,
                                   adaptivity.criterion(), nqp=setup.points_per_element,
                                   start=adaptivity.start,
                                   calibration=adaptivity.calibration,
                                   elastic_window=adaptivity.elastic_window,
                                   progress=spec.output.progress)
    material.calibration = {**material.calibration,
                            "seconds": round(time.perf_counter() - began, 3)}
    return material


def _scale_name(plan: RunPlan) -> str:
    """The specimen scale that ran when mesh and discs are its own, else ``custom``."""
    problem = plan.spec.problem
    scale = problem.resolved_scale(plan.device)
    preset = FULL_SCALE if scale == "full" else REDUCED_SCALE
    elements = (plan.setup.nx, plan.setup.ny)
    return scale if (elements, plan.discs) == (tuple(preset[0]), preset[1]) else "custom"


@contextlib.contextmanager
def _locked(out: Path | None) -> Iterator[None]:
    """The output folder locked for the run (a second run into it is refused at once)."""
    if out is None:
        yield
        return
    lock = FolderLock(out)
    lock.acquire()
    try:
        yield
    finally:
        lock.release()


def run(spec: RunSpec | DemSpec, observer: RunObserver | None = None, *,
        resume: bool = False, fresh: bool = False,
        keep_stopped: bool | None = None) -> RunOutcome | DemOutcome:
    """Run ``spec``: check it (:func:`check`), lock and write its output folder as it goes
    (tables, fields, figures, ``summary.json``; checkpoints of the committed state, see
    :class:`~granular_material.runs.checkpoint.RunCheckpoint`), and return the outcome.

    ``resume`` continues the run whose checkpoint is in ``output.out`` (its spec must be this
    one, but for where and how it reports; with no saved step it starts afresh). A fresh run
    into a folder that holds the checkpoint of a run stopped before its last load step is
    refused (a ParameterError of ``out``, nothing in the folder changed), as the commands
    refuse it:
    continue it with ``resume=True``, or pass ``fresh=True`` to throw that checkpoint away
    and start from step 0. A finished run's checkpoint is replaced. (``keep_stopped=False``
    is the older spelling of ``fresh=True``.)

    ``observer`` follows every committed step as
    :class:`~granular_material.runs.runner.RunObserver`. A Newton failure or an interrupt
    ends the run early with the steps so far (``outcome.result.error``,
    ``outcome.interrupt``), its committed steps kept in the folder's checkpoint; bad input
    is a ``ValueError`` (a :class:`~granular_material.runs.spec.SpecError` naming the field
    where it is one) before any work.

    A DEM run's spec (``prepare``, ``biaxial-dem``, ``dem-drive``:
    :mod:`granular_material.runs.dem`) runs as
    :func:`~granular_material.runs.dem.run_dem` does, with the same ``resume`` and ``fresh``,
    and returns its :class:`~granular_material.runs.dem.DemOutcome` (no observer)."""
    if is_dem(spec):
        if observer is not None:
            raise ParameterError("observer", "follows the load steps of a FEM run; a DEM "
                                             "run has none")
        if keep_stopped is not None:
            fresh = fresh or not keep_stopped
        return run_dem(spec, resume=resume, fresh=fresh)
    started = time.perf_counter()
    if not isinstance(spec, RunSpec):
        raise ParameterError("spec", f"run() takes a RunSpec, got {type(spec).__name__}")
    if keep_stopped is not None:
        fresh = fresh or not keep_stopped
    if resume and fresh:
        raise ParameterError("resume", "and fresh exclude each other: resume continues the "
                                       "stopped run, fresh throws its checkpoint away")
    out = spec.output.out
    if resume and out is None:
        raise ParameterError("resume", "needs the run's output folder (output.out)")
    check_output_dir(out)
    times = PhaseTimes()
    with _locked(out):
        try:
            checkpoint, saved = open_checkpoint(spec, resume, keep_stopped=not fresh)
        except FailedRunError as exc:
            raise FailedRunError(exc.field, f"{exc.message} (from Python: run(spec, "
                                            "fresh=True) starts afresh over it)") from None
        except StoppedRunError as exc:
            raise StoppedRunError(exc.field, f"{exc.message} (from Python: run(spec, "
                                             "resume=True) continues it, run(spec, "
                                             "fresh=True) starts afresh over it)") from None
        plan = check(spec)
        material = _built(spec, plan.context)
        material_file = checkpoint.load(tidy=False).material_path if saved else None
        if spec.adaptivity is not None:  # the RVEs prepared and the twin calibrated first
            with times.phase("preparation"):  # (a resume: made from its checkpoint)
                material = _adaptive(plan, material, material_file)
        # the material allocated, or restored (an older checkpoint refused), before the
        # folder is touched
        if material_file is not None:
            material.restore(material_file)
        else:
            with times.phase("preparation"):
                material.allocate(plan.setup.n_points)
        if out is not None:
            starting()  # every check passed: the run writes its folder from here on
        with cleanup_on_rejection(out), start_checkpoint(spec, checkpoint, saved):
            reference = _reference(material, plan, checkpoint, times)
            outcome = _execute(plan, material, observer, checkpoint, saved)
        outcome.reference = reference
        _finish(plan, outcome, times, started)
    return outcome


def _reference(material: Any, plan: RunPlan, checkpoint: RunCheckpoint | None,
               times: PhaseTimes) -> pd.DataFrame | None:
    """A single element's pure-DEM curve, where its parameters ask for one: computed once
    from the RVE before the first load step (timed as ``reference`` in ``times``), kept in
    the checkpoint."""
    if not getattr(plan.spec.material.parameters, "compare_dem", False):
        return None
    with times.phase("reference"):
        return _reference_curve(material, plan, checkpoint)


def _reference_curve(material: Any, plan: RunPlan, checkpoint: RunCheckpoint | None,
                     ) -> pd.DataFrame:
    """The pure-DEM curve from the checkpoint, or computed and saved there."""
    saved = None if checkpoint is None else checkpoint.load_table("pure_dem")
    if saved is not None:
        return saved
    problem = plan.spec.problem
    curve = material.reference_curve(problem.axial_strain, problem.confining, plan.device,
                                     progress=plan.spec.output.progress)
    if checkpoint is not None:
        checkpoint.save_table("pure_dem", curve)
    return curve


def _execute(plan: RunPlan, material: Material, observer: RunObserver | None,
             checkpoint: RunCheckpoint | None, resuming: bool) -> RunOutcome:
    """The FEM run, written under the output folder as it goes; result and summary."""
    spec = plan.spec
    noisy = spec.material.noisy
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        writer = (stack.enter_context(BiaxialWriter(spec.output.out,
                                                    points_csv=spec.output.points_csv))
                  if spec.output.out is not None else None)
        observers = [o for o in (writer, observer) if o is not None]
        result = run_biaxial(plan.setup, material, spec.problem.steps,
                             spec.newton.settings(noisy), progress=spec.output.progress,
                             observer=_Fanout(observers) if observers else None,
                             stress_tol=spec.newton.stress_tolerance(
                                 noisy, spec.problem.confining),
                             tracking=plan.tracking, checkpoint=checkpoint, resume=resuming,
                             restored=resuming,
                             regularisation=spec.regularisation.regularisation())
    summary = run_summary(result, time.perf_counter() - t0)
    summary["resumed_from_step"] = result.resumed_from
    if result.regularisation is not None:
        summary["regularisation"] = result.regularisation
    summary["preset"] = spec.preset
    if spec.adaptivity is not None:
        summary["adaptivity"] = material.summary()
    summary.update(element=plan.setup.element,
                   points_per_element=plan.setup.points_per_element,
                   convergence=spec.newton.convergence_test(noisy))
    if plan.tracking is not None:
        summary["tracked_rows"] = len(result.tracked)
        summary["tracking_time_s"] = (float(result.tracked["seconds"].sum())
                                      if len(result.tracked) else 0.0)
    return RunOutcome(result=result, summary=summary, plan=plan)


class _Fanout:
    """Several run observers as one."""

    def __init__(self, observers: list[RunObserver]) -> None:
        self.observers = observers

    def start(self, problem: Any) -> None:
        for o in self.observers:
            o.start(problem)

    def record(self, *args: Any) -> None:
        for o in self.observers:
            o.record(*args)

    def finish(self, result: BiaxialResult) -> None:
        for o in self.observers:
            o.finish(result)


def _material_summary(plan: RunPlan) -> dict[str, Any]:
    hook = getattr(plan.spec.material.cls, "run_summary", None)
    return hook(plan.spec.material.parameters, plan.context) if hook is not None else {}


def _finish(plan: RunPlan, outcome: RunOutcome, times: PhaseTimes, started: float) -> None:
    """The summary's last entries (``timing_s``: the run's seconds by phase, ``times`` those
    of what ran before the load steps, ``started`` the run's start, time.perf_counter), and
    the outputs and ``summary.json`` under the folder."""
    spec, summary, result = plan.spec, outcome.summary, outcome.result
    out = spec.output.out
    if spec.problem.test == "biaxial":
        summary.update(scale=_scale_name(plan), elements=[plan.setup.nx, plan.setup.ny],
                       gauss_points=plan.setup.n_points, particles=plan.discs,
                       device=plan.device)
        summary.update(_material_summary(plan))
        summary.update(band_summary(result, list(spec.output.map_strain),
                                    summary["peak_stress_ratio"]))
    else:
        reference = outcome.reference
        if reference is not None:
            peak, ratio = find_peak(reference["axial_strain"].to_numpy(),
                                    reference["stress_ratio"].to_numpy())
            summary["dem_peak_stress_ratio"] = ratio
            summary["dem_axial_strain_at_peak"] = float(reference["axial_strain"].iloc[peak])
        summary.update(_material_summary(plan))
    if out is not None:
        with times.phase("outputs"):
            write_outputs(result, out, map_strain=list(spec.output.map_strain),
                          reference=outcome.reference, tables=False,  # the writer's, whole
                          figures=spec.output.figures)
            if outcome.reference is not None:
                write_csv(outcome.reference, Path(out) / "pure_dem.csv")
    times.add_all(result.timings)
    # a resumed run's steps before the resume count (in the parts and the whole) with the
    # time they took then; its preparation was that of the first process's
    earlier = (0.0 if result.resumed_from is None else
               sum(r.wall_time for r in result.records if r.step <= result.resumed_from))
    outcome.timing = phase_table(times.seconds, time.perf_counter() - started + earlier)
    # to the microsecond: a phase the run entered stays above zero however short
    summary["timing_s"] = {name: round(value, 6) for name, value in outcome.timing.items()}
    if out is not None:
        summary["out"] = str(out)
        if Path(out).is_dir():
            write_json(summary, Path(out) / "summary.json")
