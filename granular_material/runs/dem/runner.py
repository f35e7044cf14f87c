"""Run a DEM spec (:mod:`granular_material.runs.dem.spec`): :func:`check` makes every check
before any work and :func:`run_dem` runs it, as :func:`granular_material.runs.run` does for
a DEM spec: the output locked while it runs (in the checkpoint folder beside the output
file), a biaxial test or a path checkpointed after its records and resumable from them
(:mod:`granular_material.runs.dem.checkpoint`), and the report the commands print.

Messages name the spec's fields in backquotes (```confining```), which the command line
shows as its options (``--confining``).
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material import checks
from granular_material.errors import ParameterError
from granular_material.results.lock import FolderLock
from granular_material.runs.checkpoint_files import CheckpointError, file_sha256
from granular_material.runs.dem.checkpoint import DemCheckpoint, checkpoint_folder
from granular_material.runs.dem.serial import from_dict, to_dict, to_flat
from granular_material.runs.dem.spec import (
    BiaxialDemSpec,
    DemSpec,
    DriveSpec,
    PrepareSpec,
)
from granular_material.runs.resume import StoppedRunError
from granular_material.runs.run_folder import starting

__all__ = ["RESUME_FREE", "SERVO_FAIL", "SERVO_WARN", "DemOutcome", "DemPlan", "check",
           "run_dem"]

#: |σxx/(−confining) − 1| of a biaxial test: above SERVO_WARN at some record a warning;
#: above SERVO_FAIL over half the records (the median) the servo did not hold it: an error
SERVO_WARN = 0.02
SERVO_FAIL = 0.05
#: fields that may differ between a DEM run and its resume: where it writes the figure and
#: how it reports (neither changes a row)
RESUME_FREE = frozenset({"plot", "progress"})
#: how a biaxial test's and a path's checks name their values: by the spec's fields
_BIAXIAL_NAMES = {"axial_strain": "`axial_strain`", "confining": "`confining`",
                  "strain_per_step": "`strain_per_step`", "max_steps": "`max_dem_steps`"}
_PATH_NAMES = {"grad_u": "`grad_u`", "increments": "`increments`",
               "max_strain_per_step": "`max_strain_per_step`", "max_steps": "`max_dem_steps`"}


@dataclass(frozen=True)
class DemPlan:
    """What a checked DEM spec will run: the spec, and for ``prepare`` its packing
    parameters, for ``dem-drive`` the DEM steps of each increment."""

    spec: DemSpec
    packing: Any = None
    increments: tuple[int, ...] = ()


@dataclass
class DemOutcome:
    """What :func:`run_dem` produced: the command's ``report`` (the JSON it prints, but for
    ``error``), the ``error`` that ended the run (None: none), the warnings said, the
    ``table`` (the curve or the path; None for prepare), the interrupt that stopped it
    early, and the record it resumed from (None: it started afresh)."""

    report: dict[str, Any]
    error: str | None = None
    warnings: list[str] = field(default_factory=list)
    table: pd.DataFrame | None = None
    interrupt: KeyboardInterrupt | None = None
    resumed_from: int | None = None

    @property
    def summary(self) -> dict[str, Any]:
        """The report with its error (as the commands print it)."""
        return {**self.report, "error": self.error}


def _check_figure(path: Path | None, others: dict[str, Path | None]) -> None:
    """The figure file ``path`` (None: none) can be written, in a format matplotlib writes,
    and is no other output file."""
    if path is None:
        return
    checks.check_output_file(path, "plot")
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    suffix = Path(path).suffix.lower().removeprefix(".")
    if suffix not in formats:
        raise ParameterError("plot", f"{path}: a figure is written as one of "
                                     f"{', '.join('.' + f for f in sorted(formats))} (its "
                                     "suffix), not "
                                     f"{'.' + suffix if suffix else 'a file without suffix'}")
    for name, other in others.items():
        if other is not None and Path(other).resolve() == Path(path).resolve():
            raise ParameterError("plot", f"{path} and `{name}` {other} name the same file; "
                                         "give each its own")


def check(spec: DemSpec) -> DemPlan:
    """Every check of the DEM run before any work (its output files, the packing, the DEM
    steps it needs, memory); nothing is allocated or written. A refusal is a
    ParameterError naming the field."""
    if isinstance(spec, PrepareSpec):
        checks.check_output_file(spec.out)
        values = type("Fields", (), spec.packing_fields())()
        packing = checks.packing_parameters(values, spec.particles, spec.pressure)
        try:
            checks.check_memory(float(spec.batch) * spec.particles * checks.DISC_BYTES,
                                f"`batch` {spec.batch} RVEs of `particles` {spec.particles} "
                                "discs")
        except ValueError as exc:
            raise checks.WordedError("batch", str(exc)) from None
        return DemPlan(spec=spec, packing=packing)
    if isinstance(spec, BiaxialDemSpec):
        from granular_material.procedures.element_tests import check_biaxial

        checks.check_output_file(spec.out)
        _check_figure(spec.plot, {"out": spec.out})
        try:
            check_biaxial(spec.axial_strain, spec.confining, spec.strain_per_step,
                          spec.max_dem_steps, names=_BIAXIAL_NAMES)
        except ValueError as exc:
            raise checks.WordedError("axial_strain", str(exc)) from None
        return DemPlan(spec=spec)
    if isinstance(spec, DriveSpec):
        from granular_material.procedures import plan_path

        checks.check_output_file(spec.out)
        try:
            plan = plan_path(np.reshape(spec.grad_u, (2, 2)), spec.increments,
                             spec.max_strain_per_step, spec.max_dem_steps, names=_PATH_NAMES)
        except ValueError as exc:
            raise checks.WordedError("grad_u", str(exc)) from None
        return DemPlan(spec=spec, increments=tuple(plan))
    raise ParameterError("spec", f"is no DEM run's spec: {type(spec).__name__}")


def _rve_list(indices: np.ndarray, values: np.ndarray, fmt: str) -> str:
    """``RVE 0: …, RVE 3: …`` of the first five ``indices`` with their ``values``."""
    shown = ", ".join(f"RVE {i}: {format(values[i], fmt)}" for i in indices[:5])
    return shown + (f" and {len(indices) - 5} more" if len(indices) > 5 else "")


def _device(spec: DemSpec) -> str:
    from granular_material.dem import resolve_device

    return resolve_device(spec.device)


# -- the lock and the checkpoint ---------------------------------------------------------------
@contextlib.contextmanager
def _locked(out: Path | None) -> Iterator[None]:
    """The run's checkpoint folder beside ``out`` locked for the run (None: no output)."""
    if out is None:
        yield
        return
    lock = FolderLock(checkpoint_folder(out))
    lock.acquire()
    try:
        yield
    finally:
        lock.release()


def _differences(spec: DemSpec, saved: DemSpec) -> list[str]:
    """The fields of ``spec`` that differ from ``saved``, each named in backquotes, but for
    those a resume may change (:data:`RESUME_FREE`)."""
    now, then = to_flat(spec), to_flat(saved)
    return [f"`{name}` {now.get(name)!r} (the run had {then.get(name)!r})"
            for name in now if name not in RESUME_FREE and now.get(name) != then.get(name)]


def _open(spec: BiaxialDemSpec | DriveSpec, resume: bool, fresh: bool,
          ) -> tuple[DemCheckpoint | None, Any]:
    """The run's checkpoint (None without an output file) and the record it resumes from
    (None: it starts afresh). A resume is checked against the saved spec, field by field,
    and its RVE file against the one the run started from; a fresh start over a stopped
    run's checkpoint is refused unless ``fresh``. Nothing in the folder is changed here."""
    if spec.out is None:
        if resume:
            raise ParameterError("resume", "needs the run's output file (`out`), beside "
                                           "which its checkpoint is kept")
        return None, None
    checkpoint = DemCheckpoint(checkpoint_folder(spec.out))
    if not resume:
        if checkpoint.has_state() and not fresh:
            raise StoppedRunError("out", f"{spec.out}: {checkpoint.folder} holds the "
                                         f"checkpoint of a {spec.test} run stopped part-way: "
                                         "continue it with `resume` (and the options it was "
                                         "started with), or start afresh over it with `fresh`; "
                                         "nothing was changed")
        return checkpoint, None
    if not checkpoint.has_options():
        print(f"granular-material {spec.test}: {checkpoint.folder} holds no saved record; "
              "the run starts from the beginning", file=sys.stderr)
        return checkpoint, None
    try:
        record = checkpoint.read_options()
        saved = from_dict(record["spec"])
    except (CheckpointError, ValueError) as exc:
        raise ParameterError("resume", f"{checkpoint.folder}: {exc}; nothing in the folder "
                                       "was changed") from None
    if saved.test != spec.test:
        raise ParameterError("resume", f"{checkpoint.folder} is a {saved.test} run, not "
                                       f"{spec.test}")
    differ = _differences(spec, saved)
    if not differ and record.get("rve_sha256") != file_sha256(spec.rve):
        differ = [f"`rve` {str(spec.rve)!r} (its content is not the file the run started "
                  "from)"]
    if differ:
        raise ParameterError("resume", f"{checkpoint.folder}: give the options the run was "
                                       f"started with; these differ: {'; '.join(differ)} "
                                       "(nothing in the folder was changed)")
    if not checkpoint.has_state():
        print(f"granular-material {spec.test}: {checkpoint.folder} holds no saved record "
              "yet; the run starts from the beginning", file=sys.stderr)
        return checkpoint, None
    try:
        return checkpoint, checkpoint.load()
    except CheckpointError as exc:
        raise ParameterError("resume", f"{exc}; nothing in the folder was changed") from None


def _started(spec: BiaxialDemSpec | DriveSpec, checkpoint: DemCheckpoint | None,
             saved: Any) -> None:
    """A fresh run records its spec in its checkpoint (an earlier one's emptied)."""
    if checkpoint is not None and saved is None:
        checkpoint.start({"test": spec.test, "spec": to_dict(spec),
                          "rve_sha256": file_sha256(spec.rve)})


def _batch(spec: BiaxialDemSpec | DriveSpec, rve: Path) -> Any:
    from granular_material.dem import DEMBatch, load_rve

    return DEMBatch(load_rve(rve), device=_device(spec), dtype=spec.dtype)


# -- the runs ------------------------------------------------------------------------------------
def run_dem(spec: DemSpec, *, resume: bool = False, fresh: bool = False) -> DemOutcome:
    """Run the DEM ``spec``: check it (:func:`check`), lock its output, run, and write its
    outputs; returns the outcome. ``resume`` continues the biaxial test or path whose
    checkpoint is beside ``out`` (its spec must be this one but for :data:`RESUME_FREE`,
    its RVE file the same; with no saved record it starts afresh); a fresh run over the
    checkpoint of a stopped one is refused (StoppedRunError of ``out``) unless ``fresh``.
    A ``prepare`` keeps no checkpoint: resumed, it starts again from its seed, which makes
    the same RVE file. An interrupt ends the run early with what it recorded
    (``outcome.interrupt``); bad input is a ParameterError naming the field before any
    work."""
    if resume and fresh:
        raise ParameterError("resume", "and fresh exclude each other: resume continues the "
                                       "stopped run, fresh throws its checkpoint away")
    plan = check(spec)
    if isinstance(spec, PrepareSpec):
        with _locked(spec.out):
            return _prepare(plan)
    with _locked(spec.out):
        checkpoint, saved = _open(spec, resume, fresh)
        # the RVE file read (one that cannot be is refused) before anything is written
        batch = _batch(spec, spec.rve if saved is None else saved.rve)
        if spec.out is not None:
            starting()  # every check passed: the run writes from here on
        _started(spec, checkpoint, saved)
        try:
            outcome = _biaxial(spec, checkpoint, saved, batch) \
                if isinstance(spec, BiaxialDemSpec) else _drive(plan, spec, checkpoint, saved,
                                                                 batch)
        except ValueError:  # input rejected once running: no checkpoint of a fresh run
            if checkpoint is not None and saved is None:
                checkpoint.remove()
            raise
        if checkpoint is not None and outcome.interrupt is None:
            checkpoint.remove()  # the run has ended: nothing to resume
    if checkpoint is not None and outcome.interrupt is None:
        with contextlib.suppress(OSError):  # its folder, where the lock left it behind
            checkpoint.folder.rmdir()
    return outcome


def _prepare(plan: DemPlan) -> DemOutcome:
    from granular_material.checks import make_parents
    from granular_material.dem import save_rve
    from granular_material.procedures import prepare_packing
    from granular_material.procedures.packing import VOID_RATIO_TOLERANCE

    spec: PrepareSpec = plan.spec  # type: ignore[assignment]
    packing = plan.packing
    batch = prepare_packing(
        n_disc=spec.particles, n_rve=spec.batch, seed=spec.seed, pressure=spec.pressure,
        meta=packing.meta, target_void_ratio=packing.target_void_ratio,
        radius_range=packing.radius_range, device=_device(spec), dtype=spec.dtype,
        progress=spec.progress,
    )
    h = batch.homogenize()
    report: dict[str, Any] = batch.summary(h)
    outcome = DemOutcome(report=report)
    target = spec.target_void_ratio
    if target is not None and (h.void_ratio > target).any():
        missed = np.flatnonzero(h.void_ratio > target)
        reached = _rve_list(missed, h.void_ratio, ".4g")
        text = (f"`target_void_ratio` {target:g} not reached under `pressure` "
                f"{spec.pressure:g} Pa: void ratio of {reached} (frictionless compaction "
                "reached the pressure first; a denser packing "
                "needs a higher `pressure`)")
        if (h.void_ratio > target + VOID_RATIO_TOLERANCE).any():
            outcome.error = text + "; no RVE file written"
        else:
            outcome.warnings.append(text)
    report["warnings"] = outcome.warnings
    if outcome.error is None:
        if spec.out is not None:
            starting()
        make_parents(spec.out)
        save_rve(spec.out, batch.to_data())
        report["out"] = str(spec.out)
    return outcome


def _saver(checkpoint: DemCheckpoint | None, batch: Any) -> Any:
    """The hook that saves the run's record into ``checkpoint`` when a save is due."""
    if checkpoint is None:
        return None

    def save(counter: int, rows: list[pd.DataFrame], steps: int, cell0: np.ndarray) -> None:
        if checkpoint.due():
            checkpoint.save(counter, steps, cell0, rows, batch.to_data())

    return save


def _biaxial(spec: BiaxialDemSpec, checkpoint: DemCheckpoint | None,
             saved: Any, batch: Any) -> DemOutcome:
    from granular_material.checks import make_parents
    from granular_material.procedures import biaxial_test
    from granular_material.procedures.element_tests import (
        BiaxialInterrupted,
        BiaxialStart,
        lateral_stress_error,
    )
    from granular_material.results import plot_biaxial_curves, summarize_biaxial, write_csv

    start = None if saved is None else BiaxialStart(saved.table, saved.counter, saved.cell0)
    save = _saver(checkpoint, batch)
    interrupt = None
    try:
        curve = biaxial_test(
            batch, axial_strain=spec.axial_strain, confining=spec.confining,
            strain_per_step=spec.strain_per_step, record_every=spec.record_every,
            progress=spec.progress, max_steps=spec.max_dem_steps, start=start,
            after_record=None if save is None else
            lambda done, rows, cell0: save(done, rows, done, cell0))
    except BiaxialInterrupted as exc:  # keep and write the records made before it
        curve, interrupt = exc.curve, exc
    summaries = [summarize_biaxial(g) for _, g in curve.groupby("rve")]
    if spec.out:
        make_parents(spec.out)
        write_csv(curve, spec.out)
    if spec.plot:
        make_parents(spec.plot)
        plot_biaxial_curves(curve, spec.plot)
    keys = ("peak_stress_ratio", "axial_strain_at_peak", "max_contraction", "final_void_ratio")
    report: dict[str, Any] = {key: _scalar_or_list(np.array([getattr(s, key)
                                                             for s in summaries]))
                              for key in keys}
    held = lateral_stress_error(curve, spec.confining)
    report |= {"steps": int(curve["step"].max()),
               "final_sxx": _scalar_or_list(held["final_sxx"].to_numpy()),
               "max_confining_error": _scalar_or_list(held["max_error"].to_numpy())}
    outcome = DemOutcome(report=report, table=curve, interrupt=interrupt,
                         resumed_from=None if saved is None else saved.counter)
    lost = np.flatnonzero(held["median_error"].to_numpy() > SERVO_FAIL)
    loose = np.flatnonzero(held["max_error"].to_numpy() > SERVO_WARN)
    final = held["final_sxx"].to_numpy()
    if lost.size:
        outcome.error = (
            f"the servo did not hold σxx at −{spec.confining:g} Pa (`confining`), off "
            f"by more than {SERVO_FAIL:.0%} in most records: final σxx [Pa] of "
            f"{_rve_list(lost, final, '.4g')}; not a drained test at this confining "
            "pressure (a smaller `strain_per_step`, or a packing prepared near "
            "`confining`, lets the servo follow)")
    elif loose.size:
        worst = held["max_error"].to_numpy()
        outcome.warnings.append(
            f"σxx strayed from −{spec.confining:g} Pa (`confining`) by more than "
            f"{SERVO_WARN:.0%} in some records: largest error [%] of "
            f"{_rve_list(loose, 100 * worst, '.3g')}")
    report["warnings"] = outcome.warnings
    if spec.out:
        report["out"] = str(spec.out)
    if saved is not None:  # only a resumed run says so: a fresh one's report is as it was
        report["resumed_from_step"] = saved.counter
    if interrupt is not None:
        outcome.error = (f"{interrupt}: the curve to axial strain "
                         f"{curve['axial_strain'].max():.4g} is kept")
    return outcome


def _drive(plan: DemPlan, spec: DriveSpec, checkpoint: DemCheckpoint | None,
           saved: Any, batch: Any) -> DemOutcome:
    from granular_material.checks import make_parents
    from granular_material.procedures import drive_path, progress_bar
    from granular_material.procedures.driven_path import DrivenPath
    from granular_material.results import write_csv

    start = None if saved is None else DrivenPath(table=saved.table, steps=saved.steps)
    save = _saver(checkpoint, batch)
    cell0 = np.zeros((0, 2, 2))
    done = 0 if saved is None else saved.counter
    # the bar counts DEM steps (what takes the time), moved at the end of each increment
    with progress_bar(sum(plan.increments), "dem-drive", spec.progress) as bar:
        if done:
            bar.update(sum(plan.increments[:done]))

        def advance(increment: int, steps: int) -> None:
            bar.update(steps)
            bar.set_postfix(increment=f"{increment}/{spec.increments}")

        path = drive_path(batch, np.reshape(spec.grad_u, (2, 2)), spec.increments,
                          max_strain_per_step=spec.max_strain_per_step,
                          max_steps=spec.max_dem_steps, after_increment=advance, start=start,
                          after_record=None if save is None else
                          lambda increment, rows, steps: save(increment, rows, steps, cell0))
    if spec.out:
        make_parents(spec.out)
        write_csv(path.table, spec.out)
    report: dict[str, Any] = {**path.summary(), "warnings": []}
    if spec.out:
        report["out"] = str(spec.out)
    outcome = DemOutcome(report=report, table=path.table, interrupt=path.interrupt,
                         resumed_from=None if saved is None else saved.counter)
    outcome.error = path.failure_message(spec.increments)
    finished = path.finished
    if path.interrupt is not None:
        outcome.error = (f"interrupted after increment {finished} of {spec.increments}: the "
                         "path to it is kept")
    report["increments_completed"] = finished
    if saved is not None:  # only a resumed run says so: a fresh one's report is as it was
        report["resumed_from_increment"] = saved.counter
    return outcome


def _scalar_or_list(values: np.ndarray) -> Any:
    """A batch of B values as a JSON value: the value itself when B = 1, else a list."""
    listed = np.asarray(values).tolist()
    return listed[0] if len(listed) == 1 else listed
