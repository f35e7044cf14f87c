"""benchmarks/material_comparison.py: its measures (material_comparison_measures.py), and its
stages at smoke size."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from run_helpers import benchmark_module

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

mc = benchmark_module("material_comparison")
measures = benchmark_module("material_comparison_measures")


def test_prandtl_nq_closed_form() -> None:
    """N_q(0) = 1; N_q(30°) = 18.40 (the textbook value); it grows with φ."""
    assert measures.prandtl_nq(0.0) == pytest.approx(1.0)
    assert measures.prandtl_nq(30.0) == pytest.approx(18.401, abs=1e-3)
    assert measures.prandtl_nq(40.0) == pytest.approx(64.195, abs=1e-3)
    assert measures.prandtl_nq(35.8) > measures.prandtl_nq(22.4)


def test_band_angles() -> None:
    """Coulomb, Roscoe and Arthur for φ = 30°, ψ = 10°; Arthur is their mean."""
    a = measures.band_angles(30.0, 10.0)
    assert a == {"coulomb": 60.0, "roscoe": 50.0, "arthur": 55.0}


def _points(gamma_by_step: list[list[float]]) -> pd.DataFrame:
    rows = []
    for step, gammas in enumerate(gamma_by_step):
        for p, g in enumerate(gammas):
            rows.append({"step": step, "axial_strain": 0.01 * step, "point": p,
                         "x": float(p), "y": 0.0, "shear_strain": g})
    return pd.DataFrame(rows)


def test_localisation_series_and_onset() -> None:
    """A uniform field stays at γmax/γmean = 1 (never localised); one point running away
    reaches the threshold at the step it first does."""
    uniform = measures.localisation_series(_points([[0, 0, 0, 0], [1, 1, 1, 1], [2, 2, 2, 2]]))
    np.testing.assert_allclose(uniform["ratio"], 1.0)
    assert measures.onset_strain(uniform) is None
    growing = measures.localisation_series(_points([[0, 0, 0, 0], [1, 1, 1, 1.5], [1, 1, 1, 5]]))
    np.testing.assert_allclose(growing["ratio"], [1.0, 1.5 / 1.125, 5 / 2])
    assert measures.onset_strain(growing) == pytest.approx(0.02)
    assert measures.onset_strain(growing, threshold=1.3) == pytest.approx(0.01)


def test_quadrant_angles_of_an_x() -> None:
    """An X of two bands at ±60° through the centre of a grid: every quadrant reads its
    arm at 60° (to 2°), where one axis for the whole grid would read neither."""
    x, y = np.meshgrid(np.linspace(-1, 1, 41), np.linspace(-2, 2, 81))
    x, y = x.ravel(), y.ravel()
    t = math.tan(math.radians(60))
    d = np.minimum(np.abs(y - t * x), np.abs(y + t * x)) / math.hypot(1, t)
    points = pd.DataFrame({"step": 3, "axial_strain": 0.05, "x": x, "y": y,
                           "shear_strain": np.exp(-(d / 0.05) ** 2)})
    angles = measures.quadrant_angles(points, 3, fraction=0.1)
    assert len(angles) == 4
    np.testing.assert_allclose(angles, 60.0, atol=2.0)


def test_bearing_curve() -> None:
    """Bearing pressure −F_y/B [Pa] of the half footing; the settlement as written."""
    steps = pd.DataFrame({"footing_settlement": [0.0, 1e-3],
                          "footing_force_y": [-1000.0, -5000.0]})
    c = measures.bearing_curve(steps, 0.05)
    np.testing.assert_allclose(c["pressure"], [20e3, 100e3])
    np.testing.assert_allclose(c["settlement"], [0.0, 1e-3])


def test_scene_with_swaps_the_material_only() -> None:
    """The footing scene with its material replaced: every other table kept, the new
    material's parameters as written, overrides on their lines; an unknown key refused."""
    text = mc.FOOTING_SCENE.read_text(encoding="utf-8")
    params = {"young": 19e6, "poisson": 0.25, "friction_angle": 35.8, "dilation_angle": 16.8,
              "cohesion": 0.0}
    out = tomllib.loads(mc.scene_with(text, "mohr-coulomb", params,
                                      {"steps": "3", "elements": "[4, 3]"}))
    base = tomllib.loads(text)
    assert out["material"] == {"name": "mohr-coulomb", "parameters": params}
    assert out["steps"] == 3 and out["mesh"]["elements"] == [4, 3]
    for key in ("boundaries", "conditions", "initial", "output"):
        assert out[key] == base[key]
    assert out["mesh"]["grading"] == base["mesh"]["grading"]
    with pytest.raises(KeyError, match="nonsense"):
        mc.scene_with(text, "dem", {}, {"nonsense": "1"})


def test_footing_variants() -> None:
    """As calibrated (softening kept), perfectly plastic at φ, and at φcs with ψ ≤ φcs."""
    p = {"young": 19e6, "poisson": 0.25, "friction_angle": 35.8, "dilation_angle": 16.8,
         "cohesion": 0.0, "critical_friction_angle": 12.0,
         "softening_strain": 0.04}
    v = mc.footing_variants(p)
    assert v["mc"] == p
    assert "critical_friction_angle" not in v["mc-peak"]
    assert v["mc-peak"]["friction_angle"] == 35.8
    assert v["mc-cs"]["friction_angle"] == 12.0 and v["mc-cs"]["dilation_angle"] == 12.0
    assert "softening_strain" not in v["mc-cs"]


def test_calibrate_and_element_stages_smoke(tmp_path: Path) -> None:
    """Two 16-disc RVEs calibrated at 100 and 20 kPa; their single elements and the
    calibrated Mohr–Coulomb one; the report of what ran (the rest left out)."""
    results = mc.main(["--smoke", "--repeats", "1", "--out", str(tmp_path),
                       "--stages", "calibrate", "element", "report"])
    material = tomllib.loads((tmp_path / "calibration-100k" / "mohr-coulomb.toml")
                             .read_text(encoding="utf-8"))
    assert 0 < material["friction_angle"] < 60 and material["young"] > 0
    element = results["element"]
    assert len(element["dem"]) == 2
    # the calibrated element (c = 0, σyy/σxx on the axes) peaks between the closed forms
    # of φ and of φcs: φ softens from the first plastic step on
    def ratio(phi: float) -> float:
        s = math.sin(math.radians(phi))
        return (1 + s) / (1 - s)

    low = ratio(material.get("critical_friction_angle", material["friction_angle"]))
    high = ratio(material["friction_angle"])
    assert low * (1 - 1e-6) <= element["mc"]["peak_ratio"] <= high * (1 + 1e-6)
    assert all(d["peak_ratio"] > 1.2 and d["iterations"] >= 1 for d in element["dem"])
    costs = json.loads((tmp_path / "costs.json").read_text())
    assert costs["element-mc"]["run_median_s"] > 0
    assert (tmp_path / "element.png").is_file()
    report = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert "| Mohr–Coulomb |" in report and "gz20k" in report


@pytest.mark.slow
def test_every_stage_smoke(tmp_path: Path) -> None:
    """Every stage at smoke size (a few minutes on a shared 2-core machine)."""
    results = mc.main(["--smoke", "--repeats", "1", "--out", str(tmp_path)])
    assert {"dem", "mc", "dem-rough", "mc-rough"} <= set(results["specimen"])
    assert {"dem", "mc", "mc-peak", "mc-cs"} <= set(results["footing"])
    for name in ("element.png", "specimen.png", "specimen_maps.png", "footing.png",
                 "footing_maps.png", "results.json"):
        assert (tmp_path / name).is_file()
