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

Every file is written under a temporary name and renamed into place. Numbers are stored in
binary (float64 arrays) or as JSON, whose floats round-trip exactly, so a resumed run
rebuilds the tables bit for bit.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import math
import re
import time
import zipfile
from collections.abc import Iterator
from dataclasses import MISSING, asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.fem.material import Material, MaterialResponse
from granular_material.fem.newton import CommittedState, NewtonSolver, StepRecord
from granular_material.filesafe import write_whole

__all__ = ["CheckpointError", "RunCheckpoint", "SavedRun", "SavedStep"]

_STATE = "state.npz"
_OPTIONS = "options.json"
#: version of the manifest kept in ``state.npz``
_MANIFEST_VERSION = 1
#: the name of a material file (nothing else may be named by ``state.npz``)
_MATERIAL_NAME = re.compile(r"material_\d{5,}\.npz")
#: the cost fields a Newton record had of its own before its costs became one mapping
#: (``StepRecord.costs``): the record of a checkpoint written then resumes with them moved
#: into ``costs``
_LEGACY_COSTS = ("dem_steps", "rve_evaluations", "particle_steps")
#: the arrays ``state.npz`` must hold
_STATE_ARRAYS = ("step", "material", "u", "load_factor", "run_start", "has_last",
                 "last_load", "last_du", "records", "response.stress", "response.tangent",
                 "response.status", "response.fields")


class CheckpointError(ValueError):
    """A checkpoint folder that cannot be resumed (missing, incomplete, or another run's)."""


@dataclass
class SavedStep:
    """One committed load step as the run's observer saw it.

    Attributes:
        row: the step's row of the ``steps`` table.
        points: its Gauss-point table.
        u: nodal displacement [m], shape (ndofs,), float64.
        tracked: its tracked post-processor rows, or None when the step was not tracked.
    """

    row: dict[str, Any]
    points: pd.DataFrame
    u: np.ndarray
    tracked: pd.DataFrame | None


@dataclass
class SavedRun:
    """The last whole checkpoint of a run.

    Attributes:
        step: the last committed load step it holds.
        steps: steps 0 … ``step``, in order.
        state: the solver's committed state after ``step``.
        material_path: the material's committed state (for :meth:`Material.restore`).
    """

    step: int
    steps: list[SavedStep]
    state: CommittedState
    material_path: Path


def _native(value: Any) -> Any:
    """JSON for the numpy scalars of a table row."""
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.bool_):
        return bool(value)
    raise TypeError(f"cannot store {type(value).__name__} in a checkpoint")


def _dumps(value: Any) -> np.ndarray:
    return np.array(json.dumps(value, default=_native))


def _loads(value: np.ndarray) -> Any:
    return json.loads(str(value))


def _frame_arrays(prefix: str, frame: pd.DataFrame) -> dict[str, np.ndarray]:
    """The columns of a table of numbers as arrays ``prefix.NAME`` plus their order."""
    arrays = {f"{prefix}.{name}": frame[name].to_numpy() for name in frame.columns}
    arrays[f"{prefix}.columns"] = _dumps([str(c) for c in frame.columns])
    return arrays


def _frame(prefix: str, npz: Any) -> pd.DataFrame:
    columns = _loads(npz[f"{prefix}.columns"])
    return pd.DataFrame({name: npz[f"{prefix}.{name}"] for name in columns}, columns=columns)


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def _write_bytes(path: Path, data: bytes) -> None:
    """``path`` written whole or not at all (a temporary file renamed into place); a failed
    write leaves no ``.part`` behind, and its error names the file."""
    write_whole(path, lambda tmp: tmp.write_bytes(data))


def _write_npz(path: Path, arrays: dict[str, np.ndarray]) -> str:
    """``path`` written whole or not at all; returns the SHA-256 of what was written."""
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    data = buffer.getvalue()
    _write_bytes(path, data)
    return _sha256(data)


@contextlib.contextmanager
def _reading(path: Path) -> Iterator[None]:
    """Errors of reading the checkpoint file ``path`` as :class:`CheckpointError` naming it
    and what is wrong (never a traceback of the zip or JSON reader)."""
    try:
        yield
    except CheckpointError:
        raise
    except KeyError as exc:
        name = exc.args[0] if exc.args else "?"
        raise CheckpointError(f"{path} lacks the array {name!r}: the file is damaged or "
                              "not a checkpoint file") from None
    except (OSError, EOFError, zipfile.BadZipFile, ValueError, TypeError,
            AttributeError, IndexError) as exc:
        what = str(exc) or type(exc).__name__
        raise CheckpointError(f"{path} cannot be read ({what}): it is truncated, damaged or "
                              "not a checkpoint file") from None


def _npz(data: bytes) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file's bytes, read whole (their CRCs checked)."""
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        return {name: np.array(npz[name]) for name in npz.files}


def _kind(value: Any) -> str:
    """The kind of a table cell read back from JSON: number, text or none."""
    if value is None:
        return "none"
    if isinstance(value, bool | int | float):
        return "number"
    if isinstance(value, str):
        return "text"
    raise CheckpointError(f"holds a {type(value).__name__} where a number or text belongs")


def _record(path: Path, record: Any) -> StepRecord:
    """A :class:`StepRecord` from its saved dictionary; CheckpointError naming an unknown or
    missing field, or for costs that are not numbers by name. The cost fields of a record
    saved before ``StepRecord.costs`` (:data:`_LEGACY_COSTS`) are moved into its costs."""
    if not isinstance(record, dict):
        raise CheckpointError(f"{path}: a Newton record is a {type(record).__name__}, not a "
                              "record")
    if "costs" not in record and any(name in record for name in _LEGACY_COSTS):
        costs = {name: record[name] for name in _LEGACY_COSTS if name in record}
        record = {k: v for k, v in record.items() if k not in costs} | {"costs": costs}
    known = {f.name: f for f in fields(StepRecord)}
    unknown = sorted(set(record) - set(known))
    if unknown:
        raise CheckpointError(f"{path}: a Newton record holds the unknown field(s) "
                              f"{', '.join(map(repr, unknown))}")
    missing = [name for name, f in known.items() if name not in record
               and f.default is MISSING and f.default_factory is MISSING]
    if missing:
        raise CheckpointError(f"{path}: a Newton record lacks the field(s) "
                              f"{', '.join(map(repr, missing))}")
    costs = record.get("costs", {})
    if not (isinstance(costs, dict) and all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in costs.values())):
        raise CheckpointError(f"{path}: a Newton record's costs are not numbers by name")
    return StepRecord(**record)


#: by elapsed time, the committed state is saved once this many times the last save's
#: duration has passed since it ended: a cheap save is made after every step, and saving
#: costs at most about 1/SAVE_SPACING of the run
SAVE_SPACING = 10.0


class RunCheckpoint:
    """The checkpoint folder of one run. The committed state is saved after the initial state,
    after the last step and, in between, after every ``every`` load steps; with ``every``
    None, by elapsed time: after the first step that ends :data:`SAVE_SPACING` times the last
    save's duration after it, and at the latest ``minutes`` after it. The per-step tables are
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
        for pattern in (_STATE, _OPTIONS, "material_*.npz*", "steps/*.npz*", "tables/*.npz*",
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
        _write_bytes(self.folder / _OPTIONS, data)
        self._options_sum = _sha256(data)

    def read_options(self) -> dict[str, Any]:
        """What the run was started with; :class:`CheckpointError` if there is no record, or
        it cannot be read, or it is not a JSON object."""
        path = self.folder / _OPTIONS
        if not path.is_file():
            raise CheckpointError(f"{self.folder} holds no checkpoint of a run ({_OPTIONS} "
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
        return (self.folder / _OPTIONS).is_file()

    def saved_step(self) -> int | None:
        """The load step of the saved committed state, read from ``state.npz`` alone (not
        checked against its manifest: :meth:`verify` does that); None when there is none or
        it cannot be read."""
        try:
            with np.load(self.folder / _STATE, allow_pickle=False) as npz:
                return int(npz["step"])
        except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile):
            return None

    def has_state(self) -> bool:
        """Whether a committed state has been saved (else a resume starts from the beginning)."""
        return (self.folder / _STATE).is_file()

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
        arrays = {"row": _dumps(row), "u": np.asarray(u, dtype=np.float64),
                  **_frame_arrays("points", points)}
        if tracked is not None:
            arrays["tracked"] = _dumps({"columns": [str(c) for c in tracked.columns],
                                        "data": tracked.to_dict(orient="list")})
        path = self._step_path(int(row["step"]))
        path.parent.mkdir(parents=True, exist_ok=True)
        self._sums[self._name(path)] = _write_npz(path, arrays)

    def _load_step(self, step: int, data: bytes | None = None) -> SavedStep:
        """Step ``step``'s file (its bytes ``data`` when already read), checked: its row is
        of that step and holds numbers and text only."""
        path = self._step_path(step)
        if data is None:
            if not path.is_file():
                raise CheckpointError(f"{path} is missing: the checkpoint is incomplete")
            with _reading(path):
                data = path.read_bytes()
        with _reading(path):
            npz = _npz(data)
            tracked = None
            if "tracked" in npz:
                saved = _loads(npz["tracked"])
                tracked = pd.DataFrame(saved["data"], columns=saved["columns"])
            row = _loads(npz["row"])
            if not isinstance(row, dict):
                raise CheckpointError(f"{path}: its row is a {type(row).__name__}, not a row "
                                      "of the steps table")
            if row.get("step") != step:
                raise CheckpointError(f"{path}: its row is of step {row.get('step')!r}, not "
                                      f"{step}")
            for key, value in row.items():
                try:
                    _kind(value)
                except CheckpointError as exc:
                    raise CheckpointError(f"{path}: column {key!r} {exc}") from None
            u = np.array(npz["u"])
            if u.ndim != 1 or u.dtype.kind != "f":
                raise CheckpointError(f"{path}: its displacement is not a vector of numbers")
            return SavedStep(row, _frame("points", npz), u, tracked)

    # -- the committed state ----------------------------------------------------------------
    def due(self, step: int, last_step: int) -> bool:
        """Whether the committed state after load ``step`` of ``last_step`` is to be saved."""
        if self.every is not None:
            return step % self.every == 0 or step == last_step
        if step == last_step or self._saved_at is None:
            return True
        since = time.monotonic() - self._saved_at
        return since >= min(SAVE_SPACING * self._save_seconds, 60.0 * self.minutes)

    def save_state(self, step: int, solver: NewtonSolver, material: Material) -> None:
        """Save the committed state after load ``step`` (material first, then the solver's
        state as the commit point, with the manifest of the files it rests on), then drop
        the material file it replaces."""
        started = time.monotonic()
        name = f"material_{step:05d}.npz"
        material.checkpoint(self.folder / name)
        state = solver.committed_state()
        response = state.response
        last = state.last_increment
        if self._options_sum is None and self.has_options():
            self._options_sum = _file_sha256(self.folder / _OPTIONS)
        files = {k: v for k, v in self._sums.items()
                 if not k.startswith("steps/") or int(k[11:-4]) <= step}
        files[name] = _file_sha256(self.folder / name)
        manifest = {"version": _MANIFEST_VERSION, "step": step, "options": self._options_sum,
                    "files": files}
        arrays = {
            "step": np.array(step), "material": np.array(name),
            "u": state.u, "load_factor": np.array(state.load_factor),
            "run_start": np.array(state.run_start),
            "has_last": np.array(last is not None),
            "last_load": np.array(np.nan if last is None else last[0]),
            "last_du": np.zeros(0) if last is None else last[1],
            "records": _dumps([asdict(r) for r in state.records]),
            "response.stress": response.stress, "response.tangent": response.tangent,
            "response.status": response.status,
            "response.fields": _dumps(sorted(response.fields)),
            **{f"response.field.{k}": np.asarray(v) for k, v in response.fields.items()},
            "manifest": _dumps(manifest),
        }
        _write_npz(self.folder / _STATE, arrays)
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
        with _reading(path):
            data = path.read_bytes()
        if manifest is not None:
            expected = manifest["files"].get(name)
            if expected is not None and _sha256(data) != expected:
                raise CheckpointError(
                    f"{path} is not the file this checkpoint saved (its SHA-256 differs: "
                    "changed, truncated or copied from another run)")
        return data

    def _read_state(self) -> tuple[int, str, CommittedState, dict[str, Any] | None]:
        """``state.npz`` read and checked: its step, material file name, the solver state
        and the manifest (None for a checkpoint written before manifests)."""
        path = self.folder / _STATE
        with _reading(path):
            npz = _npz(path.read_bytes())
            missing = [k for k in _STATE_ARRAYS if k not in npz]
            if missing:
                raise CheckpointError(f"{path} lacks the array(s) "
                                      f"{', '.join(map(repr, missing))}: the file is damaged "
                                      "or not a checkpoint file")
            step = int(npz["step"])
            material = str(npz["material"])
            if step < 0 or not _MATERIAL_NAME.fullmatch(material):
                raise CheckpointError(f"{path} names step {step} and material file "
                                      f"{material!r}: not a checkpoint's")
            manifest = _loads(npz["manifest"]) if "manifest" in npz else None
            if manifest is not None and (
                    not isinstance(manifest, dict) or manifest.get("step") != step
                    or not isinstance(manifest.get("files"), dict)):
                raise CheckpointError(f"{path}: its manifest is damaged")
            fields_saved = _loads(npz["response.fields"])
            absent = [k for k in fields_saved if f"response.field.{k}" not in npz]
            if absent:
                raise CheckpointError(f"{path} lacks the array(s) "
                                      f"{', '.join(repr(f'response.field.{k}') for k in absent)}")
            response = MaterialResponse(stress=np.array(npz["response.stress"]),
                                        tangent=np.array(npz["response.tangent"]),
                                        status=np.array(npz["response.status"]),
                                        fields={k: np.array(npz[f"response.field.{k}"])
                                                for k in fields_saved})
            last = ((float(npz["last_load"]), np.array(npz["last_du"]))
                    if bool(npz["has_last"]) else None)
            records = _loads(npz["records"])
            if not isinstance(records, list):
                raise CheckpointError(f"{path}: its Newton records are not a list")
            u = np.array(npz["u"])
            if u.ndim != 1 or u.dtype.kind != "f":
                raise CheckpointError(f"{path}: its displacement is not a vector of numbers")
            if not (math.isfinite(float(npz["load_factor"]))
                    and math.isfinite(float(npz["run_start"]))):
                raise CheckpointError(f"{path}: its load factor is not a number")
            state = CommittedState(
                u=u, load_factor=float(npz["load_factor"]),
                run_start=float(npz["run_start"]), last_increment=last,
                records=[_record(path, r) for r in records], response=response,
            )
        return step, material, state, manifest

    def verify(self) -> SavedRun:
        """Read and check the whole last checkpoint, changing nothing in the folder: every
        file present and readable, each the one the state was saved with (the manifest's
        SHA-256 of the options and of each file), the step rows of steps 0 … its step, all
        alike; :class:`CheckpointError` naming the file and what is wrong. :meth:`load`
        then returns this very checkpoint."""
        path = self.folder / _STATE
        if not path.is_file():
            raise CheckpointError(f"{self.folder} holds no committed state yet")
        step, material, state, manifest = self._read_state()
        options = self.folder / _OPTIONS
        recorded = None if manifest is None else manifest.get("options")
        if recorded is not None and not options.is_file():
            raise CheckpointError(f"{options} is missing: the options the run was started "
                                  "with cannot be checked")
        options_sum = None
        if options.is_file():
            self.read_options()
            options_sum = _file_sha256(options)
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
            sums[name] = _sha256(data)
            saved = self._load_step(k, data)
            if k == 0:
                columns = {key: _kind(value) for key, value in saved.row.items()}
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
                kind = _kind(value)
                if "none" not in (kind, columns[key]) and kind != columns[key]:
                    raise CheckpointError(f"{self._step_path(k)}: column {key!r} holds "
                                          f"{value!r} where step 0 holds a {columns[key]}")
            if saved.u.shape != state.u.shape:
                raise CheckpointError(f"{self._step_path(k)}: its displacement has "
                                      f"{saved.u.size} entries, the state {state.u.size}")
            steps.append(saved)
        data = self._checked_file(material, manifest)
        if manifest is None:
            with _reading(self.folder / material):
                _npz(data)  # readable whole, at least
        sums[material] = _sha256(data)
        if manifest is not None:
            for name in manifest["files"]:
                if name.startswith("tables/"):
                    sums[name] = _sha256(self._checked_file(name, manifest))
        for table in sorted(self.folder.glob("tables/*.npz")):
            name = self._name(table)
            if name not in sums:
                with _reading(table):
                    _frame("table", _npz(table.read_bytes()))
                    sums[name] = _file_sha256(table)
        del sums[material]
        self._sums, self._options_sum = sums, options_sum
        self._verified = SavedRun(step, steps, state, self.folder / material)
        return self._verified

    def load(self) -> SavedRun:
        """The last whole checkpoint (the one :meth:`verify` just returned, else verified
        now); only then are step files past it (written before a later state that never
        came) and half-written files removed."""
        saved = self._verified if self._verified is not None else self.verify()
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
        self._sums[self._name(path)] = _write_npz(path, _frame_arrays("table", frame))

    def load_table(self, name: str) -> pd.DataFrame | None:
        """The table saved as ``name``, or None when there is none."""
        path = self.folder / "tables" / f"{name}.npz"
        if not path.is_file():
            return None
        with _reading(path):
            return _frame("table", _npz(path.read_bytes()))
