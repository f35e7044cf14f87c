"""Multifractal spectrum against closed forms (docs/design.md#multifractal) and its invariants."""

from __future__ import annotations

import numpy as np
import pytest
from granular_material_pore_fractal import DEFAULT_Q, box_masses, multifractal_spectrum

TOL = 1e-8  # the tolerance for closed-form spectra


def cascade(weights: tuple[float, float, float, float], levels: int) -> np.ndarray:
    """Deterministic 2D multiplicative cascade on 2^levels × 2^levels pixels (sum 1)."""
    cell = np.asarray(weights, dtype=np.float64).reshape(2, 2)
    measure = np.ones((1, 1))
    for _ in range(levels):
        measure = np.kron(measure, cell)
    return measure


def cascade_closed_form(weights, q: np.ndarray) -> dict[str, np.ndarray]:
    """docs/design.md#multifractal: τ = −log₂ Σ p_jᑫ, α = −Σ p_jᑫ log₂ p_j / Σ p_jᑫ,
    f = qα − τ, D_q = τ/(q−1); sums over the non-zero weights only (empty boxes are excluded
    for every q)."""
    p = np.asarray([w for w in weights if w > 0], dtype=np.float64)
    # log domain: p_jᑫ = exp(q ln p_j), scaled by its largest term
    log_w = q[:, None] * np.log(p)[None, :]
    peak = log_w.max(axis=1, keepdims=True)
    w = np.exp(log_w - peak)
    log2_sum = (np.log(w.sum(axis=1)) + peak[:, 0]) / np.log(2.0)
    tau = -log2_sum
    alpha = -(w * np.log2(p)).sum(axis=1) / w.sum(axis=1)
    f = q * alpha - tau
    one = np.isclose(q, 1.0)
    dq = np.where(one, alpha, tau / np.where(one, 1.0, q - 1.0))
    return {"tau": tau, "alpha": alpha, "f": f, "Dq": dq}


def assert_constant_spectrum(result, value: float) -> None:
    for name in ("Dq", "alpha", "f"):
        np.testing.assert_allclose(getattr(result, name), value, rtol=0, atol=TOL, err_msg=name)
    assert result.D0 == pytest.approx(value, abs=TOL)
    assert result.alpha0 == pytest.approx(value, abs=TOL)
    assert not result.poor_fit.any()


@pytest.mark.parametrize("n", [256, 768])
def test_uniform_image_has_dimension_two(n):
    # a uniform measure fills the plane: D_q = α = f = 2 (docs/design.md#multifractal);
    # 768 = 3·256 is not a power of two and must work without padding
    result = multifractal_spectrum(np.ones((n, n)))
    assert_constant_spectrum(result, 2.0)
    np.testing.assert_allclose(result.r2, 1.0, atol=1e-12)


def test_one_pixel_row_has_dimension_one():
    # the only non-zero pixels are one full row: a line, D = 1 (docs/design.md#multifractal)
    image = np.zeros((256, 256))
    image[77] = 1.0
    assert_constant_spectrum(multifractal_spectrum(image), 1.0)


def test_single_pixel_has_dimension_zero():
    # all mass in one pixel: one occupied box at every ε, p = 1, so τ = α = f = D = 0
    image = np.zeros((256, 256))
    image[3, 200] = 5.0
    assert_constant_spectrum(multifractal_spectrum(image), 0.0)


def test_dyadic_gasket_has_dimension_log2_3():
    # (x & y) == 0 is the dyadic Sierpiński gasket: 3 of 4 sub-boxes at every level, equal
    # masses, so D_q = α = f = log₂ 3 for every q, negative q included
    # (docs/design.md#multifractal)
    y, x = np.mgrid[:256, :256]
    result = multifractal_spectrum((x & y) == 0)
    assert_constant_spectrum(result, np.log2(3.0))
    assert np.all(np.isfinite(result.Dq))


WEIGHT_SETS = [
    (0.4, 0.3, 0.2, 0.1),
    (0.7, 0.1, 0.1, 0.1),
    (0.05, 0.15, 0.35, 0.45),
    (0.6, 0.25, 0.15, 0.0),  # one empty quarter at every level
    (0.5, 0.0, 0.0, 0.5),  # a diagonal: empty boxes, D_q = 1 for all q
    (1.0 - 3e-6, 1e-6, 1e-6, 1e-6),  # p^-10 reaches 1e480: overflows unless in log domain
]


@pytest.mark.parametrize("weights", WEIGHT_SETS)
def test_cascade_matches_closed_form(weights):
    result = multifractal_spectrum(cascade(weights, 8))
    expected = cascade_closed_form(weights, result.q)
    for name, value in expected.items():
        np.testing.assert_allclose(
            getattr(result, name), value, rtol=0, atol=TOL, err_msg=f"{name} for {weights}"
        )
    at0 = cascade_closed_form(weights, np.array([0.0]))
    assert result.D0 == pytest.approx(-at0["tau"][0], abs=TOL)
    assert result.alpha0 == pytest.approx(at0["alpha"][0], abs=TOL)
    assert result.alpha0 >= result.D0 - TOL


def test_cascade_with_finer_pixels_and_other_levels():
    # a level-9 cascade (512 px) fitted on k = 3…7 only, q off the default grid
    weights = (0.4, 0.3, 0.2, 0.1)
    q = np.array([-7.25, -0.1, 0.0, 0.999, 1.0, 2.75])
    result = multifractal_spectrum(cascade(weights, 9), q=q, k=(3, 4, 5, 6, 7))
    expected = cascade_closed_form(weights, q)
    np.testing.assert_allclose(result.tau, expected["tau"], atol=TOL)
    np.testing.assert_allclose(result.alpha, expected["alpha"], atol=TOL)
    np.testing.assert_allclose(result.f, expected["f"], atol=TOL)
    np.testing.assert_allclose(result.Dq[q != 0.999], expected["Dq"][q != 0.999], atol=TOL)
    # q = 0.999: D_q = τ/(q − 1) is ill-conditioned but still close to D1
    assert result.Dq[3] == pytest.approx(result.Dq[4], abs=1e-3)


def random_image(seed: int, n: int = 256) -> np.ndarray:
    """Seeded image with no exact scaling: sparse random grey levels with empty boxes."""
    rng = np.random.default_rng(seed)
    image = rng.random((n, n)) ** 3
    image[rng.random((n, n)) < 0.6] = 0.0
    image[: n // 2, : n // 4] = 0.0  # a whole empty region: empty boxes at every level
    return image


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_legendre_identity_and_alpha0_above_d0(seed):
    result = multifractal_spectrum(random_image(seed))
    # f = qα − τ holds at every ε, hence for the fitted slopes (Chhabra & Jensen 1989)
    np.testing.assert_allclose(result.f, result.q * result.alpha - result.tau, atol=1e-10)
    i0 = int(np.flatnonzero(result.q == 0.0)[0])
    assert result.f[i0] == pytest.approx(result.D0, abs=1e-12)
    assert result.alpha[i0] == pytest.approx(result.alpha0, abs=1e-12)
    assert result.alpha0 >= result.D0


def test_empty_boxes_give_no_nan():
    image = random_image(3)
    result = multifractal_spectrum(image)
    assert (box_masses(image, 8) == 0).any()  # the premise: there are empty boxes
    for name in ("alpha", "f", "tau", "Dq", "r2"):
        assert np.all(np.isfinite(getattr(result, name))), name
    assert np.isfinite(result.D0) and np.isfinite(result.alpha0)
    assert (result.q < 0).any() and (result.q == 1.0).any()  # the orders at risk are there


def test_empty_boxes_are_excluded_for_every_q():
    # a measure in one quarter of a 512 image, seen with k = 2…9, has exactly the box
    # masses of the 256 image with k = 1…8 plus empty boxes; if empty boxes counted
    # (0⁰ = 1) D0 and every q ≤ 0 would change
    small = random_image(4)
    big = np.zeros((512, 512))
    big[256:, :256] = small
    a = multifractal_spectrum(small)
    b = multifractal_spectrum(big, k=range(2, 10))
    for name in ("alpha", "f", "tau", "Dq", "r2"):
        np.testing.assert_allclose(getattr(b, name), getattr(a, name), atol=1e-10, err_msg=name)
    assert b.D0 == pytest.approx(a.D0, abs=1e-10)


def test_batch_equals_one_by_one():
    images = np.stack([random_image(s) for s in range(4)]).reshape(2, 2, 256, 256)
    batch = multifractal_spectrum(images)
    assert batch.Dq.shape == (2, 2, DEFAULT_Q.size)
    assert batch.D0.shape == (2, 2)
    for i in range(2):
        for j in range(2):
            one = multifractal_spectrum(images[i, j])
            np.testing.assert_allclose(batch.Dq[i, j], one.Dq, atol=1e-12)
            np.testing.assert_allclose(batch.f[i, j], one.f, atol=1e-12)
            assert batch.alpha0[i, j] == pytest.approx(one.alpha0, abs=1e-12)
            assert batch.alpha0_over_D0[i, j] == pytest.approx(one.alpha0_over_D0, abs=1e-12)


def test_scaling_and_dtype_do_not_matter():
    # p_i is normalised by the total mass; a bool image is the 0/1 measure
    pore = random_image(5) > 0
    a = multifractal_spectrum(pore)
    b = multifractal_spectrum(pore.astype(np.float64) * 3.7e-5)
    np.testing.assert_allclose(a.Dq, b.Dq, atol=1e-12)
    np.testing.assert_allclose(a.f, b.f, atol=1e-12)


def test_poor_fit_is_flagged():
    # mass uniform on the 32×32 corner of a 256 image: N(ε) = 1 for k = 1, 2, 3 and 4^(k−3)
    # for k = 4…8, so ln N(ε) against ln ε is bent and the τ(0) fit is poor
    image = np.zeros((256, 256))
    image[:32, :32] = 1.0
    result = multifractal_spectrum(image)
    k = np.arange(1, 9)
    log_n = np.log(np.maximum(1, 4.0 ** (k - 3)))
    r2_expected = np.corrcoef(-k * np.log(2), log_n)[0, 1] ** 2
    i0 = int(np.flatnonzero(result.q == 0.0)[0])
    assert result.r2_tau[i0] == pytest.approx(r2_expected, abs=1e-12)
    assert r2_expected < 0.99
    assert result.poor_fit.all()  # the same bend at every q: equal masses in all boxes
    assert not multifractal_spectrum(image, min_r2=0.9).poor_fit.any()


@pytest.mark.parametrize(
    ("measure", "match"),
    [
        (np.full((256, 256), -1.0), "non-negative"),
        (np.where(np.eye(256) > 0, np.nan, 1.0), "non-finite"),
        (np.ones((256, 512)), "square"),
        (np.ones((128, 128)), "multiple of 2\\^8"),
        (np.ones((300, 300)), "never padded"),
        (np.zeros((256, 256)), "zero everywhere"),
        (np.stack([np.ones((256, 256)), np.zeros((256, 256))]), "image 1 is zero"),
        (np.ones(256), "image"),
        (np.ones((256, 256), dtype=complex), "real"),
    ],
)
def test_bad_measure_raises_clear_error(measure, match):
    with pytest.raises(ValueError, match=match):
        multifractal_spectrum(measure)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"k": (3,)}, "at least two"),
        ({"k": (1, 1, 2)}, "distinct"),
        ({"k": (1.5, 2)}, "integers"),
        ({"q": [0.0, np.inf]}, "finite"),
        ({"q": []}, "non-empty"),
        ({"min_r2": 1.5}, "min_r2"),
    ],
)
def test_bad_parameters_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        multifractal_spectrum(np.ones((256, 256)), **kwargs)
