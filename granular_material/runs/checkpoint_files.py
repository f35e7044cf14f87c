"""The files of a run's checkpoint (:mod:`granular_material.runs.checkpoint` keeps the folder):
their names, how rows, tables, the solver's committed state and its Newton records are
stored in ``.npz`` files, and how each file is read back (:class:`SavedStep`,
:class:`SavedRun`) and checked, every fault a
:class:`CheckpointError` naming the file and what is wrong (never a traceback of the zip or
JSON reader).

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
import weakref
import zipfile
from collections.abc import Iterator
from dataclasses import MISSING, asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.fem import CommittedState, MaterialResponse, StepRecord
from granular_material.filesafe import deferred_signals, write_whole

__all__ = [
    "MANIFEST_VERSION",
    "MATERIAL_NAME",
    "OPTIONS",
    "STATE",
    "CheckpointError",
    "SavedRun",
    "SavedStep",
    "cell_kind",
    "dumps",
    "file_sha256",
    "frame",
    "frame_arrays",
    "loads",
    "read_npz",
    "read_state",
    "read_step",
    "reading",
    "sha256",
    "state_arrays",
    "step_arrays",
    "write_bytes",
    "write_npz",
]

#: the solver's committed state and the manifest: the commit point of a checkpoint
STATE = "state.npz"
#: what the run was started with
OPTIONS = "options.json"
#: version of the manifest kept in ``state.npz``
MANIFEST_VERSION = 1
#: the name of a material file (nothing else may be named by ``state.npz``)
MATERIAL_NAME = re.compile(r"material_\d{5,}\.npz")
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


def dumps(value: Any) -> np.ndarray:
    """``value`` (JSON-able, numpy scalars included) as a string array."""
    return np.array(json.dumps(value, default=_native))


#: the JSON of each Newton record saved so far, by the record's identity (with a weak
#: reference to it): a committed record does not change, and the state saved after every
#: step would otherwise convert every earlier record again, at a cost growing with the steps
_RECORD_JSON: dict[int, tuple[weakref.ref, str]] = {}


def _records(records: list[StepRecord]) -> np.ndarray:
    """``dumps([asdict(r) for r in records])``, each record converted once."""
    parts = []
    for record in records:
        known = _RECORD_JSON.get(id(record))
        if known is None or known[0]() is not record:
            text = json.dumps(asdict(record), default=_native)
            key = id(record)
            _RECORD_JSON[key] = (weakref.ref(record,
                                             lambda _, key=key: _RECORD_JSON.pop(key, None)),
                                 text)
        else:
            text = known[1]
        parts.append(text)
    return np.array("[" + ", ".join(parts) + "]")


def loads(value: np.ndarray) -> Any:
    """What :func:`dumps` stored."""
    return json.loads(str(value))


def frame_arrays(prefix: str, table: pd.DataFrame) -> dict[str, np.ndarray]:
    """The columns of a table of numbers (and text, e.g. a point's region, kept as fixed-width
    strings: an .npz holds no Python objects) as arrays ``prefix.NAME`` plus their order."""
    arrays = {f"{prefix}.{name}": _plain(table[name].to_numpy()) for name in table.columns}
    arrays[f"{prefix}.columns"] = dumps([str(c) for c in table.columns])
    return arrays


def _plain(column: np.ndarray) -> np.ndarray:
    """``column`` as an array an .npz stores without pickling: text objects as strings."""
    return column.astype(str) if column.dtype == object else column


def frame(prefix: str, npz: Any) -> pd.DataFrame:
    """The table :func:`frame_arrays` stored under ``prefix``."""
    columns = loads(npz[f"{prefix}.columns"])
    return pd.DataFrame({name: npz[f"{prefix}.{name}"] for name in columns}, columns=columns)


def sha256(data: bytes) -> str:
    """The SHA-256 of ``data`` (hex)."""
    return hashlib.sha256(data).hexdigest()


def file_sha256(path: Path) -> str:
    """The SHA-256 of the file ``path`` (hex)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def write_bytes(path: Path, data: bytes) -> None:
    """``path`` written whole or not at all (a temporary file renamed into place); a failed
    write leaves no ``.part`` behind, and its error names the file."""
    write_whole(path, lambda tmp: tmp.write_bytes(data))


def write_npz(path: Path, arrays: dict[str, np.ndarray], digest: bool = True) -> str:
    """``path`` written whole or not at all; returns the SHA-256 of what was written (with
    ``digest`` False, of a file no manifest names: the empty string, not computed)."""
    buffer = io.BytesIO()
    # a stop signal handled inside numpy's zip writer would leave it with a member open, and
    # the error of closing it ("Can't close the ZIP file while there is an open writing
    # handle") would replace the stop: the signal waits until the archive is whole
    with deferred_signals():
        np.savez(buffer, **arrays)
    data = buffer.getvalue()
    write_bytes(path, data)
    return sha256(data) if digest else ""


@contextlib.contextmanager
def reading(path: Path) -> Iterator[None]:
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


def read_npz(data: bytes) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file's bytes, read whole (their CRCs checked)."""
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        return {name: np.array(npz[name]) for name in npz.files}


def cell_kind(value: Any) -> str:
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


# -- a step file ------------------------------------------------------------------------------
def step_arrays(row: dict[str, Any], points: pd.DataFrame, u: np.ndarray,
                tracked: pd.DataFrame | None) -> dict[str, np.ndarray]:
    """The arrays of one committed step's file: its row, Gauss-point table, displacement [m]
    and tracked rows (None: not tracked)."""
    arrays = {"row": dumps(row), "u": np.asarray(u, dtype=np.float64),
              **frame_arrays("points", points)}
    if tracked is not None:
        arrays["tracked"] = dumps({"columns": [str(c) for c in tracked.columns],
                                   "data": tracked.to_dict(orient="list")})
    return arrays


def read_step(path: Path, step: int, data: bytes) -> SavedStep:
    """Step ``step``'s file ``path`` from its bytes ``data``, checked: its row is of that step
    and holds numbers and text only."""
    with reading(path):
        npz = read_npz(data)
        tracked = None
        if "tracked" in npz:
            saved = loads(npz["tracked"])
            tracked = pd.DataFrame(saved["data"], columns=saved["columns"])
        row = loads(npz["row"])
        if not isinstance(row, dict):
            raise CheckpointError(f"{path}: its row is a {type(row).__name__}, not a row "
                                  "of the steps table")
        if row.get("step") != step:
            raise CheckpointError(f"{path}: its row is of step {row.get('step')!r}, not "
                                  f"{step}")
        for key, value in row.items():
            try:
                cell_kind(value)
            except CheckpointError as exc:
                raise CheckpointError(f"{path}: column {key!r} {exc}") from None
        u = np.array(npz["u"])
        if u.ndim != 1 or u.dtype.kind != "f":
            raise CheckpointError(f"{path}: its displacement is not a vector of numbers")
        return SavedStep(row, frame("points", npz), u, tracked)


# -- the state file ---------------------------------------------------------------------------
def state_arrays(step: int, material: str, state: CommittedState,
                 manifest: dict[str, Any]) -> dict[str, np.ndarray]:
    """The arrays of ``state.npz``: the solver's committed ``state`` after load ``step``, the
    name of the ``material`` file saved with it and the ``manifest``."""
    response = state.response
    last = state.last_increment
    return {
        "step": np.array(step), "material": np.array(material),
        "u": state.u, "load_factor": np.array(state.load_factor),
        "run_start": np.array(state.run_start),
        "has_last": np.array(last is not None),
        "last_load": np.array(np.nan if last is None else last[0]),
        "last_du": np.zeros(0) if last is None else last[1],
        "records": _records(state.records),
        "response.stress": response.stress, "response.tangent": response.tangent,
        "response.status": response.status,
        "response.fields": dumps(sorted(response.fields)),
        **{f"response.field.{k}": np.asarray(v) for k, v in response.fields.items()},
        "manifest": dumps(manifest),
        **({} if state.second_gradient is None else {
            "second_gradient": state.second_gradient,
            "second_gradient_modulus": np.array(state.second_gradient_modulus)}),
        **({} if state.f_int is None else {"f_int": np.asarray(state.f_int, dtype=np.float64)}),
        **({} if state.continuation is None else {"continuation": dumps(state.continuation)}),
    }


def read_state(path: Path) -> tuple[int, str, CommittedState, dict[str, Any] | None]:
    """``state.npz`` at ``path`` read and checked: its step, material file name, the solver
    state and the manifest (None for a checkpoint written before manifests)."""
    with reading(path):
        npz = read_npz(path.read_bytes())
        missing = [k for k in _STATE_ARRAYS if k not in npz]
        if missing:
            raise CheckpointError(f"{path} lacks the array(s) "
                                  f"{', '.join(map(repr, missing))}: the file is damaged "
                                  "or not a checkpoint file")
        step = int(npz["step"])
        material = str(npz["material"])
        if step < 0 or not MATERIAL_NAME.fullmatch(material):
            raise CheckpointError(f"{path} names step {step} and material file "
                                  f"{material!r}: not a checkpoint's")
        manifest = loads(npz["manifest"]) if "manifest" in npz else None
        if manifest is not None and (
                not isinstance(manifest, dict) or manifest.get("step") != step
                or not isinstance(manifest.get("files"), dict)):
            raise CheckpointError(f"{path}: its manifest is damaged")
        fields_saved = loads(npz["response.fields"])
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
        records = loads(npz["records"])
        if not isinstance(records, list):
            raise CheckpointError(f"{path}: its Newton records are not a list")
        u = np.array(npz["u"])
        if u.ndim != 1 or u.dtype.kind != "f":
            raise CheckpointError(f"{path}: its displacement is not a vector of numbers")
        if not (math.isfinite(float(npz["load_factor"]))
                and math.isfinite(float(npz["run_start"]))):
            raise CheckpointError(f"{path}: its load factor is not a number")
        second_gradient = (np.array(npz["second_gradient"], dtype=np.float64)
                           if "second_gradient" in npz else None)
        modulus = (float(npz["second_gradient_modulus"])
                   if "second_gradient_modulus" in npz else None)
        if (second_gradient is None) != (modulus is None) or (
                modulus is not None and not (math.isfinite(modulus) and modulus > 0)):
            raise CheckpointError(f"{path}: its second-gradient state is damaged")
        f_int = np.array(npz["f_int"]) if "f_int" in npz else None  # older: assembled anew
        if f_int is not None and (f_int.shape != u.shape or f_int.dtype.kind != "f"):
            raise CheckpointError(f"{path}: its internal force is not a vector of numbers "
                                  "like its displacement")
        continuation = loads(npz["continuation"]) if "continuation" in npz else None
        if continuation is not None and not isinstance(continuation, dict):
            raise CheckpointError(f"{path}: its arc-length path is damaged")
        state = CommittedState(
            u=u, load_factor=float(npz["load_factor"]),
            run_start=float(npz["run_start"]), last_increment=last,
            records=[_record(path, r) for r in records], response=response, f_int=f_int,
            second_gradient=second_gradient, second_gradient_modulus=modulus,
            continuation=continuation,
        )
    return step, material, state, manifest
