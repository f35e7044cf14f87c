"""What a run folder holds: a run that has ended (its ``summary.json``), or one interrupted
part-way whose checkpoint lets it continue. The biaxial and boundary-value runners write
both; a study or report that runs many folders asks here which still need their run.

A run writes nothing into its folder before every check has passed: it says so by calling
:func:`starting` once, right before its first write (a fresh checkpoint, a table, a tidied
checkpoint). What a caller writes beside the run (the command line's ``scene.toml``) waits
for that moment through :func:`when_starting`, so that a refused run leaves the folder as it
was."""

from __future__ import annotations

import contextlib
import contextvars
import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from granular_material.runs.checkpoint_files import OPTIONS, STATE

__all__ = ["ended_summary", "failed_error", "interrupted_error", "resumable", "starting",
           "when_starting"]

#: what is to be done when the run in hand starts writing (see :func:`when_starting`)
_ON_START: contextvars.ContextVar[list[Callable[[], None]] | None] = contextvars.ContextVar(
    "granular_material_on_start", default=None)


@contextlib.contextmanager
def when_starting(action: Callable[[], None]) -> Iterator[Callable[[], bool]]:
    """``action`` done once, when a run in the block calls :func:`starting` (all its checks
    passed, its first write next); yields a function that tells whether it has been done."""
    done = [False]

    def once() -> None:
        if not done[0]:
            done[0] = True
            action()

    token = _ON_START.set([*(_ON_START.get() or []), once])
    try:
        yield lambda: done[0]
    finally:
        _ON_START.reset(token)


def starting() -> None:
    """Called by a run once every check has passed, right before it writes into its folder:
    what :func:`when_starting` registered is done now (once)."""
    for action in _ON_START.get() or []:
        action()

#: how the error of an interrupted run begins (Ctrl-C or a signal: it continues with resume)
_INTERRUPTED = "interrupted after load step"


def interrupted_error(done: int, planned: int) -> str:
    """The ``error`` of a run interrupted after load step ``done`` of ``planned``."""
    return f"{_INTERRUPTED} {done} of {planned}"


def ended_summary(folder: Path) -> dict[str, Any] | None:
    """The summary of the run in ``folder`` where it has ended (finished, or stopped by a
    step that failed: its error says why); None where there is none yet or the run was
    interrupted (it is not over: :func:`resumable` tells whether it can continue)."""
    path = Path(folder) / "summary.json"
    if not path.is_file():
        return None
    summary = json.loads(path.read_text())
    return None if str(summary.get("error") or "").startswith(_INTERRUPTED) else summary


def resumable(folder: Path) -> bool:
    """Whether ``folder`` holds the checkpoint of a run that ``resume`` continues."""
    return (Path(folder) / "checkpoint" / OPTIONS).is_file()


def failed_error(folder: Path, checkpoint: Path) -> str | None:
    """The error of the run in ``folder`` where it ended by failing (a load step that did not
    converge: its ``summary.json`` says why) after it last saved its state in the checkpoint
    folder ``checkpoint``; None where it finished, was stopped or killed part-way (its work
    continues with ``resume``), or where the summary is older than that state (an earlier
    run's, left by a run killed since). A failed run is not resumed: its failed step would
    fail again."""
    summary = ended_summary(folder)
    if summary is None or not summary.get("error"):
        return None
    state = Path(checkpoint) / STATE
    if state.is_file() and ((Path(folder) / "summary.json").stat().st_mtime_ns
                            < state.stat().st_mtime_ns):
        return None
    return str(summary["error"])
