"""The checkpoint of a DEM run (``biaxial-dem``, ``dem-drive``), so that a stopped run resumes
to the very table an uninterrupted one writes.

The output of a DEM run is a file (``curve.csv``); its checkpoint is the folder beside it,
``curve.csv.checkpoint/`` (:func:`checkpoint_folder`), which also holds the run's lock while
it runs. It holds:

- ``options.json``: the run's spec (its dict form) and the SHA-256 of its RVE file, written
  once when the run starts;
- ``rve_NNNNNNNNNN.npz``: the RVE file of the batch after the saved record, contact history
  included (docs/design.md#rve-file: a run continued from it is bit-identical);
- ``state.npz``: the commit point, replaced in one ``os.replace`` once the RVE file is
  whole: the record's counter (DEM steps of a biaxial test, the increment of a path), the
  DEM steps so far, the cells the run started from, the table's rows so far (float64
  arrays, exact) and the name and SHA-256 of the RVE file it rests on.

A run that ends (finished, or stopped by a failure that a resume would meet again) removes
its checkpoint; one interrupted (Ctrl-C, SIGTERM) or killed keeps the last one saved. Files
are stored and read with :mod:`granular_material.runs.checkpoint_files`' helpers.
"""

from __future__ import annotations

import contextlib
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.runs.checkpoint import SAVE_SPACING
from granular_material.runs.checkpoint_files import (
    OPTIONS,
    STATE,
    CheckpointError,
    dumps,
    file_sha256,
    frame,
    frame_arrays,
    loads,
    read_npz,
    reading,
    write_bytes,
    write_npz,
)

__all__ = ["DemCheckpoint", "SavedRecord", "checkpoint_folder"]

#: the suffix of a DEM run's checkpoint folder, beside its output file
SUFFIX = ".checkpoint"


def checkpoint_folder(out: Path) -> Path:
    """The checkpoint folder of the run writing the output file ``out``."""
    out = Path(out)
    return out.with_name(out.name + SUFFIX)


@dataclass
class SavedRecord:
    """The last whole checkpoint of a DEM run.

    Attributes:
        counter: the record it holds (DEM steps of a biaxial test, the increment of a path).
        steps: DEM steps run up to it.
        cell0: the cells (B, 2, 2) [m] the run started from.
        table: the run's rows up to and including that record.
        rve: the RVE file of the batch in that record's state.
    """

    counter: int
    steps: int
    cell0: np.ndarray
    table: pd.DataFrame
    rve: Path


class DemCheckpoint:
    """The checkpoint folder of one DEM run (see the module). The batch is saved after a
    record when :data:`~granular_material.runs.checkpoint.SAVE_SPACING` times the last
    save's duration has passed since it ended (every record when saving is cheap)."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self._saved_at: float | None = None
        self._save_seconds = 0.0

    # -- what it holds -----------------------------------------------------------------------
    def has_options(self) -> bool:
        """Whether a run was started here (its options recorded)."""
        return (self.folder / OPTIONS).is_file()

    def has_state(self) -> bool:
        """Whether a record was saved here."""
        return (self.folder / STATE).is_file()

    def read_options(self) -> dict[str, Any]:
        """What the run was started with: ``spec`` (its dict form) and ``rve_sha256``."""
        path = self.folder / OPTIONS
        with reading(path):
            record = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(record, dict) or not isinstance(record.get("spec"), dict):
            raise CheckpointError(f"{path} is no DEM run's options")
        return record

    # -- a fresh run -------------------------------------------------------------------------
    def clear(self) -> None:
        """Remove every checkpoint file of an earlier run (the lock stays)."""
        for pattern in (STATE, OPTIONS, "rve_*.npz*", "*.part"):
            for path in self.folder.glob(pattern):
                path.unlink()

    def start(self, options: dict[str, Any]) -> None:
        """Begin a fresh run: the folder emptied of an earlier run's checkpoint and
        ``options`` (JSON-able) recorded."""
        self.folder.mkdir(parents=True, exist_ok=True)
        self.clear()
        text = json.dumps(options, indent=2) + "\n"
        write_bytes(self.folder / OPTIONS, text.encode("utf-8"))

    def remove(self) -> None:
        """Remove the checkpoint's files (the folder goes with the run's lock)."""
        self.clear()

    # -- saving ------------------------------------------------------------------------------
    def due(self) -> bool:
        """Whether a save is due now (:data:`SAVE_SPACING`)."""
        if self._saved_at is None:
            return True
        return time.monotonic() - self._saved_at >= SAVE_SPACING * self._save_seconds

    def save(self, counter: int, steps: int, cell0: np.ndarray, rows: list[pd.DataFrame],
             data: Any) -> None:
        """Save the record ``counter`` (``steps`` DEM steps run, the run's cells ``cell0``,
        its ``rows`` so far) with the batch's RVE data ``data``; ``state.npz`` is replaced
        last, so the folder always holds one whole checkpoint."""
        from granular_material.dem import save_rve

        began = time.monotonic()
        name = f"rve_{counter:010d}.npz"
        path = self.folder / name
        save_rve(path, data, compress=False, validate=False)  # whole or not at all
        table = pd.concat(rows, ignore_index=True)
        write_npz(self.folder / STATE, {
            "counter": np.array(counter), "steps": np.array(steps),
            "cell0": np.asarray(cell0, dtype=np.float64), "rve": np.array(name),
            "rve_sha256": np.array(file_sha256(path)), **frame_arrays("table", table),
            "manifest": dumps({"counter": counter}),
        })
        for old in self.folder.glob("rve_*.npz"):
            if old.name != name:
                with contextlib.suppress(OSError):
                    old.unlink()
        self._saved_at = time.monotonic()
        self._save_seconds = self._saved_at - began

    # -- resuming ----------------------------------------------------------------------------
    def load(self) -> SavedRecord:
        """The saved record, checked whole (CheckpointError naming the file and the fault;
        nothing in the folder is changed)."""
        path = self.folder / STATE
        with reading(path):
            npz = read_npz(path.read_bytes())
            counter, steps = int(npz["counter"]), int(npz["steps"])
            name = str(npz["rve"])
            if counter < 0 or steps < 0 or not name.startswith("rve_"):
                raise CheckpointError(f"{path}: its record {counter} or file {name!r} is not "
                                      "a checkpoint's")
            loads(npz["manifest"])
            table = frame("table", npz)
            cell0 = np.array(npz["cell0"])
            rve = self.folder / name
            if not rve.is_file():
                raise CheckpointError(f"{path} rests on {rve}, which is missing")
            if file_sha256(rve) != str(npz["rve_sha256"]):
                raise CheckpointError(f"{rve} is not the file {path} was saved with (its "
                                      "SHA-256 differs)")
        return SavedRecord(counter=counter, steps=steps, cell0=cell0, table=table, rve=rve)
