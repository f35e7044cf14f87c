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

Every file is written under a temporary name and renamed into place. Numbers are stored in
binary (float64 arrays) or as JSON, whose floats round-trip exactly, so a resumed run
rebuilds the tables bit for bit.
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.fem.material import Material, MaterialResponse
from granular_material.fem.newton import CommittedState, NewtonSolver, StepRecord

__all__ = ["CheckpointError", "RunCheckpoint", "SavedRun", "SavedStep"]

_STATE = "state.npz"
_OPTIONS = "options.json"


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


def _write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """``path`` written whole or not at all (a temporary file renamed into place)."""
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    os.replace(tmp, path)


class RunCheckpoint:
    """The checkpoint folder of one run; ``every``: save the committed state after every this
    many load steps (and after the last step); the per-step tables are kept for every step."""

    def __init__(self, folder: str | Path, every: int = 1) -> None:
        if int(every) != every or every < 1:
            raise ValueError(f"checkpoint every must be an integer >= 1, got {every!r}")
        self.folder = Path(folder)
        self.every = int(every)

    # -- the run's options -------------------------------------------------------------------
    def clear(self) -> None:
        """Remove every checkpoint file of an earlier run in the folder (a fresh start)."""
        for pattern in (_STATE, _OPTIONS, "material_*.npz*", "steps/*.npz*", "tables/*.npz*",
                        "*.part"):
            for path in self.folder.glob(pattern):
                path.unlink()

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
        path = self.folder / _OPTIONS
        tmp = path.with_name(path.name + ".part")
        tmp.write_text(json.dumps(options, indent=2, sort_keys=True, default=str) + "\n")
        os.replace(tmp, path)

    def read_options(self) -> dict[str, Any]:
        """What the run was started with; :class:`CheckpointError` if there is no record."""
        path = self.folder / _OPTIONS
        if not path.is_file():
            raise CheckpointError(f"{self.folder} holds no checkpoint of a run ({_OPTIONS} "
                                  "is missing)")
        try:
            return json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise CheckpointError(f"{path} cannot be read: {exc}") from exc

    def has_options(self) -> bool:
        """Whether a run's options are recorded here (a run was started in the folder)."""
        return (self.folder / _OPTIONS).is_file()

    def has_state(self) -> bool:
        """Whether a committed state has been saved (else a resume starts from the beginning)."""
        return (self.folder / _STATE).is_file()

    # -- steps ------------------------------------------------------------------------------
    def _step_path(self, step: int) -> Path:
        return self.folder / "steps" / f"step_{step:05d}.npz"

    def save_step(self, row: dict[str, Any], points: pd.DataFrame, u: np.ndarray,
                  tracked: pd.DataFrame | None) -> None:
        """Keep one committed step's row, Gauss-point table, displacement [m] and tracked
        rows (None: not tracked)."""
        arrays = {"row": _dumps(row), "u": np.asarray(u, dtype=np.float64),
                  **_frame_arrays("points", points)}
        if tracked is not None:
            arrays["tracked"] = _dumps({"columns": [str(c) for c in tracked.columns],
                                        "data": tracked.to_dict(orient="list")})
        self._step_path(int(row["step"])).parent.mkdir(parents=True, exist_ok=True)
        _write_npz(self._step_path(int(row["step"])), arrays)

    def _load_step(self, step: int) -> SavedStep:
        path = self._step_path(step)
        if not path.is_file():
            raise CheckpointError(f"{path} is missing: the checkpoint is incomplete")
        with np.load(path, allow_pickle=False) as npz:
            tracked = None
            if "tracked" in npz.files:
                saved = _loads(npz["tracked"])
                tracked = pd.DataFrame(saved["data"], columns=saved["columns"])
            return SavedStep(_loads(npz["row"]), _frame("points", npz),
                             np.array(npz["u"]), tracked)

    # -- the committed state ----------------------------------------------------------------
    def due(self, step: int, last_step: int) -> bool:
        """Whether the state after ``step`` (of ``last_step``) is saved."""
        return step % self.every == 0 or step == last_step

    def save_state(self, step: int, solver: NewtonSolver, material: Material) -> None:
        """Save the committed state after load ``step`` (material first, then the solver's
        state as the commit point), then drop the material file it replaces."""
        name = f"material_{step:05d}.npz"
        material.checkpoint(self.folder / name)
        state = solver.committed_state()
        response = state.response
        last = state.last_increment
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
        }
        _write_npz(self.folder / _STATE, arrays)
        self._drop_stale(keep=name)

    def _drop_stale(self, keep: str) -> None:
        """Material files other than ``keep`` and half-written files."""
        for path in self.folder.glob("material_*.npz*"):
            if path.name != keep:
                path.unlink(missing_ok=True)
        for path in self.folder.glob("**/*.part"):
            path.unlink(missing_ok=True)

    def load(self) -> SavedRun:
        """The last whole checkpoint; step files past it (written before a later state that
        never came) are removed."""
        path = self.folder / _STATE
        if not path.is_file():
            raise CheckpointError(f"{self.folder} holds no committed state yet")
        with np.load(path, allow_pickle=False) as npz:
            step = int(npz["step"])
            material = str(npz["material"])
            fields = {k: np.array(npz[f"response.field.{k}"])
                      for k in _loads(npz["response.fields"])}
            response = MaterialResponse(stress=np.array(npz["response.stress"]),
                                        tangent=np.array(npz["response.tangent"]),
                                        status=np.array(npz["response.status"]),
                                        fields=fields)
            last = ((float(npz["last_load"]), np.array(npz["last_du"]))
                    if bool(npz["has_last"]) else None)
            state = CommittedState(
                u=np.array(npz["u"]), load_factor=float(npz["load_factor"]),
                run_start=float(npz["run_start"]), last_increment=last,
                records=[StepRecord(**r) for r in _loads(npz["records"])], response=response,
            )
        self._drop_stale(keep=material)
        for later in self.folder.glob("steps/step_*.npz"):
            if int(later.stem.removeprefix("step_")) > step:
                later.unlink()
        if not (self.folder / material).is_file():
            raise CheckpointError(f"{self.folder / material} is missing: the checkpoint is "
                                  "incomplete")
        steps = [self._load_step(k) for k in range(step + 1)]
        return SavedRun(step, steps, state, self.folder / material)

    # -- tables stored once -----------------------------------------------------------------
    def save_table(self, name: str, frame: pd.DataFrame) -> None:
        """Keep a table of numbers under ``name`` (e.g. a reference curve computed once)."""
        (self.folder / "tables").mkdir(parents=True, exist_ok=True)
        _write_npz(self.folder / "tables" / f"{name}.npz", _frame_arrays("table", frame))

    def load_table(self, name: str) -> pd.DataFrame | None:
        """The table saved as ``name``, or None when there is none."""
        path = self.folder / "tables" / f"{name}.npz"
        if not path.is_file():
            return None
        with np.load(path, allow_pickle=False) as npz:
            return _frame("table", npz)
