"""The core command line: prepare, dem-drive, biaxial-dem (names and keys users rely on)."""

from __future__ import annotations

import json
from dataclasses import replace

import pandas as pd
import pytest
from run_helpers import run_table

from granular_material.cli import main
from granular_material.dem import DEMBatch, load_rve, save_rve


def _json(capsys: pytest.CaptureFixture) -> dict:
    return json.loads(capsys.readouterr().out)


def test_prepare_writes_a_batch_and_reports(tmp_path, capsys):
    out = tmp_path / "rve.npz"
    rc = main(["prepare", "--particles", "40", "--batch", "2", "--seed", "5",
               "--out", str(out), "--device", "cpu", "--json"])
    assert rc == 0
    report = _json(capsys)
    assert {"void_ratio", "mean_stress", "coordination", "cell", "particles"} <= set(report)
    assert report["particles"] == 40
    assert len(report["void_ratio"]) == 2
    for p in report["mean_stress"]:
        assert p == pytest.approx(-100e3, rel=0.01)
    data = load_rve(out)
    assert data.radius.shape == (2, 40)
    assert data.meta.seed == 5


def test_dem_drive_csv_and_exact_timestep(small_rve_path, tmp_path, capsys):
    data = load_rve(small_rve_path)
    rve = tmp_path / "dt.npz"
    save_rve(rve, replace(data, meta=replace(data.meta, timestep=3.0e-6)))
    assert DEMBatch(load_rve(rve), device="cpu").dt.tolist() == [3.0e-6]
    csv = tmp_path / "path.csv"
    rc = main(["dem-drive", str(rve), "--grad-u", "0,0.001,0,0", "--increments", "3",
               "--out", str(csv), "--device", "cpu", "--json"])
    assert rc == 0
    report = _json(capsys)
    table = pd.read_csv(csv)
    expected = ["rve", "increment", "Gxx", "Gxy", "Gyx", "Gyy", "sxx", "syy", "sxy",
                "void_ratio", "coordination"]
    assert list(table.columns[: len(expected)]) == expected
    assert table["increment"].tolist() == [0, 1, 2, 3]
    assert table["Gxy"].iloc[-1] == pytest.approx(1e-3)
    # simple shear raises the shear stress magnitude
    assert abs(table["sxy"].iloc[-1]) > abs(table["sxy"].iloc[0])
    assert report["sxy"] == pytest.approx(table["sxy"].iloc[-1])


def test_biaxial_dem_reports_peak(small_rve_path, tmp_path, capsys):
    csv = tmp_path / "curve.csv"
    rc = main(["biaxial-dem", str(small_rve_path), "--axial-strain", "0.01", "--confining",
               "100e3", "--out", str(csv), "--device", "cpu", "--json"])
    assert rc == 0
    report = _json(capsys)
    assert {"peak_stress_ratio", "axial_strain_at_peak", "max_contraction",
            "final_void_ratio"} <= set(report)
    curve = pd.read_csv(csv)
    assert {"axial_strain", "volumetric_strain", "sxx", "syy", "sxy",
            "void_ratio"} <= set(curve.columns)
    assert curve["axial_strain"].iloc[-1] == pytest.approx(0.01, rel=1e-9)
    assert report["peak_stress_ratio"] > 1.5
    # lateral stress held by the servo at the confining pressure
    assert (curve["sxx"] / -100e3 - 1).abs().max() < 0.02


@pytest.mark.parametrize(
    "argv, message",
    [
        (["dem-drive", "{rve}", "--grad-u", "nan,0,0,0", "--out", "{out}"], "finite"),
        (["dem-drive", "{rve}", "--grad-u", "1,2,3", "--out", "{out}"], "four"),
        (["biaxial-dem", "{junk}", "--out", "{out}"], "not a readable RVE file"),
        (["prepare", "--particles", "0", "--out", "{out}"], "must be >= 1"),
        (["prepare", "--pressure", "-5", "--out", "{out}"], "positive"),
    ],
)
def test_bad_input_exits_2_and_writes_nothing(small_rve_path, tmp_path, capsys, argv, message):
    junk = tmp_path / "junk.npz"
    junk.write_text("garbage")
    out = tmp_path / "out.csv"
    argv = [a.format(rve=small_rve_path, out=out, junk=junk) for a in argv]
    try:
        rc = main([*argv, "--device", "cpu"])
    except SystemExit as exc:  # argparse rejects malformed values itself
        rc = exc.code
    assert rc == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_outputs_go_into_new_folders(small_rve_path, tmp_path, capsys):
    out = tmp_path / "a" / "b" / "path.csv"
    rc = main(["dem-drive", str(small_rve_path), "--grad-u", "0,0,0,0", "--increments", "1",
               "--out", str(out), "--device", "cpu"])
    assert rc == 0
    assert out.exists()


def test_a_prepared_file_gives_a_run_the_rves_it_would_prepare(tmp_path, capsys):
    """Prepare once, run many: ``prepare --batch B --seed S`` then ``--rve`` gives a FEM run
    the RVEs it prepares itself from ``--seed S`` (one per Gauss point), bit for bit."""
    rves = tmp_path / "rves.npz"
    assert main(["prepare", "--particles", "24", "--batch", "4", "--seed", "3",
                 "--out", str(rves), "--device", "cpu", "--no-progress"]) == 0
    common = ["biaxial", "--elements", "1", "1", "--steps", "1", "--axial-strain", "0.002",
              "--shards", "1", "--device", "cpu", "--no-progress"]
    assert main([*common, "--particles", "24", "--seed", "3", "--out",
                 str(tmp_path / "own")]) == 0
    assert main([*common, "--rve", str(rves), "--out", str(tmp_path / "file")]) == 0
    capsys.readouterr()
    for table in ("steps.csv", "points.csv"):
        own, file = (run_table(tmp_path / run, table).drop(columns="wall_time",
                                                               errors="ignore")
                     for run in ("own", "file"))
        pd.testing.assert_frame_equal(own, file, check_exact=True)
