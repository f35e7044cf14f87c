"""benchmarks/adaptivity_study.py at smoke size: the footing all-DEM and adaptive, measured
against each other, and the report written from what ran."""

from __future__ import annotations

import json

from run_helpers import benchmark_module

study = benchmark_module("adaptivity_study")


def test_the_smoke_study_measures_the_adaptive_footing_against_all_dem(tmp_path) -> None:
    results = study.main(["--smoke", "--out", str(tmp_path)])
    rows = results["footing"]
    reference, adaptive = rows["all-DEM"], rows["f=0.7"]
    assert reference["largest_error_to_peak"] == 0.0 and reference["cost_ratio"] == 1.0
    assert 0 < adaptive["dem_points"][-1] < adaptive["gauss_points"]
    assert adaptive["dem_points"][0] == 0
    assert 0 < adaptive["cost_ratio"] < 1  # the twin's points ran no DEM
    assert adaptive["switch_particle_steps"] > 0
    assert adaptive["twin"]["parameters"]["friction_angle"] > 0
    report = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert f"{adaptive['cost_ratio']:.3f}" in report
    assert json.loads((tmp_path / "results.json").read_text(encoding="utf-8")) == results
    assert (tmp_path / "adaptivity.png").stat().st_size > 0


def test_a_variant_is_the_scene_with_its_adaptivity_table() -> None:
    text = study.scene_text("footing", "f=0.7, point")
    assert text.endswith('[adaptivity]\nmobilised_fraction = 0.7\nneighbours = "point"\n')
    assert "[adaptivity]" not in study.scene_text("wall-passive", "all-DEM")


def test_a_stopped_full_size_run_is_measured_against_the_committed_table() -> None:
    import pandas as pd

    reference = pd.read_csv(study.STUDIED["footing-full"]["reference"])
    stopped = reference.iloc[:9].copy()  # to 2 mm, before the reference's peak
    stopped["footing_force_y"] *= 1.02
    stopped["particle_steps"] //= 4
    row = study.measure_steps(stopped, {"error": None, "gauss_points": 7500}, "run",
                              "footing-full", reference)
    assert row["steps"] == 8 and not row["reached_peak"] and row["peak_step"] == 23
    assert abs(row["largest_error_to_peak"] - 0.02) < 1e-9
    assert row["window_steps"] == 5 and abs(row["largest_error_in_window"] - 0.02) < 1e-9
    assert abs(row["cost_ratio"] - 0.25) < 1e-3
