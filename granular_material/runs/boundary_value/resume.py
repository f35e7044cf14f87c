"""The checkpoint of a boundary-value run, so that a stopped one continues where it stopped.

A boundary-value run keeps ``<out>/checkpoint/`` (a
:class:`~granular_material.runs.checkpoint.RunCheckpoint`): the scene it was started with,
every committed step's row, Gauss-point table and displacement, and the committed state of
solver and material, saved by elapsed time (a cheap save after every step, an expensive one
— thousands of RVEs with their contacts — at most about a tenth of the run's time, and at
the latest every ten minutes). A run that reaches its last step removes it; one stopped by
Ctrl-C, a kill or a step that did not converge keeps it, and
``run_boundary_value(spec, resume=True)`` (``granular-material run SCENE --resume``) continues
from its last saved state: the tables, fields and figures are those of a run that never
stopped. A folder holding a stopped run's checkpoint is refused to a fresh run, so that hours
of work are not thrown away by a run started twice.

Beside the scene the checkpoint keeps the SHA-256 of every file the run reads (its mesh file,
its RVE file: :func:`run_files`); a resume whose file has changed is refused naming it, with
nothing in the folder changed. A checkpoint written before the hashes were kept (no
``files`` in its options) still resumes: its files cannot be checked, and a note on stderr
says so.
"""

from __future__ import annotations

import json
import sys
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pandas as pd

from granular_material.runs.boundary_value.spec import BoundaryValueSpec
from granular_material.runs.checkpoint import CheckpointError, RunCheckpoint, SavedRun
from granular_material.runs.checkpoint_files import file_sha256
from granular_material.runs.run_folder import failed_error
from granular_material.runs.spec import SpecError

__all__ = ["RESUME_FREE", "check_not_stopped", "open_bvp_checkpoint", "remember", "run_files",
           "scene_record", "start_bvp_checkpoint"]

#: the scene's fields a resume may change: where it writes, how it reports (tables, fields,
#: figures), the device and the CPU shards (none changes a result beyond the DEM's float
#: rounding)
RESUME_FREE = frozenset({"out", "progress", "device", "shards", "fields", "points_csv",
                         "figures"})
#: minutes between saves of the committed state at the latest
SAVE_MINUTES = 10.0


def scene_record(spec: BoundaryValueSpec) -> dict[str, Any]:
    """``spec`` as JSON values (paths as text), as a checkpoint records and compares it (a
    scene without phases: no ``phases``, as it was recorded before they were added)."""
    record = json.loads(json.dumps(asdict(spec), default=str))
    if not record.get("phases"):
        record.pop("phases", None)
    return record


def run_files(spec: BoundaryValueSpec) -> dict[str, Path]:
    """The files a run of ``spec`` reads, by the scene key that names them: ``mesh.file`` and
    the DEM material's ``material.parameters.rve`` (where given; by region,
    ``materials[k].parameters.rve``)."""
    files = {"mesh.file": spec.mesh.file,
             "material.parameters.rve": getattr(spec.material.parameters, "rve", None)}
    for k, m in enumerate(spec.materials or ()):
        files[f"materials[{k}].parameters.rve"] = getattr(m.material.parameters, "rve", None)
    return {name: Path(path) for name, path in files.items() if path is not None}


def _hashes(spec: BoundaryValueSpec) -> dict[str, dict[str, str]]:
    """key → {"path", "sha256"} of every file of :func:`run_files` (one that cannot be read:
    no hash; the run's own check refuses it)."""
    return {name: {"path": str(path), "sha256": file_sha256(path)}
            for name, path in run_files(spec).items() if path.is_file()}


def _changed_file(spec: BoundaryValueSpec, saved: Any, out: Path) -> None:
    """SpecError naming the first file of the run whose content differs from the one the
    checkpoint's ``saved`` hashes record (None: an older checkpoint, not checked)."""
    if saved is None:
        print(f"granular-material: {out}'s checkpoint predates the files' hashes: the mesh "
              "and RVE files are not checked against the ones the run started with",
              file=sys.stderr)
        return
    for name, now in _hashes(spec).items():
        then = saved.get(name) if isinstance(saved, dict) else None
        if not isinstance(then, dict) or then.get("sha256") != now["sha256"]:
            raise SpecError(name, f"{now['path']} is not the file the run in {out} was "
                                  "started with (its SHA-256 differs from the checkpoint's): "
                                  "resume it with the same file (nothing in the folder was "
                                  "changed)")


def _same(now: Any, then: Any) -> bool:
    """``now`` equals ``then``, where a key missing from a table of either counts as None (a
    field added since the checkpoint was written, at its default None, is no difference)."""
    if isinstance(now, dict) and isinstance(then, dict):
        return all(_same(now.get(k), then.get(k)) for k in set(now) | set(then))
    if isinstance(now, list) and isinstance(then, list):
        return len(now) == len(then) and all(map(_same, now, then))
    return now == then


def _differences(now: dict[str, Any], then: dict[str, Any]) -> list[str]:
    keys = sorted((set(now) | set(then)) - RESUME_FREE)
    return [k for k in keys if not _same(now.get(k), then.get(k))]


def _checkpoint(out: Path) -> RunCheckpoint:
    return RunCheckpoint(Path(out) / "checkpoint", every=None, minutes=SAVE_MINUTES)


def check_not_stopped(spec: BoundaryValueSpec, out: Path) -> None:
    """:class:`SpecError` on ``out`` when it holds the checkpoint of a stopped run (a fresh
    run there would throw it away): continue it with ``resume``; or of a run that failed,
    which cannot be resumed: another folder, or its checkpoint deleted."""
    checkpoint = _checkpoint(out)
    if checkpoint.has_state():
        step = checkpoint.saved_step()
        error = failed_error(out, checkpoint.folder)
        if error is not None:
            raise SpecError("out", f"{out} holds a boundary-value run that failed "
                                   f"({error}); a failed run cannot be resumed (its failed "
                                   "step would fail again): write to another folder, or "
                                   f"delete its checkpoint folder ({checkpoint.folder}) to "
                                   "run it afresh there")
        raise SpecError("out", f"{out} holds a boundary-value run stopped after load step "
                               f"{step} of {spec.steps} (its checkpoint): continue it with "
                               "`resume`, or write to another folder (delete its checkpoint "
                               "folder to start it afresh)")


def open_bvp_checkpoint(spec: BoundaryValueSpec, out: Path | None, resume: bool,
                        ) -> tuple[RunCheckpoint | None, SavedRun | None]:
    """The checkpoint of the run of ``spec`` in ``out``, and what it saved when resuming
    (None, None for a run that writes nothing; such a run cannot be resumed). Nothing in the
    folder is changed here: :func:`start_bvp_checkpoint` does that once the run starts.

    ``resume``: the saved run, checked whole and against ``spec`` (:class:`SpecError`
    naming the fields that differ). A folder with no run to continue (empty, never started,
    or finished: its checkpoint is removed at the end) starts the run from step 0, with a
    note on stderr, as the other commands' ``--resume`` does, so that a batch script can
    always ask to resume. A fresh run into a folder whose checkpoint holds a stopped run is
    refused (:class:`SpecError` on ``out``); an empty or finished one is started afresh.
    """
    if out is None:
        if resume:
            raise SpecError("out", "resume needs the run folder of the run to continue")
        return None, None
    checkpoint = _checkpoint(out)
    record = scene_record(spec)
    if not resume:
        check_not_stopped(spec, out)
        return checkpoint, None
    if not checkpoint.has_options():
        if checkpoint.has_state():
            raise SpecError("out", f"{out}: {checkpoint.folder / 'options.json'} is missing, "
                                   "so the scene the run was started with cannot be "
                                   "checked (nothing in the folder was changed)")
        print(f"granular-material run: {out} holds no stopped boundary-value run (no "
              "checkpoint); the run starts from the beginning", file=sys.stderr)
        return checkpoint, None
    try:
        options = checkpoint.read_options()
    except CheckpointError as exc:
        raise SpecError("out", f"cannot resume: {exc} (nothing in the folder was "
                               "changed)") from None
    saved_scene = options.get("scene")
    if not isinstance(saved_scene, dict):
        raise SpecError("out", f"{out}'s checkpoint is not a boundary-value run's (nothing "
                               "in the folder was changed)")
    differ = _differences(record, saved_scene)
    if differ:
        raise SpecError(differ[0], f"the scene differs from the one the run in {out} was "
                                   f"started with in {', '.join(differ)}: resume it with "
                                   "the same scene (nothing in the folder was changed)")
    _changed_file(spec, options.get("files"), out)
    if not checkpoint.has_state():
        return checkpoint, None
    try:
        return checkpoint, checkpoint.verify()  # checked whole; the folder tidied at start
    except CheckpointError as exc:
        raise SpecError("out", f"cannot resume: {exc} (nothing in the folder was "
                               "changed)") from None


def start_bvp_checkpoint(spec: BoundaryValueSpec, checkpoint: RunCheckpoint | None,
                         saved: SavedRun | None) -> None:
    """The run starts writing: a fresh one records its scene and files in ``checkpoint``
    (an earlier run's emptied), a resumed one tidies it (step files past the state it
    continues from, half-written files)."""
    if checkpoint is None:
        return
    if saved is None:
        checkpoint.start({"scene": scene_record(spec), "files": _hashes(spec)})
    else:
        checkpoint.load()


def remember(checkpoint: RunCheckpoint | None, name: str,
             values: dict[str, float] | None = None) -> dict[str, float]:
    """``values`` (numbers by name) kept in the checkpoint as table ``name``; without
    ``values``, those it kept ({} where none)."""
    if values is not None:
        if checkpoint is not None:
            checkpoint.save_table(name, pd.DataFrame([values]))
        return values
    table = None if checkpoint is None else checkpoint.load_table(name)
    return {} if table is None else {k: float(v) for k, v in table.iloc[0].items()}
