"""Comparison metrics of the YADE cross-validation, on synthetic curves with known answers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from granular_material_validation import metrics
from granular_material_validation.engine_runner import voigt_tangent

P0 = 1e5  # confining stress [Pa], as the biaxial test of docs/design.md#yade-anchors


def biaxial_curve(peak: float = 2.9, strain_peak: float = 0.02, shift: float = 0.0,
                  factor: float = 1.0, n: int = 1001) -> pd.DataFrame:
    """σxx = −P0, σyy = −P0·R(ε) with R = 1 + (peak − 1)·(s)·exp(1 − s), s = (ε − shift)/εp.

    R peaks at ε = shift + εp with the value ``peak``; ``factor`` scales σyy.
    """
    eps = np.linspace(0.0, 0.1, n)
    s = np.clip(eps - shift, 0.0, None) / strain_peak
    ratio = 1.0 + (peak - 1.0) * s * np.exp(1.0 - s)
    return pd.DataFrame({"axial_strain": eps, "sxx": -P0 * np.ones(n),
                         "syy": -P0 * ratio * factor, "sxy": np.zeros(n),
                         "volumetric_strain": -0.01 * s * np.exp(1.0 - s),
                         "void_ratio": 0.175 + 0.01 * eps})


def test_principal_stresses_of_a_rotated_tensor() -> None:
    """σ = R·diag(−3, −1)·Rᵀ (tension positive) has σ1 = 3, σ3 = 1 for every rotation."""
    for angle in (0.0, 0.3, 1.2):
        c, s = np.cos(angle), np.sin(angle)
        rot = np.array([[c, -s], [s, c]])
        sig = rot @ np.diag([-3.0, -1.0]) @ rot.T
        s1, s3 = metrics.principal_stresses(sig[0, 0], sig[1, 1], sig[0, 1])
        assert s1 == pytest.approx(3.0) and s3 == pytest.approx(1.0)


def test_stress_ratio_is_nan_without_compression() -> None:
    frame = pd.DataFrame({"sxx": [-2.0, 1.0], "syy": [-1.0, 1.0], "sxy": [0.0, 0.0]})
    ratio = metrics.stress_ratio(frame)
    assert ratio[0] == pytest.approx(2.0)
    assert np.isnan(ratio[1])


def test_identical_curves_pass_with_zero_differences() -> None:
    ref = biaxial_curve()
    c = metrics.compare_curves(ref, ref.copy())
    assert c.peak_ratio_ref == pytest.approx(2.9, rel=1e-4)
    assert c.strain_at_peak_argmax_ref == pytest.approx(0.02, abs=1e-4)
    # the 1 % plateau of R = 1 + 1.9·s·e^(1−s) spans s ∈ [0.878, 1.148]: centre 1.013 εp
    assert c.strain_at_peak_ref == pytest.approx(0.0202, abs=1e-4)
    assert c.stress_scale == pytest.approx(2.9 * P0, rel=1e-4)
    assert c.pre_peak_diff == 0 and c.post_peak_diff == 0 and c.strain_at_peak_diff == 0
    assert c.passed


def test_one_percent_larger_stress_is_one_percent_of_the_peak() -> None:
    """σyy·1.01: the largest pre-peak difference is 1 % of σ1 (at the peak), ratio +1 %."""
    c = metrics.compare_curves(biaxial_curve(), biaxial_curve(factor=1.01))
    assert c.pre_peak_diff == pytest.approx(0.01, rel=1e-6)
    assert c.peak_ratio_diff == pytest.approx(0.01, rel=1e-6)
    assert c.checks() == {"pre_peak": True, "peak_ratio": True, "strain_at_peak": True,
                          "post_peak": True}


def test_three_percent_larger_stress_fails_pre_peak_only() -> None:
    c = metrics.compare_curves(biaxial_curve(), biaxial_curve(factor=1.03))
    assert c.pre_peak_diff == pytest.approx(0.03, rel=1e-6)
    assert c.checks() == {"pre_peak": False, "peak_ratio": True, "strain_at_peak": True,
                          "post_peak": True}
    assert not c.passed


def test_peak_shifted_by_six_tenths_percent_fails_strain_at_peak() -> None:
    c = metrics.compare_curves(biaxial_curve(), biaxial_curve(shift=0.006))
    assert c.strain_at_peak_diff == pytest.approx(0.006, abs=2e-4)
    assert not c.checks()["strain_at_peak"]
    assert c.checks()["peak_ratio"]


def test_post_peak_difference_is_measured_after_the_peak_only() -> None:
    ref = biaxial_curve()
    ours = ref.copy()
    late = ours["axial_strain"] > 0.05
    ours.loc[late, "syy"] -= 0.15 * 2.9 * P0
    c = metrics.compare_curves(ref, ours)
    assert c.pre_peak_diff == 0
    assert c.post_peak_diff == pytest.approx(0.15, rel=1e-3)
    assert c.checks()["pre_peak"] and not c.checks()["post_peak"]


def test_peak_at_end_of_path_has_no_post_peak_part() -> None:
    ref = biaxial_curve(strain_peak=0.2)  # still rising at 10 %
    c = metrics.compare_curves(ref, ref.copy())
    assert not c.peak_inside
    assert np.isnan(c.post_peak_diff)
    assert c.to_dict()["post_peak_diff"] is None and c.passed


def test_ours_is_interpolated_onto_the_reference_grid() -> None:
    """A coarser curve of ours (every 10th row, h = 1e-3) of the same law: only the linear
    interpolation error h²/8·max|σyy''| remains, σyy'' = 1.9·P0·(s − 2)·e^(1−s)/εp² (≤ 2e at s = 0).
    """
    ref = biaxial_curve()
    c = metrics.compare_curves(ref, ref.iloc[::10].reset_index(drop=True))
    bound = (1e-3) ** 2 / 8 * 1.9 * P0 * 2 * np.e / 0.02**2 / (2.9 * P0)
    assert 0.5 * bound < c.pre_peak_diff <= bound * 1.0001
    assert c.post_peak_diff <= bound * 1.0001


def test_find_peak_ignores_a_one_point_spike() -> None:
    eps = np.linspace(0, 0.1, 201)
    ratio = 2.0 + np.sin(np.pi * eps / 0.1)  # smooth peak at 5 %
    ratio[20] = 10.0
    i, _ = metrics.find_peak(eps, ratio, window=5)
    assert eps[i] == pytest.approx(0.05, abs=1e-3)
    i_raw, value = metrics.find_peak(eps, ratio, window=1)
    assert i_raw == 20 and value == 10.0


def test_compare_curves_names_missing_column_and_decreasing_strain() -> None:
    ref = biaxial_curve()
    with pytest.raises(ValueError, match="sxy"):
        metrics.compare_curves(ref, ref.drop(columns="sxy"))
    with pytest.raises(ValueError, match="axial_strain"):
        metrics.compare_curves(ref, ref.iloc[::-1].reset_index(drop=True))


def test_ensemble_mean_averages_on_the_common_range() -> None:
    a = biaxial_curve(factor=1.0)
    b = biaxial_curve(factor=1.1).iloc[:501]  # ends at 5 %
    mean = metrics.ensemble_mean([a, b])
    assert mean["axial_strain"].iloc[-1] == pytest.approx(0.05)
    np.testing.assert_allclose(mean["syy"], 1.05 * a["syy"].iloc[:501], rtol=1e-12)


def test_tangent_difference_and_voigt_of_isotropic_tangent() -> None:
    """Isotropic C = λδijδkl + μ(δikδjl + δilδjk) is [[λ+2μ, λ, 0], [λ, λ+2μ, 0], [0, 0, μ]]."""
    lam, mu = 3.0e7, 1.0e7
    d = np.eye(2)
    c = (lam * np.einsum("ij,kl->ijkl", d, d)
         + mu * (np.einsum("ik,jl->ijkl", d, d) + np.einsum("il,jk->ijkl", d, d)))
    v = voigt_tangent(c)
    np.testing.assert_allclose(v, [[lam + 2 * mu, lam, 0], [lam, lam + 2 * mu, 0], [0, 0, mu]])
    diff = metrics.tangent_difference(v, 1.02 * v)
    assert diff["frobenius"] == pytest.approx(0.02) and diff["max_entry"] == pytest.approx(0.02)
    with pytest.raises(ValueError, match="shape"):
        metrics.tangent_difference(v, v[:2])


def plateau_curve(bump_at: float, n: int = 301) -> pd.DataFrame:
    """σ1/σ3 rising to a flat top 2.9 between 1.5 % and 2.5 % strain, then falling, with a
    bump of +0.3 % (YADE's pure shear: 2.890 at 1.6 % against 2.898 at 2.35 %) at
    ``bump_at``."""
    eps = np.linspace(0.0, 0.03, n)
    ratio = np.interp(eps, [0.0, 0.015, 0.025, 0.03], [1.0, 2.9, 2.9, 2.7])
    ratio = ratio + 0.0087 * np.exp(-(((eps - bump_at) / 0.001) ** 2))
    return pd.DataFrame({"axial_strain": eps, "sxx": -P0 * np.ones(n),
                         "syy": -P0 * ratio, "sxy": np.zeros(n)})


def test_plateau_centre_ignores_where_on_the_plateau_the_largest_value_falls() -> None:
    """Two curves equal but for a 0.3 % bump at 1.6 % or 2.35 %: the largest values lie
    0.75 % strain apart (the former rule fails), the plateaus' centres 0.02 % apart."""
    c = metrics.compare_curves(plateau_curve(0.016), plateau_curve(0.0235))
    assert c.strain_at_peak_argmax_diff == pytest.approx(0.0075, abs=2e-4)
    assert not c.to_dict()["strain_at_peak_argmax_pass"]
    assert c.plateau_ref[0] == pytest.approx(0.0149, abs=2e-4)
    assert c.strain_at_peak_ref == pytest.approx(0.02, abs=5e-4)
    assert c.strain_at_peak_diff <= 5e-4 and c.checks()["strain_at_peak"]


def test_peak_plateau_of_a_sharp_peak_is_the_peak() -> None:
    eps = np.linspace(0.0, 0.04, 401)
    ratio = 3.0 - 100.0 * np.abs(eps - 0.01)  # falls 1 % of 3 within 0.03 % strain
    lo, hi, centre = metrics.peak_plateau(eps, ratio, window=1)
    assert (lo, hi) == (pytest.approx(0.0097), pytest.approx(0.0103))
    assert centre == pytest.approx(0.01)
    with pytest.raises(ValueError, match="tol"):
        metrics.peak_plateau(eps, ratio, tol=1.5)


def test_plateau_centre_lies_between_two_near_equal_humps() -> None:
    """Humps of 2.90 at 1.3 % and 2.895 at 2.35 % with a dip to 2.80 between them: the
    largest value sits on the first hump, the centre between the two (the second, 0.2 %
    lower, weighs a little less)."""
    eps = np.linspace(0.0, 0.03, 301)
    ratio = (2.80 + 0.10 * np.exp(-(((eps - 0.013) / 0.002) ** 2))
             + 0.095 * np.exp(-(((eps - 0.0235) / 0.002) ** 2)))
    ratio = np.where(eps < 0.008, 1.0 + 1.8 * eps / 0.008, ratio)
    lo, hi, centre = metrics.peak_plateau(eps, ratio, window=1)
    assert lo == pytest.approx(0.0118, abs=2e-4) and hi == pytest.approx(0.0246, abs=2e-4)
    assert 0.017 < centre < 0.0182
