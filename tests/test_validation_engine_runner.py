"""The validation's DEM runs in process give what the commands give, bit for bit.

``engine_runner.ours_prepare`` / ``ours_biaxial`` / ``ours_drive`` call the library functions
of ``prepare`` / ``biaxial-dem`` / ``dem-drive`` in this process; here each is set against
the command itself (:func:`granular_material.cli.main` with ``--json``) on a small case: the
same RVE arrays, byte-identical CSV files and the same JSON summary (timings aside).
"""

from __future__ import annotations

import filecmp
import json
from pathlib import Path

import numpy as np
import pytest
from granular_material_validation import engine_runner, femxdem_case

from granular_material.cli import main

TIMING = ("wall_s", "cpu_s")


def _command(argv: list[str], capsys: pytest.CaptureFixture) -> dict:
    capsys.readouterr()
    assert main([*argv, "--device", "cpu", "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _same_summary(ours: dict, command: dict) -> None:
    assert all(ours[key] >= 0 for key in TIMING)
    assert {k: v for k, v in ours.items() if k not in TIMING} == command
    assert [k for k in ours if k not in TIMING] == list(command)  # the same keys, in order


def test_prepare_biaxial_and_drive_match_the_commands(tmp_path: Path, capsys) -> None:
    ours = engine_runner.ours_prepare(tmp_path / "ours.npz", particles=30, seed=2,
                                      pressure=1e5, device="cpu")
    theirs = _command(["prepare", "--particles", "30", "--seed", "2", "--pressure", "1e5",
                       "--out", str(tmp_path / "cli.npz")], capsys)
    _same_summary({**ours, "out": theirs["out"]}, theirs)
    a, b = np.load(tmp_path / "ours.npz"), np.load(tmp_path / "cli.npz")
    assert sorted(a.files) == sorted(b.files)
    for key in a.files:
        assert a[key].dtype == b[key].dtype and a[key].tobytes() == b[key].tobytes(), key

    rve = tmp_path / "cli.npz"
    curve, ours = engine_runner.ours_biaxial(rve, tmp_path / "ours_bi.csv",
                                             axial_strain=0.003, record_every=50,
                                             device="cpu")
    theirs = _command(["biaxial-dem", str(rve), "--axial-strain", "0.003", "--record-every",
                       "50", "--out", str(tmp_path / "cli_bi.csv")], capsys)
    _same_summary({**ours, "out": theirs["out"]}, theirs)
    assert filecmp.cmp(tmp_path / "ours_bi.csv", tmp_path / "cli_bi.csv", shallow=False)
    assert curve["step"].iloc[-1] == theirs["steps"] and (curve["rve"] == 0).all()

    path, ours = engine_runner.ours_drive(rve, tmp_path / "ours_drive.csv",
                                          [0.001, 0.0005, 0.0, -0.001], 3, device="cpu")
    theirs = _command(["dem-drive", str(rve), "--grad-u=0.001,0.0005,0.0,-0.001",
                       "--increments", "3", "--out", str(tmp_path / "cli_drive.csv")], capsys)
    _same_summary({**ours, "out": theirs["out"]}, theirs)
    assert filecmp.cmp(tmp_path / "ours_drive.csv", tmp_path / "cli_drive.csv",
                       shallow=False)
    assert path["increment"].tolist() == [0, 1, 2, 3]


def test_a_refused_run_raises_engine_error(tmp_path: Path) -> None:
    with pytest.raises(engine_runner.EngineError, match="prepare"):
        engine_runner.ours_prepare(tmp_path / "few.npz", particles=3, device="cpu")
    assert not (tmp_path / "few.npz").exists()


def test_the_femxdem_variants_are_run_specs() -> None:
    from granular_material.runs import from_flat

    for fields in femxdem_case.ours_variants((1, 2)).values():
        from_flat({"material": "dem", "test": "biaxial", **fields})
    assert set(femxdem_case.ours_variants((1, 2))) == {
        "ours-defaults", "ours-as-gz", "ours-q9", "ours-small-strain", "ours-fine"}


def test_a_cached_femxdem_run_is_keyed_by_the_defaults_it_ran_under(monkeypatch):
    """A run folder's ``run.json`` is read back only for the run the same options make
    today: the key holds every spec field with its default and the Newton settings the DEM
    material gets, so a change of the commands' defaults reruns it."""
    from granular_material.fem.solver import defaults

    flat = {"test": "biaxial", "rve": "rve.npz", "elements": [2, 4], "steps": 30,
            "axial_strain": 0.03, "out": "run", "element": "quad8"}
    today = engine_runner._resolved(flat)
    assert today["tangent"] == "condensed-sticking"
    assert today["newton_settings"]["relaxation"] == "aitken"
    monkeypatch.setattr(defaults, "NOISY_DEFAULTS", {})
    assert engine_runner._resolved(flat) != today
    assert engine_runner._resolved(flat)["newton_settings"]["relaxation"] == "none"
