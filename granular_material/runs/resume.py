"""A run's checkpoint and its spec: a fresh run records its spec there; a resumed one is
checked against it field by field before anything in the folder is touched."""

from __future__ import annotations

import contextlib
import json
import sys
import warnings
from collections.abc import Iterator, Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

from granular_material.checks import RVE_MATERIAL_DEFAULTS
from granular_material.errors import ParameterError
from granular_material.runs.checkpoint import CheckpointError, RunCheckpoint
from granular_material.runs.run_folder import failed_error
from granular_material.runs.serial import from_dict, from_flat, to_dict, to_flat
from granular_material.runs.spec import RunSpec
from granular_material.vocabulary import RenamedWarning, renamed

__all__ = ["FailedRunError", "StoppedRunError", "differences_from_saved", "open_checkpoint",
           "resolved_newton", "spec_differences", "start_checkpoint"]


class StoppedRunError(ParameterError):
    """A fresh run refused over the checkpoint of a run stopped before its last load step
    (``field``: ``out``), whose work a resume would continue; nothing was changed."""


class FailedRunError(StoppedRunError):
    """A fresh run refused over the checkpoint of a run that failed before its last load
    step (``field``: ``out``): it cannot be resumed, only started afresh; nothing was
    changed."""

#: fields that may differ between a run and its resume: where it writes, how it reports and
#: how often it saves, whether it writes points.csv or figures, the CPU threads and the
#: backend (none changes a result)
RESUME_FREE = frozenset({"out", "progress", "checkpoint_every", "checkpoint_minutes",
                         "points_csv", "figures", "shards", "backend"})
#: options added after checkpoints were first written, with the value older runs had
_ADDED_OPTIONS = {"element": "quad4", "quadrature": None, "convergence": "force",
                  "formulation": "small-strain", "accept_correction": 0.0,
                  **RVE_MATERIAL_DEFAULTS}
#: options of older checkpoints' records that are no spec fields (the command line's own)
_NOT_FIELDS = frozenset({"command", "resume", "json", "func"})


def _saved_spec(record: dict[str, Any]) -> RunSpec:
    """The spec a checkpoint's record was started with: the spec itself, or the options of
    an older version's (every command-line option, those added since at their old value)."""
    with warnings.catch_warnings():  # the old names of a saved run: read, not the user's
        warnings.simplefilter("ignore", RenamedWarning)
        if "spec" in record:
            return from_dict(record["spec"])
        material = record.get("material", "dem")
        options = {**_ADDED_OPTIONS, **renamed(record, material, warn=False,
                                               given=lambda v: v is not None)}
        options.setdefault("material", "dem")
        options["test"] = options.get("command", "single-element")
        flat = {k: v for k, v in options.items() if k not in _NOT_FIELDS and v is not None}
        return from_flat(flat, strict=False)


def _compared(spec: RunSpec) -> dict[str, Any]:
    """The flat form of ``spec`` as a resume compares it: the post-processors of tracked
    points resolved (None: every installed one), none without tracking."""
    flat = to_flat(spec)
    output = spec.output
    flat["postprocess"] = None if output.track is None else list(output.postprocessors())
    return flat


def resolved_newton(spec: RunSpec) -> dict[str, Any] | None:
    """The Newton settings ``spec`` runs with, the commands' defaults filled in (as JSON
    values; ``stress_tol`` the absolute tolerance [Pa]); None where the spec's values are
    refused (its check says why)."""
    try:
        noisy = spec.material.noisy
        values = asdict(spec.newton.settings(noisy))
        values["stress_tol"] = spec.newton.stress_tolerance(noisy, spec.problem.confining)
    except ValueError:
        return None
    return json.loads(json.dumps(values))


def spec_differences(given: RunSpec, saved: RunSpec,
                     saved_newton: Mapping[str, Any] | None = None) -> list[str]:
    """The fields (each named in backquotes) of ``given`` that differ from ``saved``, but for those
    a resume may change (:data:`RESUME_FREE`). With ``saved_newton`` (the run's
    :func:`resolved_newton`, recorded since the commands' defaults may change between
    versions) the Newton settings are compared as resolved: an option left to a default
    that is no longer the run's differs, and one given as the run's value does not."""
    now, then = _compared(given), _compared(saved)

    def difference(name: str, value: Any, before: Any) -> str:
        # None: left to the material's default
        given = "not given" if value is None else repr(value)
        had = "the run did not give it" if before is None else f"the run had {before!r}"
        return f"`{name}` {given} ({had})"

    differ: list[str] = []
    resolved = resolved_newton(given) if saved_newton is not None else None
    if saved_newton is not None and resolved is not None:
        for name in sorted(set(resolved) & set(saved_newton)):
            if resolved[name] != saved_newton[name]:
                option = f"`{name}`" if name in now else name
                how = " by default" if now.get(name) is None else ""
                differ.append(f"{option} {resolved[name]!r}{how} (the run had "
                              f"{saved_newton[name]!r})")
        now = {k: v for k, v in now.items() if k not in saved_newton}
        then = {k: v for k, v in then.items() if k not in saved_newton}
    return differ + [difference(k, now.get(k), then.get(k))
                     for k in sorted(set(now) | set(then))
                     if k not in RESUME_FREE and now.get(k) != then.get(k)]


def _record_differences(spec: RunSpec, record: dict[str, Any]) -> list[str]:
    """What of ``spec`` differs from the run a checkpoint's ``record`` was started with."""
    return spec_differences(spec, _saved_spec(record), record.get("newton"))


def differences_from_saved(spec: RunSpec) -> list[str]:
    """What of ``spec`` differs from the spec of the run started in its output folder, as a
    resume would name it (:func:`spec_differences`); empty where no run was started there or
    its record cannot be read (a resume then says why)."""
    if spec.output.out is None:
        return []
    checkpoint = RunCheckpoint(Path(spec.output.out) / "checkpoint")
    if not checkpoint.has_options():
        return []
    try:
        return _record_differences(spec, checkpoint.read_options())
    except (CheckpointError, ValueError, KeyError, TypeError):
        return []


def _check_record(spec: RunSpec, checkpoint: RunCheckpoint, folder: Path) -> None:
    """The checkpoint in ``folder`` is of a run of ``spec`` (a ParameterError of ``resume``
    naming what differs; nothing is changed)."""
    try:
        record = checkpoint.read_options()
    except CheckpointError as exc:
        raise ParameterError("resume", f"{folder}: {exc}; nothing in the folder was "
                                       "changed") from None
    command = record.get("command")
    if command not in (None, spec.problem.test):
        raise ParameterError("resume", f"{folder} is a {command} run, not {spec.problem.test}")
    differ = _record_differences(spec, record)
    if differ:
        raise ParameterError("resume", f"{folder}: give the options the run was started "
                                       f"with; these differ: {'; '.join(differ)} (nothing "
                                       "in the folder was changed)")


def _refuse_over_stopped_run(checkpoint: RunCheckpoint, out: Path) -> None:
    """A fresh run would empty ``checkpoint``: refused (StoppedRunError, nothing changed) where
    it is of a run that stopped before its last load step, whose work a ``--resume`` would
    continue; a finished run's, a damaged or an unsaved one's may be replaced."""
    step = checkpoint.saved_step() if checkpoint.has_options() else None
    if step is None:
        return
    try:
        planned = _saved_spec(checkpoint.read_options()).problem.steps
    except (CheckpointError, ValueError, KeyError, TypeError):
        return
    if step >= planned:
        return
    error = failed_error(out, checkpoint.folder)
    if error is not None:
        raise FailedRunError("out", f"{out} holds the checkpoint of a run that failed "
                                    f"({error}); a failed run cannot be resumed (its failed "
                                    "step would fail again): write to another folder, or "
                                    f"remove {checkpoint.folder} to run it afresh there; "
                                    "nothing in the folder was changed")
    raise StoppedRunError("out", f"{out} holds the checkpoint of a run stopped after load "
                                 f"step {step} of {planned}: continue it with `resume` (and "
                                 "the options it was started with), or remove "
                                 f"{checkpoint.folder} to start afresh there; nothing in the "
                                 "folder was changed")


def open_checkpoint(spec: RunSpec, resume: bool, keep_stopped: bool = False,
                    ) -> tuple[RunCheckpoint | None, bool]:
    """The run's checkpoint (None without an output folder) and whether the run resumes
    from a saved state in it (checked whole first); else it starts afresh, which
    ``keep_stopped`` refuses over the checkpoint of a run stopped before its last step."""
    out = spec.output.out
    if out is None:
        return None, False
    checkpoint = RunCheckpoint(Path(out) / "checkpoint", every=spec.output.checkpoint_every,
                               minutes=spec.output.checkpoint_minutes)
    if not resume:
        if keep_stopped:
            _refuse_over_stopped_run(checkpoint, Path(out))
        return checkpoint, False
    if not checkpoint.has_options():
        if checkpoint.has_state():
            raise ParameterError("resume", f"{out}: {checkpoint.folder / 'options.json'} is "
                                           "missing, so the options the run was started "
                                           "with cannot be checked; nothing in the folder "
                                           "was changed")
    else:
        _check_record(spec, checkpoint, Path(out))
    if not checkpoint.has_state():
        print(f"granular-material {spec.problem.test}: {out} holds no saved step yet; the "
              "run starts from the beginning", file=sys.stderr)
        return checkpoint, False
    try:  # read and checked whole before anything in the folder is touched
        saved = checkpoint.verify()
    except CheckpointError as exc:
        raise ParameterError("resume", f"{out}: {exc}; nothing in the folder was "
                                       "changed") from None
    if saved.step > spec.problem.steps:
        raise ParameterError("resume", f"{out}: its checkpoint is of load step {saved.step}, "
                                       f"past `steps` {spec.problem.steps}; nothing in the "
                                       "folder was changed")
    return checkpoint, True


@contextlib.contextmanager
def start_checkpoint(spec: RunSpec, checkpoint: RunCheckpoint | None,
                     resuming: bool) -> Iterator[None]:
    """The block of a run: a fresh one first empties the checkpoint and records its spec;
    input rejected in the block (``ValueError``) leaves no fresh checkpoint behind."""
    if checkpoint is None or resuming:
        yield
        return
    checkpoint.start({"command": spec.problem.test, "spec": to_dict(spec),
                      "newton": resolved_newton(spec)})
    try:
        yield
    except ValueError:
        checkpoint.remove()
        raise
