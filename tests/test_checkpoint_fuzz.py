"""Damaged checkpoints (issue 24, part 1): a resume reads and checks the whole checkpoint
before it touches the folder. Truncated, emptied, edited, swapped or deleted files give exit
2 naming the file and what is wrong, and leave every file as it was; what is still a whole
checkpoint resumes to the run that never stopped. Never a traceback."""

from __future__ import annotations

import io
import json
import random
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from run_helpers import run_table, without_clock

from granular_material.cli import main
from granular_material.dem import save_rve
from granular_material.procedures import prepare_packing
from granular_material.runs.checkpoint import RunCheckpoint

#: a 16-disc single element of three load steps: a second of DEM per run
ARGV = ["single-element", "--steps", "3", "--axial-strain", "0.003", "--device", "cpu",
        "--no-progress", "--json"]


def _snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` with its bytes."""
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """The RVE file, a finished run (the reference) and a finished run of other options
    (a source of files from another run)."""
    root = tmp_path_factory.mktemp("fuzz")
    rve = root / "rve16.npz"
    save_rve(rve, prepare_packing(n_disc=16, seed=1, pressure=100e3, device="cpu").to_data())
    argv = [*ARGV, "--rve", str(rve)]
    assert main([*argv, "--out", str(root / "reference")]) == 0
    assert main([*argv, "--axial-strain", "0.004", "--out", str(root / "other")]) == 0
    return {"rve": rve, "argv": argv, "reference": root / "reference", "other": root / "other"}


def _rewrite(path: Path, edit) -> None:
    """Rewrite the .npz ``path`` with ``edit(arrays)`` applied (arrays by name)."""
    with np.load(path, allow_pickle=False) as npz:
        arrays = {k: np.array(npz[k]) for k in npz.files}
    edit(arrays)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    path.write_bytes(buffer.getvalue())


def _edit_json(key: str, change) -> object:
    def edit(arrays: dict[str, np.ndarray]) -> None:
        value = json.loads(str(arrays[key]))
        change(value)
        arrays[key] = np.array(json.dumps(value))
    return edit


def _truncate(size) -> object:
    return lambda path: path.write_bytes(path.read_bytes()[:size(path.stat().st_size)])


STATE, STEP0, STEP2, MATERIAL = ("state.npz", "steps/step_00000.npz", "steps/step_00002.npz",
                                 "material_00003.npz")

#: name: (the file under checkpoint/, what is done to it, what the message must say)
DAMAGE = {
    "state truncated": (STATE, _truncate(lambda n: n // 2), "state.npz cannot be read"),
    "state empty": (STATE, _truncate(lambda n: 0), "state.npz cannot be read"),
    "state cut short": (STATE, _truncate(lambda n: n - 30), "state.npz cannot be read"),
    "step truncated": (STEP2, _truncate(lambda n: n // 2), "step_00002.npz"),
    "step empty": (STEP0, _truncate(lambda n: 0), "step_00000.npz"),
    "material truncated": (MATERIAL, _truncate(lambda n: n - 100), "material_00003.npz"),
    "array missing in state": (STATE, lambda p: _rewrite(p, lambda a: a.pop("u")), "'u'"),
    "array missing in step": (STEP2, lambda p: _rewrite(p, lambda a: a.pop("u")),
                              "step_00002.npz"),
    "unknown record field": (STATE, lambda p: _rewrite(p, _edit_json(
        "records", lambda r: r[0].update(bogus=1))), "unknown field(s) 'bogus'"),
    "record field missing": (STATE, lambda p: _rewrite(p, _edit_json(
        "records", lambda r: r[0].pop("step"))), "lacks the field(s) 'step'"),
    "record costs not numbers": (STATE, lambda p: _rewrite(p, _edit_json(
        "records", lambda r: r[0]["costs"].update(dem_steps="7"))),
        "costs are not numbers by name"),
    "records not a list": (STATE, lambda p: _rewrite(p, lambda a: a.update(
        records=np.array("null"))), "records are not a list"),
    "step out of range": (STATE, lambda p: _rewrite(p, lambda a: a.update(step=np.array(7))),
                          "state.npz"),
    "material path outside": (STATE, lambda p: _rewrite(p, lambda a: a.update(
        material=np.array("../../x.npz"))), "not a checkpoint's"),
    "row holds a string": (STEP2, lambda p: _rewrite(p, _edit_json(
        "row", lambda r: r.update(sxx="abc"))), "step_00002.npz"),
    "row lacks a column": (STEP2, lambda p: _rewrite(p, _edit_json(
        "row", lambda r: r.pop("sxx"))), "step_00002.npz"),
    "options a list": ("options.json", lambda p: p.write_text("[1, 2]"), "options.json"),
    "options null": ("options.json", lambda p: p.write_text("null"), "options.json"),
    "options not JSON": ("options.json", lambda p: p.write_text("{steps: 3"), "options.json"),
    "options edited": ("options.json", lambda p: p.write_text(
        p.read_text().replace('"seed": 1', '"seed": 1.0')), "options.json"),
    "options deleted": ("options.json", lambda p: p.unlink(), "options.json is missing"),
    "step deleted": (STEP0, lambda p: p.unlink(), "step_00000.npz is missing"),
    "state of a later step": (STATE, lambda p: _rewrite(p, lambda a: a.pop("manifest")) or
                              _rewrite(p, lambda a: a.update(step=np.array(5))),
                              "step_00004.npz, step_00005.npz are missing"),
    "material deleted": (MATERIAL, lambda p: p.unlink(), "material_00003.npz is missing"),
    "steps folder deleted": ("steps", shutil.rmtree, "step_00000.npz, step_00001.npz"),
}

#: the same damage where the checkpoint has no manifest (as one of an earlier version)
NO_MANIFEST = ("row holds a string", "row lacks a column", "step truncated",
               "material truncated", "step out of range")


def _resume(runs, out: Path, capsys) -> tuple[int, str]:
    code = main([*runs["argv"], "--resume", str(out)])
    return code, capsys.readouterr().err


def _assert_refused(runs, out: Path, capsys, says: str) -> None:
    before = _snapshot(out)
    code, err = _resume(runs, out, capsys)
    assert code == 2, err
    assert "Traceback" not in err and says in err, err
    assert "nothing in the folder was changed" in err, err
    assert _snapshot(out) == before  # not a byte changed, nothing removed


def _assert_same_run(runs, out: Path) -> None:
    for table in ("steps.csv", "points.csv"):
        pd.testing.assert_frame_equal(
            without_clock(run_table(out, table)),
            without_clock(run_table(runs["reference"], table)), check_exact=True)


@pytest.mark.parametrize("case", sorted(DAMAGE))
def test_a_damaged_checkpoint_is_refused_and_left_as_it_was(case, runs, tmp_path, capsys):
    out = tmp_path / "run"
    shutil.copytree(runs["reference"], out)
    name, damage, says = DAMAGE[case]
    damage(out / "checkpoint" / name)
    _assert_refused(runs, out, capsys, says)


@pytest.mark.parametrize("case", NO_MANIFEST)
def test_a_damaged_checkpoint_without_manifest_is_refused(case, runs, tmp_path, capsys):
    out = tmp_path / "run"
    shutil.copytree(runs["reference"], out)
    _rewrite(out / "checkpoint" / STATE, lambda a: a.pop("manifest"))
    name, damage, says = DAMAGE[case]
    damage(out / "checkpoint" / name)
    _assert_refused(runs, out, capsys, says)


@pytest.mark.parametrize("name", [STATE, "steps/step_00001.npz", STEP2, MATERIAL,
                                  "options.json"])
def test_a_file_of_another_run_is_refused(name, runs, tmp_path, capsys):
    out = tmp_path / "run"
    shutil.copytree(runs["reference"], out)
    # (step 0, the initial state, is the same in both runs: taking it is an identical resume)
    shutil.copy(runs["other"] / "checkpoint" / name, out / "checkpoint" / name)
    _assert_refused(runs, out, capsys, "")
    if name != STATE:
        return
    # nothing was lost (issue 24: the refusal deleted the later files): the run's own
    # state.npz put back, the resume goes on
    shutil.copy(runs["reference"] / "checkpoint" / name, out / "checkpoint" / name)
    code, err = _resume(runs, out, capsys)
    assert code == 0, err
    _assert_same_run(runs, out)


def test_random_damage_is_refused_or_resumes_to_the_same_run(runs, tmp_path, capsys):
    """Seeded random cuts and byte flips in random checkpoint files: each resume is refused
    (exit 2, nothing changed) or is the run that never stopped."""
    rng = random.Random(24)
    outcomes = {"refused": 0, "resumed": 0}
    for k in range(12):
        out = tmp_path / f"run{k}"
        shutil.copytree(runs["reference"], out)
        files = sorted(p for p in (out / "checkpoint").rglob("*") if p.is_file())
        path = rng.choice(files)
        data = bytearray(path.read_bytes())
        if rng.random() < 0.5:
            data = data[:rng.randrange(len(data))]
        else:
            where = rng.randrange(len(data))
            data[where] ^= 1 << rng.randrange(8)
        path.write_bytes(bytes(data))
        before = _snapshot(out)
        code, err = _resume(runs, out, capsys)
        assert code in (0, 2) and "Traceback" not in err, err
        if code == 2:
            assert _snapshot(out) == before, err
            outcomes["refused"] += 1
        else:
            _assert_same_run(runs, out)
            outcomes["resumed"] += 1
    assert outcomes["refused"] >= 6, outcomes


def test_records_with_the_old_cost_fields_read_back_and_resume(runs, tmp_path, capsys):
    """A checkpoint written before ``StepRecord.costs`` (its records hold dem_steps,
    rve_evaluations and particle_steps as fields of their own) reads back with them in the
    costs, and resumes to the run that never stopped."""
    out = tmp_path / "run"
    shutil.copytree(runs["reference"], out)
    expected = [r.costs for r in RunCheckpoint(out / "checkpoint").verify().state.records]
    assert expected and all(list(c) == ["dem_steps", "rve_evaluations", "particle_steps"]
                            for c in expected)

    def old_fields(records: list[dict]) -> None:
        for record in records:
            record.update(record.pop("costs"))

    _rewrite(out / "checkpoint" / STATE, _edit_json("records", old_fields))
    assert [r.costs for r in RunCheckpoint(out / "checkpoint").verify().state.records] == \
        expected
    code, err = _resume(runs, out, capsys)
    assert code == 0, err
    _assert_same_run(runs, out)


def test_a_whole_checkpoint_still_resumes(runs, tmp_path, capsys):
    """The untouched copy, and one whose half-written files and later steps are stray,
    resume to the reference; a deleted state.npz starts the run afresh, to the same run."""
    out = tmp_path / "run"
    shutil.copytree(runs["reference"], out)
    (out / "checkpoint" / "steps" / "step_00009.npz.part").write_bytes(b"half")
    code, err = _resume(runs, out, capsys)
    assert code == 0, err
    _assert_same_run(runs, out)
    assert not list(out.rglob("*.part"))
    (out / "checkpoint" / STATE).unlink()
    code, err = _resume(runs, out, capsys)
    assert code == 0 and "starts from the beginning" in err, err
    _assert_same_run(runs, out)
