"""The command line says when it cannot do what was asked (issue 12, parts 4 and 5): missed
targets exit 1 with the reached value (or warn), bad output paths and step counts are refused
before any work, and a rejected run leaves nothing behind."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from granular_material.cli import main
from granular_material.dem import load_rve, save_rve
from granular_material.procedures import prepare_packing
from granular_material.results import write_csv


@pytest.fixture(scope="module")
def rve64(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, float]:
    """A 64-disc RVE file (seed 1, 100 kPa) and its void ratio."""
    batch = prepare_packing(n_disc=64, seed=1, pressure=100e3, device="cpu")
    path = tmp_path_factory.mktemp("rve") / "rve64.npz"
    save_rve(path, batch.to_data())
    return path, float(batch.homogenize().void_ratio[0])


def _run(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, dict | None, str]:
    """Exit code, the JSON report (None when nothing was printed) and stderr."""
    code = main([*argv, "--json"])
    captured = capsys.readouterr()
    return code, json.loads(captured.out) if captured.out.strip() else None, captured.err


# -- 4: targets that cannot be reached ------------------------------------------------------
def test_biaxial_dem_servo_overrun_is_a_failure(rve64, tmp_path, capsys):
    csv = tmp_path / "curve.csv"
    code, report, err = _run(capsys, "biaxial-dem", str(rve64[0]), "--strain-per-step", "0.05",
                             "--out", str(csv), "--device", "cpu")
    assert code == 1
    assert "--confining" in err and "final σxx" in err
    assert report["final_sxx"] < -2e5  # the reached value, far past -100 kPa
    assert report["error"] and report["max_confining_error"] > 1
    assert len(pd.read_csv(csv)) > 1  # the curve is kept as the evidence


def test_biaxial_dem_unreachable_confining_is_a_failure(rve64, capsys):
    code, report, err = _run(capsys, "biaxial-dem", str(rve64[0]), "--confining", "1e-3",
                             "--axial-strain", "0.002", "--device", "cpu")
    assert code == 1 and "-0.001" in err.replace("−", "-")
    assert abs(report["final_sxx"]) > 1e-2


def test_biaxial_dem_held_confining_reports_no_warning(rve64, capsys):
    code, report, _ = _run(capsys, "biaxial-dem", str(rve64[0]), "--axial-strain", "0.002",
                           "--device", "cpu")
    assert code == 0 and report["warnings"] == [] and report["error"] is None
    assert report["max_confining_error"] < 0.02


def test_prepare_unreached_void_ratio_fails_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "dense.npz"
    code, report, err = _run(capsys, "prepare", "--particles", "64", "--target-void-ratio",
                             "0.01", "--out", str(out), "--device", "cpu")
    assert code == 1
    assert "--target-void-ratio 0.01" in err and f"{report['void_ratio']:.4g}" in err
    assert report["void_ratio"] > 0.1 and not out.exists()


def test_prepare_barely_missed_void_ratio_warns(rve64, tmp_path, capsys):
    # a target the compaction cannot reach: the packing ends near e of rve64 (no target)
    target = rve64[1] - 0.002
    out = tmp_path / "rve.npz"
    code, report, err = _run(capsys, "prepare", "--particles", "64", "--target-void-ratio",
                             f"{target}", "--out", str(out), "--device", "cpu")
    assert code == 0 and out.exists()
    assert rve64[1] - 0.002 < report["void_ratio"] < rve64[1] + 0.002
    assert len(report["warnings"]) == 1 and "--target-void-ratio" in report["warnings"][0]
    assert "warning" in err


def test_single_element_refuses_a_two_rve_file(rve64, tmp_path, capsys):
    two = tmp_path / "two.npz"
    save_rve(two, load_rve(rve64[0]).replicate(2))
    code, _, err = _run(capsys, "single-element", "--rve", str(two), "--device", "cpu",
                        "--no-progress")
    assert code == 2 and "holds 2 RVEs" in err
    code, _, err = _run(capsys, "single-element", "--rve", str(rve64[0]), "--independent",
                        "--device", "cpu", "--no-progress")
    assert code == 2 and "--independent" in err


# -- 5: refused before work, nothing left behind ---------------------------------------------
@pytest.mark.skipif(os.geteuid() == 0, reason="root writes in read-only folders")
def test_read_only_out_is_refused_before_work(rve64, tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        code, _, err = _run(capsys, "dem-drive", str(rve64[0]), "--grad-u", "0,0.001,0,0",
                            "--out", str(locked / "path.csv"), "--device", "cpu")
    finally:
        locked.chmod(0o700)
    assert code == 2 and "cannot write" in err


@pytest.mark.parametrize("command", [
    ["dem-drive", "{rve}", "--grad-u", "0,0.001,0,0"],
    ["biaxial-dem", "{rve}", "--axial-strain", "0.002"],
    ["prepare", "--particles", "64"],
])
def test_out_under_a_file_is_refused_before_work(command, rve64, tmp_path, capsys):
    argv = [a.format(rve=rve64[0]) for a in command]
    code, _, err = _run(capsys, *argv, "--out", str(rve64[0] / "x"), "--device", "cpu")
    assert code == 2 and "is not a folder" in err


def test_out_naming_a_folder_is_refused_and_leaves_no_part(rve64, tmp_path, capsys):
    folder = tmp_path / "curve"
    folder.mkdir()
    code, _, err = _run(capsys, "biaxial-dem", str(rve64[0]), "--axial-strain", "0.002",
                        "--out", str(folder), "--device", "cpu")
    assert code == 2 and "is a folder" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["curve"]
    with pytest.raises(IsADirectoryError):
        write_csv(pd.DataFrame({"a": [1]}), folder)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["curve"]


@pytest.mark.parametrize("argv", [
    ["dem-drive", "{junk}", "--grad-u", "0,0.001,0,0", "--out", "{new}/path.csv"],
    ["dem-drive", "{rve}", "--grad-u=-2,0,0,0", "--out", "{new}/path.csv"],
    ["dem-drive", "{rve}", "--grad-u=-2,0,0,-3", "--increments", "1", "--out",
     "{new}/path.csv"],
    ["biaxial-dem", "{rve}", "--axial-strain", "0.95", "--out", "{new}/c.csv"],
    ["prepare", "--particles", "5", "--out", "{new}/rve.npz"],
    ["single-element", "--material", "linear-elastic", "--rtol", "-1", "--out", "{new}"],
])
def test_rejected_input_leaves_no_folder(argv, rve64, tmp_path, capsys):
    junk = tmp_path / "junk.npz"
    junk.write_text("not an RVE")
    new = tmp_path / "new" / "deeper"
    argv = [a.format(rve=rve64[0], junk=junk, new=new) for a in argv]
    code, _, _ = _run(capsys, *argv, "--device", "cpu", "--no-progress")
    assert code == 2
    assert not (tmp_path / "new").exists()


def test_huge_grad_u_names_the_cap(rve64, capsys):
    code, _, err = _run(capsys, "dem-drive", str(rve64[0]), "--grad-u", "1e300,0,0,0",
                        "--device", "cpu")
    assert code == 2 and "--max-dem-steps" in err and "-9223372036854775808" not in err


def test_dem_drive_step_cap_counts_every_increment(rve64, tmp_path, capsys):
    # 0.001/3 a increment at 1e-5 a step: 34 steps each, 102 in all
    argv = ["dem-drive", str(rve64[0]), "--grad-u", "0,0.001,0,0", "--increments", "3",
            "--device", "cpu"]
    code, _, err = _run(capsys, *argv, "--max-dem-steps", "101")
    assert code == 2 and "102 DEM steps" in err and "--max-dem-steps 101" in err
    code, _, err = _run(capsys, "dem-drive", str(rve64[0]), "--grad-u", "100,0,0,100",
                        "--device", "cpu")
    assert code == 2 and "1268603 DEM steps" in err
    code, report, err = _run(capsys, *argv, "--max-dem-steps", "102", "--progress")
    assert code == 0 and report["steps"] == 102
    assert "102/102" in err  # the bar counts DEM steps and reaches its total


def test_biaxial_dem_step_cap(rve64, capsys):
    code, _, err = _run(capsys, "biaxial-dem", str(rve64[0]), "--strain-per-step", "1e-12",
                        "--device", "cpu")
    assert code == 2 and "--max-dem-steps" in err and "1.054e+11" in err


def test_prepare_limits_are_checked_before_work(capsys):
    from granular_material.procedures.packing import min_discs

    assert min_discs() == 12
    code, _, err = _run(capsys, "prepare", "--particles", "8", "--device", "cpu")
    assert code == 2 and "at least 12 discs" in err and "--particles 8" in err
    code, _, err = _run(capsys, "prepare", "--pressure", "1e7", "--device", "cpu")
    assert code == 2 and "--pressure 1e+07" in err and "1.5e+06" in err
    code, _, err = _run(capsys, "prepare", "--pressure", "100", "--device", "cpu")
    assert code == 2 and "--pressure 100 Pa is too low" in err and "at least 750 Pa" in err
    with pytest.raises(ValueError, match="at least 12"):
        prepare_packing(n_disc=11, device="cpu")


def test_highest_pressure_still_prepares(tmp_path, capsys):
    from granular_material.dem import RVEMeta
    from granular_material.procedures.packing import max_pressure

    top = max_pressure(RVEMeta())
    out = tmp_path / "rve.npz"
    code, report, _ = _run(capsys, "prepare", "--particles", "24", "--pressure", f"{top}",
                           "--out", str(out), "--device", "cpu")
    assert code == 0 and report["void_ratio"] > 0 and out.exists()
    assert report["mean_stress"] == pytest.approx(-top, rel=0.02)


def test_linear_elastic_needs_a_confining_pressure(capsys):
    code, _, err = _run(capsys, "single-element", "--material", "linear-elastic",
                        "--confining", "0", "--steps", "2", "--no-progress")
    assert code == 2 and "--confining" in err


def test_biaxial_summary_reports_what_ran(rve64, tmp_path, capsys):
    rve20 = tmp_path / "rve20.npz"
    save_rve(rve20, prepare_packing(n_disc=20, seed=2, device="cpu").to_data())
    code, report, _ = _run(capsys, "biaxial", "--rve", str(rve20), "--elements", "1", "1",
                           "--steps", "1", "--axial-strain", "0.0005", "--device", "cpu",
                           "--no-progress")
    assert code == 0, report["error"]
    assert report["particles"] == 20 and report["scale"] == "custom"
    assert np.isfinite(report["peak_stress_ratio"])


def test_single_element_uses_the_four_rves_of_a_file(rve64, tmp_path):
    from granular_material.runs import MaterialSpec, ProblemSpec, RunSpec, check

    def replicated(**parameters) -> bool:
        spec = RunSpec(problem=ProblemSpec(test="single-element"), device="cpu",
                       material=MaterialSpec(name="dem", parameters=parameters))
        context = check(spec).context
        return spec.material.cls.for_run(spec.material.parameters, context).parameters.replicate

    four = tmp_path / "four.npz"
    save_rve(four, load_rve(rve64[0]).replicate(4))
    assert replicated(rve=four) is False  # one RVE per Gauss point, not RVE 0 four times
    assert replicated(rve=rve64[0]) is True
    assert replicated(independent=True) is False
