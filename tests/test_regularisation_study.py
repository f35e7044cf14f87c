"""benchmarks/regularisation_study.py at smoke size: every stage runs, regularised and not,
and the report is written from what ran."""

from __future__ import annotations

import json
import sys

import pytest
from run_helpers import benchmark_module

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

study = benchmark_module("regularisation_study")


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    out = tmp_path_factory.mktemp("regularisation")
    return study.main(["--smoke", "--out", str(out)]), out


def test_every_stage_ran_with_and_without_the_second_gradient(smoke):
    results, out = smoke
    for stage in ("specimen", "dem", "footing"):
        rows = results[stage]
        assert {r["internal_length"] for r in rows} >= {0.0}, stage
        assert any(r["internal_length"] > 0 for r in rows), stage
        for r in rows:
            assert r["error"] in (None, ""), (stage, r)
            assert r["steps_completed"] >= 2
    regularised = [r for r in results["specimen"] if r["internal_length"] > 0]
    assert all(r["iterations"] > 0 and r["time_s"] > 0 for r in regularised)
    saved = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert saved["specimen"] == json.loads(json.dumps(results["specimen"], default=str))


def test_the_report_and_figures_are_written(smoke):
    _, out = smoke
    report = (out / "report.md").read_text(encoding="utf-8")
    for heading in ("Mohr–Coulomb softening specimen", "FEM × DEM specimen", "Footing"):
        assert f"## {heading}" in report
    for figure in ("specimen_curves.png", "specimen_maps.png", "band_width.png",
                   "specimen_active_maps.png", "dem_ratios.png", "footing_curves.png"):
        assert (out / figure).stat().st_size > 10_000, figure


def test_the_footing_scenes_carry_the_regularisation_and_the_calibrated_twin():
    text = study.FOOTING_SCENE.read_text(encoding="utf-8")
    scene = tomllib.loads(study.footing_scene(text, (6, 4), 0.01, study.FULL,
                                              study._calibrated()))
    assert scene["mesh"]["elements"] == [6, 4]
    assert scene["regularisation"] == {"model": "second-gradient", "internal_length": 0.01}
    assert scene["material"]["name"] == "mohr-coulomb"
    assert scene["material"]["parameters"]["critical_friction_angle"] < scene["material"][
        "parameters"]["friction_angle"]
    assert scene["newton"]["formulation"] == "small-strain"
    plain = tomllib.loads(study.footing_scene(text, (12, 8), 0.0, study.FULL, None))
    assert "regularisation" not in plain and plain["material"]["name"] == "dem"
