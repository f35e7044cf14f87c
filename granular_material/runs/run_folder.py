"""What a run folder holds: a run that has ended (its ``summary.json``), or one interrupted
part-way whose checkpoint lets it continue. The biaxial and boundary-value runners write
both; a study or report that runs many folders asks here which still need their run."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from granular_material.runs.checkpoint_files import OPTIONS

__all__ = ["ended_summary", "interrupted_error", "resumable"]

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
