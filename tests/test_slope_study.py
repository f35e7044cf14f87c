"""benchmarks/slope_study.py at smoke size: the homogeneous embankment's strength reduction
runs to a collapse near Bishop's factor, and the report is written from what ran."""

from __future__ import annotations

import json

import pytest
from run_helpers import benchmark_module

study = benchmark_module("slope_study")


def test_the_smoke_study_finds_bishops_factor_and_reports_it(tmp_path) -> None:
    results = study.main(["--smoke", "--out", str(tmp_path)])
    [row] = results["runs"]
    assert row["method"] == "strength-reduction" and row["stopped_by"] == "collapse"
    bishop = results["bishop"]["homogeneous"]["factor_of_safety"]
    assert bishop == pytest.approx(1.143, abs=0.005)
    assert row["value"] == pytest.approx(bishop, rel=0.03)
    report = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert f"{row['value']:.3f}" in report and f"{bishop:.3f}" in report
    assert json.loads((tmp_path / "results.json").read_text(encoding="utf-8")) == results
    assert (tmp_path / "slope_paths.png").stat().st_size > 0


def test_a_gravity_scene_is_the_slope_without_its_reduction() -> None:
    text = study.scene_text("two-layer", "gravity-arc-length", 12)
    assert "[strength_reduction]" not in text
    assert 'continuation = "arc-length"' in text and "max_cutbacks = 12" in text
    assert "factor = [0.0, 3.0]" in text
