"""A resume checks every file the run reads (its mesh file, its RVE file) against the SHA-256
its checkpoint keeps: a changed one is refused naming it, with nothing in the folder changed;
an older checkpoint without the hashes still resumes (issue 61, kind 2)."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import meshio
import numpy as np
import pandas as pd
import pytest
import tomllib
from run_helpers import PRESSED_BLOCK
from test_bvp_resume import _stop_at

from granular_material.cli import main
from granular_material.runs.boundary_value.resume import (
    open_bvp_checkpoint,
    run_files,
    start_bvp_checkpoint,
)
from granular_material.runs.boundary_value.runner import run_boundary_value
from granular_material.runs.boundary_value.spec import bvp_from_dict
from granular_material.runs.checkpoint import RunCheckpoint
from granular_material.runs.spec import SpecError

SCENE = """test = "boundary-value"
steps = 3
[mesh]
file = "block.msh"
[boundaries]
base = "y = bottom"
top = "y = top"
""" + PRESSED_BLOCK.format(base="base")


def _block(path: Path, shift: float = 0.0) -> Path:
    """A 2 × 2 quad4 block 0.4 × 0.2 m; ``shift`` [m] moves its centre node along x."""
    x, y = np.meshgrid(np.linspace(0, 0.4, 3), np.linspace(0, 0.2, 3))
    points = np.column_stack([x.ravel(), y.ravel(), np.zeros(9)])
    points[4, 0] += shift
    cells = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7]]
    meshio.write(path, meshio.Mesh(points, [("quad", np.array(cells))]), file_format="gmsh22",
                 binary=False)
    return path


def _folder_state(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _stopped(tmp_path: Path, monkeypatch, old: bool = False) -> tuple[Path, Path]:
    """A run stopped before load step 2 (``old``: its checkpoint as written before the files'
    hashes were kept)."""
    tmp_path.mkdir(exist_ok=True)
    _block(tmp_path / "block.msh")
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    out = tmp_path / "run"
    with monkeypatch.context() as m:
        _stop_at(m, 2)
        if old:
            start = RunCheckpoint.start
            m.setattr(RunCheckpoint, "start", lambda self, options: start(
                self, {k: v for k, v in options.items() if k != "files"}))
        assert main(["run", str(scene), "--out", str(out)]) != 0
    assert (out / "checkpoint").is_dir()
    return scene, out


@pytest.mark.parametrize("change", ["node moved 5 cm", "node moved 1e-12 m", "rewritten"])
def test_a_resume_after_the_mesh_file_changed_is_refused_naming_it(tmp_path, monkeypatch,
                                                                    capsys, change):
    scene, out = _stopped(tmp_path, monkeypatch)
    shift = {"node moved 5 cm": 0.05, "node moved 1e-12 m": 1e-12, "rewritten": 0.0}[change]
    if change == "rewritten":  # the same mesh, another file: its bytes differ
        (tmp_path / "block.msh").write_text((tmp_path / "block.msh").read_text() + "\n")
    else:
        _block(tmp_path / "block.msh", shift)
    before = _folder_state(out)
    capsys.readouterr()
    assert main(["run", str(scene), "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "mesh.file" in err and "block.msh" in err and "SHA-256" in err
    assert _folder_state(out) == before


def test_a_resume_with_the_same_files_reaches_the_uninterrupted_run(tmp_path, monkeypatch):
    scene, out = _stopped(tmp_path, monkeypatch)
    assert main(["run", str(scene), "--out", str(out), "--resume"]) == 0
    assert main(["run", str(scene), "--out", str(tmp_path / "whole")]) == 0
    a, b = (pd.read_csv(f / "steps.csv").drop(columns=["wall_time"]) for f in
            (out, tmp_path / "whole"))
    pd.testing.assert_frame_equal(a, b, check_exact=True)


def test_an_older_checkpoint_without_hashes_still_resumes(tmp_path, monkeypatch, capsys):
    assert set(json.loads((_stopped(tmp_path / "new", monkeypatch)[1] / "checkpoint" /
                           "options.json").read_text())["files"]) == {"mesh.file"}
    scene, out = _stopped(tmp_path, monkeypatch, old=True)
    assert "files" not in json.loads((out / "checkpoint" / "options.json").read_text())
    capsys.readouterr()
    assert main(["run", str(scene), "--out", str(out), "--resume"]) == 0
    assert "not checked" in capsys.readouterr().err


def test_a_resume_after_the_rve_file_changed_is_refused_naming_it(tmp_path, small_rve_path):
    rve = tmp_path / "rve.npz"
    shutil.copy(small_rve_path, rve)
    data = tomllib.loads(SCENE.replace('name = "linear-elastic"', 'name = "dem"').replace(
        "young = 60e6\npoisson = 0.3", f'rve = "{rve}"'))
    _block(tmp_path / "block.msh")
    spec = bvp_from_dict(data, tmp_path)
    assert set(run_files(spec)) == {"mesh.file", "material.parameters.rve"}
    out = tmp_path / "run"
    start_bvp_checkpoint(spec, *open_bvp_checkpoint(spec, out, resume=False))  # a fresh run's
    open_bvp_checkpoint(spec, out, resume=True)  # the same files: accepted
    with np.load(small_rve_path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    first = next(k for k, v in arrays.items() if v.dtype.kind == "f" and v.size)
    arrays[first] = arrays[first] * (1 + 1e-9)
    np.savez(rve, **arrays)
    before = _folder_state(out)
    with pytest.raises(SpecError) as refused:
        open_bvp_checkpoint(spec, out, resume=True)
    assert refused.value.field == "material.parameters.rve" and "rve.npz" in str(refused.value)
    assert _folder_state(out) == before


def test_a_run_without_files_records_none(tmp_path):
    data = tomllib.loads(SCENE.replace('file = "block.msh"', "size = [0.4, 0.2]\n"
                                       "elements = [2, 2]"))
    spec = bvp_from_dict(data, tmp_path)
    assert run_files(spec) == {}
    assert run_boundary_value(spec, out=tmp_path / "run").error is None
