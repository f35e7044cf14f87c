"""Calibration of a Mohr–Coulomb material from drained biaxial DEM tests (issue 45): the
reading on curves of known parameters, the point driver, the command end to end on the
64-disc RVE, and its refusals."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import tomllib

import granular_material
from granular_material.cli import main
from granular_material.errors import ParameterError
from granular_material.fem.materials.linear_elastic import LinearElastic
from granular_material.fem.materials.mohr_coulomb import MohrCoulomb
from granular_material.procedures.calibration import (
    calibrate_mohr_coulomb,
    drained_point_curve,
    principal_ratio,
    read_parameters,
)

granular_material.verbose(False)

RVE64 = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "rve64.npz"
P = 100e3
TRUE = {"young": 40e6, "poisson": 0.25, "friction_angle": 34.0, "dilation_angle": 8.0,
        "cohesion": 0.0, "critical_friction_angle": 28.0, "softening_strain": 0.03}


@pytest.fixture(scope="module")
def synthetic() -> pd.DataFrame:
    """The Mohr–Coulomb material of known parameters through the drained path to 8 %."""
    return drained_point_curve(MohrCoulomb(**TRUE, initial_stress=-P), P, 0.08)


def test_point_driver_holds_the_confining_stress_on_an_elastic_solid():
    e, nu = 30e6, 0.2
    curve = drained_point_curve(LinearElastic(e, nu, -P), P, 0.01)
    assert np.allclose(curve["sxx"], -P, rtol=1e-9)
    e1 = -np.log1p(-curve["axial_strain"])
    e3 = -np.log1p(curve["lateral_strain"])
    # plane strain, σ3 held: dσ1 = E/(1 − ν²) dε1, dε3 = −ν/(1 − ν) dε1 (the material
    # sums ∇u increments on the moving cell: logarithmic strains to O(increment))
    assert np.allclose(-curve["syy"] - P, e / (1 - nu**2) * e1, rtol=1e-3, atol=1.0)
    assert np.allclose(e3, -nu / (1 - nu) * e1, rtol=1e-3, atol=1e-9)
    assert curve["iterations"].iloc[1:].max() <= 3  # linear: Newton in one or two


def test_read_parameters_gives_back_the_parameters_of_a_mohr_coulomb_curve(synthetic):
    cal = read_parameters(synthetic, P)
    p = cal.parameters
    assert p["young"] == pytest.approx(TRUE["young"], rel=0.01)
    assert p["poisson"] == pytest.approx(TRUE["poisson"], rel=0.01)
    assert p["friction_angle"] == pytest.approx(TRUE["friction_angle"], abs=0.5)
    assert p["dilation_angle"] == pytest.approx(TRUE["dilation_angle"], abs=0.5)
    assert p["critical_friction_angle"] == pytest.approx(TRUE["critical_friction_angle"], abs=0.5)
    assert p["softening_strain"] == pytest.approx(TRUE["softening_strain"], rel=0.05)
    assert p["cohesion"] == 0.0
    # the peak of a Mohr–Coulomb curve with c = 0 is (1 + sin φ)/(1 − sin φ)
    s = math.sin(math.radians(TRUE["friction_angle"]))
    assert principal_ratio(synthetic).max() == pytest.approx((1 + s) / (1 - s), rel=2e-3)
    # the calibrated material runs and, driven again, gives the same peak
    again = drained_point_curve(MohrCoulomb(**cal.material_keywords()), P, 0.08)
    assert principal_ratio(again).max() == pytest.approx(principal_ratio(synthetic).max(),
                                                         rel=5e-3)


def test_read_parameters_reads_the_scatter_of_several_curves(synthetic):
    stiffer = drained_point_curve(MohrCoulomb(**{**TRUE, "young": 60e6}, initial_stress=-P),
                                  P, 0.08)
    both = pd.concat([synthetic, stiffer.assign(rve=1)], ignore_index=True)
    e = read_parameters(both, P).readings["young"]
    assert e.value == pytest.approx(50e6, rel=0.01)
    assert (e.min, e.max) == pytest.approx((40e6, 60e6), rel=0.01)
    assert e.std == pytest.approx(10e6, rel=0.01)


def test_read_parameters_refuses_what_it_cannot_read(synthetic):
    with pytest.raises(ParameterError) as err:
        read_parameters(synthetic, 0.0)
    assert err.value.field == "pressure"
    with pytest.raises(ParameterError) as err:
        read_parameters(synthetic.drop(columns="syy"), P)
    assert err.value.field == "curve"
    with pytest.raises(ParameterError) as err:  # one record in the elastic window
        read_parameters(synthetic, P, elastic_window=1e-5)
    assert err.value.field == "elastic_window"
    elastic = drained_point_curve(LinearElastic(30e6, 0.2, -P), P, 0.01)
    with pytest.raises(ParameterError) as err:  # no plastic flow: no ψ
        read_parameters(elastic, P)
    assert err.value.field == "dilatancy_window"


def test_calibrate_end_to_end_on_the_64_disc_rve(tmp_path):
    out = tmp_path / "cal"
    code = main(["calibrate", str(RVE64), "--confining", "100e3", "--axial-strain", "0.03",
                 "--out", str(out), "--device", "cpu", "--no-progress", "--json"])
    assert code == 0
    for name in ("mohr-coulomb.toml", "calibration.json", "calibration.csv",
                 "mohr-coulomb.csv", "calibration.png"):
        assert (out / name).stat().st_size > 0, name
    params = tomllib.loads((out / "mohr-coulomb.toml").read_text(encoding="utf-8"))
    # the DEM peak of this RVE: σ1/σ3 ≈ 3.3 (principal) → φ ≈ 32.5°
    assert 27.0 < params["friction_angle"] < 37.0
    assert 0.0 <= params["dilation_angle"] <= params["friction_angle"]
    assert 5e6 < params["young"] < 1e8 and 0.0 < params["poisson"] < 0.5
    # the material file loads back: the run parameters, then the material itself
    run = MohrCoulomb.Parameters(**params)
    material = MohrCoulomb(young=run.young, poisson=run.poisson,
                           friction_angle=run.friction_angle,
                           dilation_angle=run.dilation_angle, cohesion=run.cohesion,
                           critical_friction_angle=run.critical_friction_angle,
                           softening_strain=run.softening_strain, initial_stress=-P)
    material.allocate(1)
    assert material.evaluate(np.zeros((1, 2, 2))).ok
    report = json.loads((out / "calibration.json").read_text(encoding="utf-8"))
    assert report["readings"]["friction_angle"]["value"] == pytest.approx(params["friction_angle"])
    assert report["pressure"] == P and report["settings"]["rves"] == 1
    curve = pd.read_csv(out / "calibration.csv")
    assert curve["axial_strain"].max() == pytest.approx(0.03, rel=1e-6)


def test_calibrate_reconsolidates_an_rve_at_another_pressure():
    cal = calibrate_mohr_coulomb(RVE64, 200e3, axial_strain=0.005, device="cpu",
                                 dilatancy_window=0.004)
    assert any("re-consolidated" in note for note in cal.notes)
    first = cal.curve[cal.curve["step"] == 0]
    assert np.allclose(first[["sxx", "syy"]].to_numpy(), -200e3, rtol=0.02)


@pytest.mark.parametrize("argv, words", [
    (["--confining", "0"], "--confining"),
    (["--confining", "-5e3"], "--confining"),
])
def test_calibrate_refuses_a_pressure_that_is_not_positive(tmp_path, capsys, argv, words):
    out = tmp_path / "cal"
    with pytest.raises(SystemExit) as exit_:
        main(["calibrate", str(RVE64), *argv, "--out", str(out)])
    assert exit_.value.code == 2
    assert words in capsys.readouterr().err
    assert not out.exists()


def test_calibrate_refuses_a_missing_file_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "cal"
    code = main(["calibrate", str(tmp_path / "none.npz"), "--confining", "1e5",
                 "--out", str(out)])
    assert code == 2
    assert "none.npz does not exist" in capsys.readouterr().err
    assert not out.exists()
    with pytest.raises(ParameterError) as err:
        calibrate_mohr_coulomb(tmp_path / "none.npz", P)
    assert err.value.field == "rve"


def test_calibrate_refuses_an_rve_file_of_no_rves_and_bad_settings(tmp_path, capsys):
    with np.load(RVE64) as data:
        empty = {k: (v[:0] if v.ndim else v) for k, v in data.items()}
    path = tmp_path / "empty.npz"
    np.savez(path, **empty)
    out = tmp_path / "cal"
    assert main(["calibrate", str(path), "--confining", "1e5", "--out", str(out)]) == 2
    assert "B=0" in capsys.readouterr().err and not out.exists()
    assert main(["calibrate", str(RVE64), "--confining", "1e5", "--rves", "2",
                 "--out", str(out)]) == 2
    assert "--rves 2" in capsys.readouterr().err and not out.exists()
    for kwargs, field in (({"confining": -1.0}, "confining"),
                          ({"confining": math.nan}, "confining"),
                          ({"confining": P, "axial_strain": 0.95}, "axial_strain"),
                          ({"confining": P, "rves": 0}, "rves")):
        with pytest.raises(ParameterError) as err:
            calibrate_mohr_coulomb(RVE64, **kwargs)
        assert err.value.field == field
