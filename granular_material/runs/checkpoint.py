"""Checkpoints of a FEM run, so that a stopped or killed run resumes to the same result.

A :class:`RunCheckpoint` keeps a folder (``<out>/checkpoint/`` for the commands):

- ``options.json``: what the run was started with (the caller's dictionary), written once;
- ``steps/step_NNNNN.npz``: one file per committed load step (step 0 is the initial state):
  its ``steps`` row, its Gauss-point table, the nodal displacement, its tracked rows and its
  Newton record, everything the tables and figures of the run are made from;
- ``material_NNNNN.npz``: the material's committed state (:meth:`Material.checkpoint`; for
  the DEM material an RVE file with contact history);
- ``state.npz``: the Newton solver's committed state (:class:`CommittedState`) and the step
  it belongs to. It is replaced in one ``os.replace`` after the step and material files are
  complete, so it is the commit point: whenever the process dies, the folder holds one whole
  checkpoint, the last one whose ``state.npz`` was replaced;
- ``tables/NAME.npz``: tables the caller stores once (e.g. a pure-DEM reference curve).

``state.npz`` also holds the checkpoint's manifest: the SHA-256 of ``options.json`` and of
every file the state rests on (the step files up to its step, the material file, the
tables). :meth:`RunCheckpoint.verify` reads and checks the whole checkpoint against it, and
changes nothing in the folder, so a resume that is refused (a truncated, edited, missing or
swapped file) leaves the folder as it was; :meth:`RunCheckpoint.load` tidies the folder only
after that check has passed.

Every file is written under a temporary name and renamed into place; how each is stored and
read back is :mod:`granular_material.runs.checkpoint_files`.
:func:`~granular_material.runs.runner.run_biaxial` saves into a :class:`RunCheckpoint` and
resumes from the :class:`SavedRun` it loads.
"""

from __future__ import annotations

import contextlib
import json
import math
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.fem import Material, NewtonSolver
from granular_material.runs.checkpoint_files import (
    MANIFEST_VERSION,
    OPTIONS,
    STATE,
    CheckpointError,
    SavedRun,
    SavedStep,
    cell_kind,
    file_sha256,
    frame,
    frame_arrays,
    read_npz,
    read_state,
    read_step,
    reading,
    sha256,
    state_arrays,
    step_arrays,
    write_bytes,
    write_npz,
)

__all__ = ["SAVE_FLOOR_SECONDS", "SAVE_SPACING", "CheckpointError", "RunCheckpoint",
           "SavedRun", "SavedStep"]

#: by elapsed time, the committed state is saved once this many times the last save's
#: duration has passed since it ended: a cheap save is made after every step, and saving
#: costs at most about 1/SAVE_SPACING of the run
SAVE_SPACING = 10.0
#: by elapsed time, the committed state is saved at most once this many seconds [s] (but
#: after the initial state and the last step): a kill loses about this much work, redone
#: alike by the resume; a save after every step of a fast continuum run (3 ms of a 40 ms
#: step) cost more than the tables
SAVE_FLOOR_SECONDS = 1.0


class RunCheckpoint:
    """The checkpoint folder of one run. The committed state is saved after the initial state,
    after the last step and, in between, after every ``every`` load steps; with ``every``
    None, by elapsed time: after the first step that ends :data:`SAVE_SPACING` times the last
    save's duration after it and at least :data:`SAVE_FLOOR_SECONDS` after it, and at the
    latest ``minutes`` after it. The per-step tables are
    kept for every step."""

    def __init__(self, folder: str | Path, every: int | None = 1,
                 minutes: float = 10.0) -> None:
        if every is not None and (int(every) != every or every < 1):
            raise ValueError(f"checkpoint every must be an integer >= 1, got {every!r}")
        if not (math.isfinite(minutes) and minutes > 0):
            raise ValueError(f"checkpoint minutes must be > 0, got {minutes!r}")
        self.folder = Path(folder)
        self.every = None if every is None else int(every)
        self.minutes = float(minutes)
        #: when the last save of the state ended (time.monotonic) and how long it took [s]
        self._saved_at: float | None = None
        self._save_seconds = 0.0
        #: SHA-256 of each file written (or verified) so far, by its path in the folder
        self._sums: dict[str, str] = {}
        self._options_sum: str | None = None
        self._verified: SavedRun | None = None

    # -- the run's options -------------------------------------------------------------------
    def clear(self) -> None:
        """Remove every checkpoint file of an earlier run in the folder (a fresh start)."""
        for pattern in (STATE, OPTIONS, "material_*.npz*", "steps/*.npz*", "tables/*.npz*",
                        "*.part"):
            for path in self.folder.glob(pattern):
                path.unlink()
        self._sums, self._options_sum, self._verified = {}, None, None

    def start(self, options: dict[str, Any]) -> None:
        """Begin a fresh run: the folder is made or emptied of an earlier run's checkpoint,
        and ``options`` (what the run is started with, JSON-able values) are recorded."""
        self.folder.mkdir(parents=True, exist_ok=True)
        self.clear()
        self.write_options(options)

    def remove(self) -> None:
        """Remove the checkpoint with its folders (where nothing else is left in them)."""
        self.clear()
        for folder in (self.folder / "steps", self.folder / "tables", self.folder):
            with contextlib.suppress(OSError):
                folder.rmdir()

    def write_options(self, options: dict[str, Any]) -> None:
        """Record what the run is started with (JSON-able values), replacing any record."""
        (self.folder / "steps").mkdir(parents=True, exist_ok=True)
        data = (json.dumps(options, indent=2, sort_keys=True, default=str) + "\n").encode()
        write_bytes(self.folder / OPTIONS, data)
        self._options_sum = sha256(data)

    def read_options(self) -> dict[str, Any]:
        """What the run was started with; :class:`CheckpointError` if there is no record, or
        it cannot be read, or it is not a JSON object."""
        path = self.folder / OPTIONS
        if not path.is_file():
            raise CheckpointError(f"{self.folder} holds no checkpoint of a run ({OPTIONS} "
                                  "is missing)")
        try:
            options = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise CheckpointError(f"{path} cannot be read: {exc}") from exc
        if not isinstance(options, dict):
            raise CheckpointError(f"{path} holds {json.dumps(options)[:40]} (a "
                                  f"{type(options).__name__}), not the options of a run")
        return options

    def has_options(self) -> bool:
        """Whether a run's options are recorded here (a run was started in the folder)."""
        return (self.folder / OPTIONS).is_file()

    def saved_step(self) -> int | None:
        """The load step of the saved committed state, read from ``state.npz`` alone (not
        checked against its manifest: :meth:`verify` does that); None when there is none or
        it cannot be read."""
        try:
            with np.load(self.folder / STATE, allow_pickle=False) as npz:
                return int(npz["step"])
        except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile):
            return None

    def has_state(self) -> bool:
        """Whether a committed state has been saved (else a resume starts from the beginning)."""
        return (self.folder / STATE).is_file()

    # -- steps ------------------------------------------------------------------------------
    def _step_path(self, step: int) -> Path:
        return self.folder / "steps" / f"step_{step:05d}.npz"

    def _name(self, path: Path) -> str:
        """``path`` as the manifest names it: relative to the folder, with ``/``."""
        return path.relative_to(self.folder).as_posix()

    def save_step(self, row: dict[str, Any], points: pd.DataFrame, u: np.ndarray,
                  tracked: pd.DataFrame | None) -> None:
        """Keep one committed step's row, Gauss-point table, displacement [m] and tracked
        rows (None: not tracked)."""
        arrays = step_arrays(row, points, u, tracked)
        path = self._step_path(int(row["step"]))
        path.parent.mkdir(parents=True, exist_ok=True)
        self._sums[self._name(path)] = write_npz(path, arrays)

    def _load_step(self, step: int, data: bytes | None = None) -> SavedStep:
        """Step ``step``'s file (its bytes ``data`` when already read), checked: its row is
        of that step and holds numbers and text only."""
        path = self._step_path(step)
        if data is None:
            if not path.is_file():
                raise CheckpointError(f"{path} is missing: the checkpoint is incomplete")
            with reading(path):
                data = path.read_bytes()
        return read_step(path, step, data)

    # -- the committed state ----------------------------------------------------------------
    def due(self, step: int, last_step: int) -> bool:
        """Whether the committed state after load ``step`` of ``last_step`` is to be saved."""
        if self.every is not None:
            return step % self.every == 0 or step == last_step
        if step == last_step or self._saved_at is None:
            return True
        since = time.monotonic() - self._saved_at
        return since >= min(max(SAVE_SPACING * self._save_seconds, SAVE_FLOOR_SECONDS),
                            60.0 * self.minutes)

    def save_state(self, step: int, solver: NewtonSolver, material: Material) -> None:
        """Save the committed state after load ``step`` (material first, then the solver's
        state as the commit point, with the manifest of the files it rests on), then drop
        the material file it replaces."""
        started = time.monotonic()
        name = f"material_{step:05d}.npz"
        material.checkpoint(self.folder / name)
        state = solver.committed_state()
        if self._options_sum is None and self.has_options():
            self._options_sum = file_sha256(self.folder / OPTIONS)
        files = {k: v for k, v in self._sums.items()
                 if not k.startswith("steps/") or int(k[11:-4]) <= step}
        files[name] = file_sha256(self.folder / name)
        manifest = {"version": MANIFEST_VERSION, "step": step, "options": self._options_sum,
                    "files": files}
        # the commit point, named by no manifest: its SHA-256 is not needed
        write_npz(self.folder / STATE, state_arrays(step, name, state, manifest), digest=False)
        self._drop_stale(keep=name)
        self._saved_at = time.monotonic()
        self._save_seconds = self._saved_at - started

    def _drop_stale(self, keep: str) -> None:
        """Material files other than ``keep`` and half-written files."""
        for path in self.folder.glob("material_*.npz*"):
            if path.name != keep:
                path.unlink(missing_ok=True)
        for path in self.folder.glob("**/*.part"):
            path.unlink(missing_ok=True)

    def _checked_file(self, name: str, manifest: dict[str, Any] | None) -> bytes:
        """The bytes of the checkpoint's file ``name``, present, readable and (with a
        ``manifest``) the very file the state was saved with."""
        path = self.folder / name
        if not path.is_file():
            raise CheckpointError(f"{path} is missing: the checkpoint is incomplete")
        with reading(path):
            data = path.read_bytes()
        if manifest is not None:
            expected = manifest["files"].get(name)
            if expected is not None and sha256(data) != expected:
                raise CheckpointError(
                    f"{path} is not the file this checkpoint saved (its SHA-256 differs: "
                    "changed, truncated or copied from another run)")
        return data

    def verify(self) -> SavedRun:
        """Read and check the whole last checkpoint, changing nothing in the folder: every
        file present and readable, each the one the state was saved with (the manifest's
        SHA-256 of the options and of each file), the step rows of steps 0 … its step, all
        alike; :class:`CheckpointError` naming the file and what is wrong. :meth:`load`
        then returns this very checkpoint."""
        path = self.folder / STATE
        if not path.is_file():
            raise CheckpointError(f"{self.folder} holds no committed state yet")
        step, material, state, manifest = read_state(path)
        options = self.folder / OPTIONS
        recorded = None if manifest is None else manifest.get("options")
        if recorded is not None and not options.is_file():
            raise CheckpointError(f"{options} is missing: the options the run was started "
                                  "with cannot be checked")
        options_sum = None
        if options.is_file():
            self.read_options()
            options_sum = file_sha256(options)
        if recorded is not None and recorded != options_sum:
            raise CheckpointError(f"{path} was saved with other options than {options} "
                                  "holds (their SHA-256 differs): one of them is another "
                                  "run's, or options.json was edited")
        lost = [self._step_path(k).name for k in range(step + 1)
                if not self._step_path(k).is_file()]
        if lost:
            shown = ", ".join(lost[:3]) + (f" and {len(lost) - 3} more" if len(lost) > 3 else "")
            raise CheckpointError(f"{self.folder / 'steps'}: {shown} "
                                  f"{'is' if len(lost) == 1 else 'are'} missing, but {path} "
                                  f"is of load step {step}: the checkpoint is incomplete")
        sums: dict[str, str] = {}
        steps = []
        columns: dict[str, str] = {}
        for k in range(step + 1):
            name = self._name(self._step_path(k))
            data = self._checked_file(name, manifest)
            sums[name] = sha256(data)
            saved = self._load_step(k, data)
            if k == 0:
                columns = {key: cell_kind(value) for key, value in saved.row.items()}
                points = list(saved.points.columns)
            elif set(saved.row) != set(columns):
                lost = sorted(set(columns) - set(saved.row))
                more = sorted(set(saved.row) - set(columns))
                raise CheckpointError(
                    f"{self._step_path(k)}: its row {'lacks ' + ', '.join(lost) if lost else ''}"
                    f"{' and ' if lost and more else ''}"
                    f"{'has ' + ', '.join(more) if more else ''} (step 0's does not)")
            elif list(saved.points.columns) != points:
                raise CheckpointError(f"{self._step_path(k)}: its Gauss-point table has "
                                      "other columns than step 0's")
            for key, value in saved.row.items():
                kind = cell_kind(value)
                if "none" not in (kind, columns[key]) and kind != columns[key]:
                    raise CheckpointError(f"{self._step_path(k)}: column {key!r} holds "
                                          f"{value!r} where step 0 holds a {columns[key]}")
            if saved.u.shape != state.u.shape:
                raise CheckpointError(f"{self._step_path(k)}: its displacement has "
                                      f"{saved.u.size} entries, the state {state.u.size}")
            steps.append(saved)
        data = self._checked_file(material, manifest)
        if manifest is None:
            with reading(self.folder / material):
                read_npz(data)  # readable whole, at least
        sums[material] = sha256(data)
        if manifest is not None:
            for name in manifest["files"]:
                if name.startswith("tables/"):
                    sums[name] = sha256(self._checked_file(name, manifest))
        for table in sorted(self.folder.glob("tables/*.npz")):
            name = self._name(table)
            if name not in sums:
                with reading(table):
                    frame("table", read_npz(table.read_bytes()))
                    sums[name] = file_sha256(table)
        del sums[material]
        self._sums, self._options_sum = sums, options_sum
        self._verified = SavedRun(step, steps, state, self.folder / material)
        return self._verified

    def load(self, tidy: bool = True) -> SavedRun:
        """The last whole checkpoint (the one :meth:`verify` just returned, else verified
        now); only then, with ``tidy``, are step files past it (written before a later state
        that never came) and half-written files removed (without: the folder is left as it
        is, and a later ``load()`` returns the same checkpoint and tidies)."""
        saved = self._verified if self._verified is not None else self.verify()
        if not tidy:
            self._verified = saved
            return saved
        self._verified = None
        self._drop_stale(keep=saved.material_path.name)
        for later in self.folder.glob("steps/step_*.npz"):
            with contextlib.suppress(ValueError):
                if int(later.stem.removeprefix("step_")) > saved.step:
                    later.unlink()
        return saved

    # -- tables stored once -----------------------------------------------------------------
    def save_table(self, name: str, frame: pd.DataFrame) -> None:
        """Keep a table of numbers under ``name`` (e.g. a reference curve computed once)."""
        (self.folder / "tables").mkdir(parents=True, exist_ok=True)
        path = self.folder / "tables" / f"{name}.npz"
        self._sums[self._name(path)] = write_npz(path, frame_arrays("table", frame))

    def load_table(self, name: str) -> pd.DataFrame | None:
        """The table saved as ``name``, or None when there is none."""
        path = self.folder / "tables" / f"{name}.npz"
        if not path.is_file():
            return None
        with reading(path):
            return frame("table", read_npz(path.read_bytes()))
