"""Box rules of the pore spectrum: boxes in pixels, the physical rule, fit errors, and a
cross-check of the box counts against PoreSpy (skipped where it is not installed)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from granular_material_pore_fractal import (
    analyse_rve,
    box_masses_px,
    multifractal_spectrum,
    physical_boxes,
)
from scipy import stats
from test_pore_fractal_rve import as_rve_data, random_packing
from test_pore_fractal_spectrum import WEIGHT_SETS, cascade

from granular_material.cli import main
from granular_material.dem.rve.file import save_rve

TOL = 1e-8


def dyadic(n: int, levels: range) -> list[int]:
    """Box sides in pixels n/2ᵏ of the levels k, as the physical rule's ``box_px``."""
    return [n >> k for k in levels]


def analytic_images() -> dict[str, np.ndarray]:
    y, x = np.mgrid[:256, :256]
    row = np.zeros((256, 256))
    row[77] = 1.0
    return {"uniform": np.ones((256, 256)), "row": row, "gasket": (x & y) == 0,
            **{f"cascade{i}": cascade(w, 8) for i, w in enumerate(WEIGHT_SETS)}}


@pytest.mark.parametrize("name", list(analytic_images()))
def test_boxes_in_pixels_give_the_closed_forms_of_the_levels(name):
    # the analytic checks of docs/design.md#multifractal under boxes given in pixels: the same
    # boxes as k = 1…8, so the same spectrum (the closed forms are checked on k in the other file)
    image = analytic_images()[name]
    by_level = multifractal_spectrum(image)
    by_pixels = multifractal_spectrum(image, box_px=dyadic(256, range(1, 9)))
    np.testing.assert_array_equal(by_pixels.box_px, by_level.box_px)
    for field in ("alpha", "f", "tau", "Dq", "r2", "se_alpha", "se_f", "Dq_se"):
        np.testing.assert_allclose(getattr(by_pixels, field), getattr(by_level, field),
                                   rtol=0, atol=1e-12, err_msg=field)
    expected = {"uniform": 2.0, "row": 1.0, "gasket": np.log2(3.0)}.get(name)
    if expected is not None:
        np.testing.assert_allclose(by_pixels.Dq, expected, atol=TOL)
        assert by_pixels.D0_se == pytest.approx(0.0, abs=TOL)


def test_uniform_image_is_two_with_sides_that_are_not_powers_of_two():
    # 3, 5, 8 and 15 px divide 240 = 2⁴·3·5, an image no power of two divides fully
    result = multifractal_spectrum(np.ones((240, 240)), box_px=[3, 5, 8, 15])
    np.testing.assert_allclose(result.Dq, 2.0, atol=TOL)
    np.testing.assert_allclose(result.f, 2.0, atol=TOL)
    # a side that does not divide the image: whole boxes only, the rest left out, no padding
    masses = box_masses_px(np.arange(100.0).reshape(10, 10), 3)
    assert masses.shape == (3, 3)
    assert masses[0, 0] == 0 + 1 + 2 + 10 + 11 + 12 + 20 + 21 + 22
    # … and the covered part stands for the whole image: still exactly 2 (without the
    # scaling, 256 = 2·100 + 56 would count 4 boxes of 100 px where the image holds 6.6)
    result = multifractal_spectrum(np.ones((256, 256)), box_px=[7, 11, 30, 100])
    np.testing.assert_allclose(result.Dq, 2.0, atol=TOL)
    np.testing.assert_allclose(result.alpha, 2.0, atol=TOL)
    np.testing.assert_allclose(result.f, 2.0, atol=TOL)
    # mass only in the strip that boxes of 40 px leave out (80 = 2·40 of 100 px)
    stray = np.zeros((100, 100))
    stray[85, 5] = 1.0
    with pytest.raises(ValueError, match="every box size covers"):
        multifractal_spectrum(stray, box_px=[40, 50])
    with pytest.raises(ValueError, match="smaller than the largest box"):
        multifractal_spectrum(np.ones((30, 30)), box_px=[8, 40])


def test_standard_errors_are_those_of_the_least_squares_slope():
    rng = np.random.default_rng(3)
    image = rng.random((240, 240)) ** 4  # a rough measure whose log-moments bend
    sides = [2, 3, 4, 6, 8, 12, 24]
    result = multifractal_spectrum(image, q=[-2.0, 0.0, 3.0], box_px=sides)
    # τ(q) against ln ε, by scipy, from the partition sums over the same boxes
    log_eps = np.log(sides)
    for i, q in enumerate((-2.0, 0.0, 3.0)):
        z = [np.log(((box_masses_px(image, b) / box_masses_px(image, b).sum()) ** q).sum())
             for b in sides]
        fit = stats.linregress(log_eps, z)
        assert result.tau[i] == pytest.approx(fit.slope, rel=1e-10)
        assert result.r2_tau[i] == pytest.approx(fit.rvalue**2, rel=1e-10)
        if q != 1.0:
            assert result.Dq_se[i] == pytest.approx(fit.stderr / abs(q - 1.0), rel=1e-8)
    assert result.D0_se == pytest.approx(result.Dq_se[1], rel=1e-12)
    assert result.D0_se > 0 and result.alpha0_se > 0
    assert result.alpha0_over_D0_se > 0


def test_min_fill_drops_boxes_holding_a_sliver():
    # pores fill the left half; one stray pore pixel sits in the right half. Boxes of
    # 16–64 px hold that pixel as under 1 % of their area: with min_fill they are empty
    # and the set is a filled half plane (D = 2); without, the stray boxes lower D0
    image = np.zeros((256, 256))
    image[:, :128] = 1.0
    image[200, 200] = 1.0
    kept = multifractal_spectrum(image, box_px=[16, 32, 64])
    dropped = multifractal_spectrum(image, box_px=[16, 32, 64], min_fill=0.01)
    assert dropped.D0 == pytest.approx(2.0, abs=TOL)
    assert kept.D0 < 2.0 - 1e-3
    with pytest.raises(ValueError, match="min_fill"):
        multifractal_spectrum(image, box_px=[16, 32], min_fill=1.5)


def test_physical_boxes_are_the_same_lengths_at_every_pixel():
    coarse = physical_boxes(0.3e-3, 650)
    fine = physical_boxes(0.15e-3, 1300)
    assert np.abs(fine - 2 * coarse).max() <= 1  # the same lengths, to the pixel
    assert coarse[0] == 128 and coarse[-1] == 8 and coarse.size == 9  # 2.4–38.4 mm, √2
    # capped at half the window: a small cell keeps the same smallest box
    small = physical_boxes(0.3e-3, 150)
    assert small[-1] == 8 and small[0] <= 75
    with pytest.raises(ValueError, match="at least 2 pixels"):
        physical_boxes(2e-3, 100)
    with pytest.raises(ValueError, match="fewer than two"):
        physical_boxes(0.3e-3, 20)


@pytest.fixture(scope="module")
def dense_packing():
    """400 discs at porosity 0.2 (the DEM's is 0.15 at e0 = 0.18, too dense for this
    test packing to separate quickly), seed 11."""
    return as_rve_data(*(a[None] for a in random_packing(400, 0.2, seed=11)))


def test_physical_rule_holds_the_indices_across_resolutions(dense_packing):
    # issue 29: under the physical rule D0 and α0/D0 move by under 0.5 % from 0.3 to 0.15 mm
    # pixels (measured 0.24 % and 0.07 % here); under the cell rule, whose finest box is a
    # few pixels, they move more (0.8 % and 1.5 %)
    out = {}
    for rule in ("cell", "physical"):
        for pixel in (0.3e-3, 0.15e-3):
            _, spec = analyse_rve(dense_packing, 0, pixel, box_rule=rule)
            out[rule, pixel] = np.array([spec.D0, spec.alpha0_over_D0])
    change = {rule: np.abs(out[rule, 0.15e-3] / out[rule, 0.3e-3] - 1.0)
              for rule in ("cell", "physical")}
    assert np.all(change["physical"] < 0.005), change
    assert np.all(change["cell"] > 0.005), change


def test_cli_physical_rule_reports_the_fit_range_and_explains_poor_fits(
        dense_packing, tmp_path, capsys):
    path = tmp_path / "rve.npz"
    save_rve(path, dense_packing)
    assert main(["fractal", str(path), "--box-rule", "physical", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    _, spec = analyse_rve(dense_packing, 0, 0.3e-3, box_rule="physical")
    assert out["box_rule"] == "physical"
    assert out["D0"] == pytest.approx(float(spec.D0), rel=1e-15)
    assert out["box_min_px"] == 8 and out["box_max_px"] == 128
    assert out["box_min_m"] == pytest.approx(2.4e-3, rel=0.02)
    assert out["D0_se"] == pytest.approx(float(spec.D0_se), rel=1e-15)
    assert 0 < out["r2_q0"] <= 1
    assert main(["fractal", str(path), "--min-r2", "0.999999"]) == 0
    text = capsys.readouterr().out
    assert "poor fits" in text and "meaning" in text and "--box-rule physical" in text
    assert main(["fractal", str(path), "--box-rule", "physical", "--pixel", "2e-3"]) == 2
    assert "at least 2 pixels" in capsys.readouterr().err


def test_cli_physical_rule_says_curved_orders_are_the_packings_own(
        dense_packing, tmp_path, capsys):
    """Under --box-rule physical the advice to take it is not repeated; the flagged orders
    are printed as runs (q = -10 to -1, ...), not one by one."""
    path = tmp_path / "rve.npz"
    save_rve(path, dense_packing)
    _, spec = analyse_rve(dense_packing, 0, 0.3e-3, box_rule="physical")
    min_r2 = float(spec.r2[spec.q == 0][0]) - 1e-9  # q = 0 passes, orders that bend more fail
    assert main(["fractal", str(path), "--box-rule", "physical", "--min-r2", f"{min_r2!r}"]) == 0
    text = capsys.readouterr().out
    poor = spec.q[spec.r2 < min_r2]
    assert poor.size > 2 and "poor fits" in text
    assert "expected for a disc packing" in text and "add --box-rule" not in text
    assert f"q = {poor[0]:g} to " in text


# -- cross-check against PoreSpy (PMEAL), an optional extra: pip install '.[crosscheck]' --


def _porespy():
    return pytest.importorskip(
        "porespy", reason="PoreSpy is not installed (pip install '.[crosscheck]'): the "
                          "cross-check of the box counts against porespy.metrics.boxcount "
                          "is skipped")


def occupied_counts_by_porespy(image: np.ndarray, sides: list[int]) -> np.ndarray:
    """Boxes of each side holding any True pixel, counted by ``porespy.metrics.boxcount``.

    PoreSpy counts the boxes that hold both phases. Each pixel becomes a 2 × 2 block whose
    only possibly True pixel is one corner, so no box of the doubled image is all True and
    PoreSpy's count at 2b is the number of boxes of b pixels holding any True pixel.
    """
    porespy = _porespy()
    doubled = np.kron(image.astype(bool), np.array([[1, 0], [0, 0]], dtype=bool))
    result = porespy.metrics.boxcount(doubled, bins=[2 * b for b in sides])
    return np.asarray(result.count, dtype=np.float64)


@pytest.mark.parametrize("which", ["gasket", "packing"])
def test_box_counts_and_d0_agree_with_porespy(which, dense_packing):
    porespy = _porespy()
    sides = [8, 16, 32, 64]
    if which == "gasket":
        y, x = np.mgrid[:512, :512]
        image = (x & y) == 0
    else:
        image = analyse_rve(dense_packing, 0, 0.3e-3, box_rule="physical")[0].pore
        image = image[:640, :640]  # a multiple of every side: the two tilings are the same
    # PoreSpy's own count (boxes holding both phases) against ours from the box masses
    ours_mixed = [int(np.count_nonzero((m > 0) & (m < b * b)))
                  for b in sides for m in [box_masses_px(image.astype(float), b)]]
    theirs_mixed = porespy.metrics.boxcount(image, bins=sides).count
    assert list(map(int, theirs_mixed)) == ours_mixed
    # D0: the slope of the occupied-box counts, PoreSpy's against our spectrum's
    counts = occupied_counts_by_porespy(image, sides)
    d0_porespy = -stats.linregress(np.log(sides), np.log(counts)).slope
    spec = multifractal_spectrum(image, q=[0.0], box_px=sides)
    assert spec.D0 == pytest.approx(d0_porespy, abs=1e-12)
    if which == "gasket":
        assert d0_porespy == pytest.approx(np.log2(3.0), abs=1e-12)
