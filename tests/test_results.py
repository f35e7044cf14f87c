"""Results floor: the one peak finder, the commands' Newton defaults, the run writer."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from granular_material.fem import (
    BiaxialSetup,
    LinearElastic,
    NewtonSettings,
    default_settings,
    default_stress_tol,
)
from granular_material.results import BiaxialWriter, find_peak, read_points, summarize_biaxial
from granular_material.runs import run_biaxial


def test_find_peak_with_window_one_is_the_largest_value_nans_skipped():
    ratio = np.array([1.0, np.nan, 2.5, 2.4, 2.5001, 1.0])
    assert find_peak(np.arange(6.0), ratio) == (4, 2.5001)
    assert find_peak(np.arange(3.0), np.full(3, np.nan))[0] == -1
    with pytest.raises(ValueError, match="lengths"):
        find_peak(np.arange(3.0), ratio)


def test_summarize_biaxial_takes_the_first_largest_ratio():
    curve = pd.DataFrame({"axial_strain": [0.0, 0.01, 0.02, 0.03],
                          "stress_ratio": [1.0, 2.9, 2.9, 2.5],
                          "volumetric_strain": [0.0, -0.004, -0.001, 0.002],
                          "void_ratio": [0.18, 0.17, 0.18, 0.19]})
    s = summarize_biaxial(curve)
    assert (s.peak_stress_ratio, s.axial_strain_at_peak) == (2.9, 0.01)
    assert (s.max_contraction, s.final_void_ratio) == (-0.004, 0.19)


def test_default_settings_are_the_commands_and_depend_on_the_material_by_name():
    dem, elastic = default_settings("dem"), default_settings("linear-elastic")
    for s in (dem, elastic):  # Guo & Zhao's loop in finite strain, our predictor
        assert s.predictor == "extrapolate"
        assert s.max_iterations == 100
        assert s.formulation == "updated-lagrangian"
    # DEM: their test judged one iterate earlier; a smooth material: the force residual
    assert (dem.convergence, dem.rtol) == ("residual-displacement", 0.01)
    assert (elastic.convergence, elastic.rtol) == ("force", 1e-4)
    assert default_settings("mohr-coulomb").convergence == "force"
    assert default_settings("linear-elastic", convergence="displacement").convergence == (
        "displacement")
    # a noisy material's increments hold their first tangent and are Aitken-relaxed; a
    # smooth one keeps full Newton; either can be asked for the other's
    assert (dem.relaxation, dem.tangent_update) == ("aitken", "hold")
    assert (elastic.relaxation, elastic.tangent_update) == ("none", "none")
    plain = default_settings("dem", relaxation="none", tangent_update="none")
    assert (plain.relaxation, plain.tangent_update) == ("none", "none")
    # Broyden updates come without Aitken (the two fight) unless it is asked for
    assert default_settings("dem", tangent_update="secant").relaxation == "none"
    assert default_settings("dem", tangent_update="secant",
                            relaxation="aitken").relaxation == "aitken"
    assert dem.accept_correction == 0.01 and elastic.accept_correction == 0.0
    assert dem.stall_rtol == 2 * dem.rtol and elastic.stall_rtol == 0.0
    assert default_settings("dem", rtol=0.01).stall_rtol == 0.02
    assert default_settings("dem", stall_rtol=None, predictor="tangent").predictor == "tangent"
    assert default_stress_tol("dem", 100e3) == 500.0
    assert default_stress_tol("linear-elastic", 100e3) == 0.0
    # the library's own defaults stay plain Newton
    assert (NewtonSettings().predictor, NewtonSettings().relaxation) == ("tangent", "none")


def test_biaxial_writer_tables_equal_the_result_and_the_fields_file_is_closed(tmp_path):
    with BiaxialWriter(tmp_path) as writer:
        result = run_biaxial(BiaxialSetup(nx=1, ny=2), LinearElastic(young=30e6, poisson=0.3),
                             3, observer=writer)
    steps = pd.read_csv(tmp_path / "steps.csv")
    assert steps["step"].tolist() == [0, 1, 2, 3] and "dem_steps" in steps.columns
    assert len(read_points(tmp_path)) == len(result.points) == 4 * 8
    text = (tmp_path / "fields.xdmf").read_text()
    assert text.rstrip().endswith("</Xdmf>") and text.count("<Time ") == 4
