"""Straight shear bands and their widths in metres (results.bands), on made-up Gauss-point
fields whose answer is known: a Gaussian band γ = γb + A exp(−d²/2s²) has a full width at
half maximum of 2√(2 ln 2) s ≈ 2.3548 s at any angle and on any cloud of points; a symmetric
cross gives two bands at ±θ; a field without a band gives none."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from granular_material.results.active_bands import (
    active_bands,
    fit_bands,
    incremental_points,
    start_step,
)
from granular_material.results.band_measures import band_measures
from granular_material.results.bands import band_width, find_bands
from granular_material.results.summary import band_summary

WIDTH, HEIGHT = 0.05, 0.10
FWHM = 2 * math.sqrt(2 * math.log(2))  # a Gaussian's width over its standard deviation


def grid(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    """A regular nx × ny grid of points over the specimen."""
    x, y = np.meshgrid(np.linspace(0, WIDTH, nx), np.linspace(0, HEIGHT, ny))
    return x.ravel(), y.ravel()


def jittered(nx: int, ny: int, seed: int, amount: float = 0.4) -> tuple[np.ndarray, np.ndarray]:
    """A grid whose points are each moved by up to ``amount`` of its spacing (an irregular
    cloud that still covers the specimen evenly)."""
    rng = np.random.default_rng(seed)
    hx, hy = WIDTH / nx, HEIGHT / ny
    x, y = np.meshgrid((np.arange(nx) + 0.5) * hx, (np.arange(ny) + 0.5) * hy)
    x = x.ravel() + amount * hx * rng.uniform(-1, 1, x.size)
    y = y.ravel() + amount * hy * rng.uniform(-1, 1, y.size)
    return x, y


def scattered(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points drawn uniformly over the specimen."""
    rng = np.random.default_rng(seed)
    return rng.uniform(0, WIDTH, n), rng.uniform(0, HEIGHT, n)


def gauss_points(nx: int, ny: int, order: int) -> tuple[np.ndarray, np.ndarray]:
    """The Gauss points (order × order a quadrilateral) of an nx × ny mesh of the specimen."""
    q = {2: np.array([-1, 1]) / math.sqrt(3), 3: np.array([-1, 0, 1]) * math.sqrt(0.6)}[order]
    xs = ((np.arange(nx)[:, None] + 0.5 + 0.5 * q) * WIDTH / nx).ravel()
    ys = ((np.arange(ny)[:, None] + 0.5 + 0.5 * q) * HEIGHT / ny).ravel()
    x, y = np.meshgrid(xs, ys)
    return x.ravel(), y.ravel()


def distance(x: np.ndarray, y: np.ndarray, angle_deg: float,
             centre: tuple[float, float] = (WIDTH / 2, HEIGHT / 2)) -> np.ndarray:
    """Signed distance [m] of the points to the line through ``centre`` at ``angle_deg``."""
    t = math.radians(angle_deg)
    return -(x - centre[0]) * math.sin(t) + (y - centre[1]) * math.cos(t)


def gaussian(x: np.ndarray, y: np.ndarray, angle_deg: float, s: float,
             centre: tuple[float, float] = (WIDTH / 2, HEIGHT / 2)) -> np.ndarray:
    """A Gaussian band of standard deviation ``s`` [m], peak 0.2 over a background 0.01."""
    return 0.01 + 0.2 * np.exp(-distance(x, y, angle_deg, centre) ** 2 / (2 * s * s))


def table(x: np.ndarray, y: np.ndarray, gamma: np.ndarray, step: int = 3) -> pd.DataFrame:
    return pd.DataFrame({"step": step, "axial_strain": 0.05, "x": x, "y": y,
                         "shear_strain": gamma})


def angle_error(measured: float, expected: float) -> float:
    """|measured − expected| [°] of two axes (180° apart is the same axis)."""
    return abs((measured - expected + 90.0) % 180.0 - 90.0)


@pytest.mark.parametrize("points", [(20, 40), (40, 80)], ids=["2.5mm", "1.25mm"])
@pytest.mark.parametrize("angle", [0.0, 30.0, 55.0, -60.0, 90.0, -45.0])
@pytest.mark.parametrize("s", [0.002, 0.004])
def test_one_gaussian_band_gives_its_width_and_angle_on_two_spacings(points, angle, s):
    x, y = grid(*points)
    bands = find_bands(table(x, y, gaussian(x, y, angle, s)))
    assert len(bands) == 1
    band = bands[0]
    assert band.width == pytest.approx(FWHM * s, rel=0.10)
    assert angle_error(band.inclination_deg, angle) < 1.5
    assert -90 < band.inclination_deg <= 90
    assert (band.centre_x, band.centre_y) == pytest.approx((WIDTH / 2, HEIGHT / 2), abs=2e-3)
    # its axis is the line −x sin θ + y cos θ = offset, through its centre
    t = math.radians(band.inclination_deg)
    assert -band.centre_x * math.sin(t) + band.centre_y * math.cos(t) == pytest.approx(
        band.offset, abs=1e-9)
    assert band.peak_shear_strain == pytest.approx(0.21, rel=0.05)
    assert band.background_shear_strain == pytest.approx(0.01, rel=0.05)
    assert 0.01 < band.mean_shear_strain < 0.21
    assert band.length > 3 * band.width and band.step == 3 and band.axial_strain == 0.05
    assert band_width(table(x, y, gaussian(x, y, angle, s))) == band.width


@pytest.mark.parametrize("cloud", ["jittered", "scattered"])
@pytest.mark.parametrize("angle", [20.0, 55.0, -70.0])
def test_irregular_clouds_give_the_same_width(cloud, angle):
    s = 0.003
    for seed in range(3):
        x, y = jittered(30, 60, seed) if cloud == "jittered" else scattered(2000, seed)
        bands = find_bands(table(x, y, gaussian(x, y, angle, s)))
        assert len(bands) == 1
        assert bands[0].width == pytest.approx(FWHM * s, rel=0.10)
        assert angle_error(bands[0].inclination_deg, angle) < 2.0


def test_the_width_does_not_depend_on_the_mesh():
    """One band on the Gauss points of 8 × 16 quadrilaterals (2 × 2 points each, 6.25 mm
    elements) and of 16 × 32 and 32 × 64 (3 × 3 points): the same width within 5 %."""
    s = 0.003
    widths = []
    for mesh in ((8, 16, 2), (16, 32, 3), (32, 64, 3)):
        x, y = gauss_points(*mesh)
        widths.append(band_width(table(x, y, gaussian(x, y, 55.0, s))))
    assert widths == pytest.approx([FWHM * s] * 3, rel=0.05)


def test_the_width_is_not_a_multiple_of_the_spacing():
    """On a 2.5 mm grid, bands 4.7–10.6 mm wide measure as wide as they are, each wider than
    the one before: the width is read between the points, not counted in them."""
    x, y = grid(20, 40)
    sigmas = np.linspace(0.002, 0.0045, 11)
    widths = np.array([band_width(table(x, y, gaussian(x, y, 0.0, s))) for s in sigmas])
    assert np.all(np.diff(widths) > 0)
    assert widths == pytest.approx(FWHM * sigmas, rel=0.10)


def test_a_top_hat_band_is_as_wide_as_it_is():
    x, y = gauss_points(16, 32, 3)
    gamma = np.where(np.abs(distance(x, y, 55.0)) < 0.002, 0.3, 0.02)
    assert band_width(table(x, y, gamma)) == pytest.approx(0.004, rel=0.10)


@pytest.mark.parametrize("theta", [40.0, 55.0, 65.0])
@pytest.mark.parametrize("cloud", ["grid", "gauss", "jittered"])
def test_a_symmetric_cross_gives_two_bands_at_plus_and_minus_theta(theta, cloud):
    s = 0.003
    x, y = {"grid": lambda: grid(40, 80), "gauss": lambda: gauss_points(16, 32, 3),
            "jittered": lambda: jittered(30, 60, 1)}[cloud]()
    gamma = np.maximum(gaussian(x, y, theta, s), gaussian(x, y, -theta, s))
    bands = find_bands(table(x, y, gamma))
    assert len(bands) == 2
    angles = sorted(b.inclination_deg for b in bands)
    assert angle_error(angles[0], -theta) < 2.0 and angle_error(angles[1], theta) < 2.0
    for band in bands:
        assert band.width == pytest.approx(FWHM * s, rel=0.10)
        assert (band.centre_x, band.centre_y) == pytest.approx((WIDTH / 2, HEIGHT / 2),
                                                               abs=3e-3)
    assert len(find_bands(table(x, y, gamma), max_bands=1)) == 1


def test_two_parallel_bands_are_two_bands():
    x, y = gauss_points(16, 32, 3)
    lower, upper = (WIDTH / 2, 0.035), (WIDTH / 2, 0.070)
    gamma = np.maximum(gaussian(x, y, 55.0, 0.003, lower), gaussian(x, y, 55.0, 0.003, upper))
    bands = find_bands(table(x, y, gamma))
    assert len(bands) == 2
    for band in bands:
        assert angle_error(band.inclination_deg, 55.0) < 1.5
        assert band.width == pytest.approx(FWHM * 0.003, rel=0.10)
    # each band's axis runs through its own centre line
    t = math.radians(55.0)
    offsets = sorted(b.offset for b in bands)
    expected = sorted(-cx * math.sin(t) + cy * math.cos(t) for cx, cy in (lower, upper))
    assert offsets == pytest.approx(expected, abs=1e-3)


def _no_band_fields(mesh: tuple[int, int, int]) -> dict[str, np.ndarray]:
    x, y = gauss_points(*mesh)
    rng = np.random.default_rng(4)
    return {
        "uniform": np.full(x.size, 0.02),
        "noisy": 0.02 * (1 + 0.05 * rng.standard_normal(x.size)),
        "zero": np.zeros(x.size),
        "gradient": 0.01 + 0.5 * x,
        "hot spot": 0.01 + 0.2 * np.exp(-((x - 0.02) ** 2 + (y - 0.03) ** 2) / (2 * 0.006 ** 2)),
        # strain gathered along the base: it never falls to half on the lower side
        "base": 0.01 + 0.2 * np.exp(-(y ** 2) / (2 * 0.005 ** 2)),
        # a band whose peak is 1.25 times the background
        "faint": 0.02 + 0.005 * np.exp(-distance(x, y, 55.0) ** 2 / (2 * 0.003 ** 2)),
    }


@pytest.mark.parametrize("mesh", [(8, 16, 2), (32, 64, 3)], ids=["8x16", "32x64"])
@pytest.mark.parametrize("name", list(_no_band_fields((1, 1, 2))))
def test_no_band_gives_none_and_a_nan_width(name, mesh):
    x, y = gauss_points(*mesh)
    points = table(x, y, _no_band_fields(mesh)[name])
    assert find_bands(points) == []
    assert math.isnan(band_width(points))


def test_too_few_points_and_bad_input():
    assert find_bands(table(np.array([0.0, 1.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0, 1.0]),
                            np.array([0.0, 1.0, 0.0, 1.0]))) == []
    x, y = grid(10, 20)
    with pytest.raises(ValueError, match="columns"):
        find_bands(pd.DataFrame({"x": x, "y": y}))
    with pytest.raises(ValueError, match="max_bands"):
        find_bands(table(x, y, x), max_bands=0)
    with pytest.raises(ValueError, match="finite"):
        find_bands(table(x, y, np.where(x > 0.01, np.nan, 0.0)))
    with pytest.raises(ValueError, match="no step"):
        find_bands(table(x, y, x), step=9)


def test_the_step_is_chosen():
    x, y = grid(20, 40)
    points = pd.concat([table(x, y, gaussian(x, y, 30.0, 0.003), step=1),
                        table(x, y, np.full(x.size, 0.02), step=2)], ignore_index=True)
    assert math.isnan(band_width(points))  # the last step: uniform
    assert band_width(points, step=1) == pytest.approx(FWHM * 0.003, rel=0.10)


@settings(max_examples=30, deadline=None)
@given(angle=st.floats(-85.0, 85.0), s=st.floats(0.0018, 0.0045),
       shift=st.tuples(st.floats(-0.005, 0.005), st.floats(-0.01, 0.01)),
       seed=st.integers(0, 2 ** 16))
def test_any_gaussian_band_on_an_irregular_cloud(angle, s, shift, seed):
    x, y = jittered(30, 60, seed)
    centre = (WIDTH / 2 + shift[0], HEIGHT / 2 + shift[1])
    bands = find_bands(table(x, y, gaussian(x, y, angle, s, centre)))
    assert len(bands) == 1
    assert bands[0].width == pytest.approx(FWHM * s, rel=0.10)
    assert angle_error(bands[0].inclination_deg, angle) < 2.0
    assert abs(float(distance(np.array(bands[0].centre_x), np.array(bands[0].centre_y),
                              angle, centre))) < 1e-3


@settings(max_examples=15, deadline=None)
@given(theta=st.floats(35.0, 70.0), s=st.floats(0.002, 0.004), seed=st.integers(0, 2 ** 16))
def test_any_symmetric_cross(theta, s, seed):
    x, y = jittered(30, 60, seed)
    gamma = np.maximum(gaussian(x, y, theta, s), gaussian(x, y, -theta, s))
    angles = sorted(b.inclination_deg for b in find_bands(table(x, y, gamma)))
    assert len(angles) == 2
    assert angle_error(angles[0], -theta) < 2.0 and angle_error(angles[1], theta) < 2.0


def _specimen(band: bool) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A run of three steps on the Gauss points of 16 × 32 elements; at the last, a cross of
    two Gaussian bands (s = 3 mm) at ±55° or a uniform γ."""
    x, y = gauss_points(16, 32, 3)
    tables, rows = [], []
    for step, e in enumerate((0.0, 0.05, 0.10)):
        gamma = np.full(x.size, e / 2)
        if band and step == 2:
            gamma = np.maximum(gaussian(x, y, 55.0, 0.003), gaussian(x, y, -55.0, 0.003))
        tables.append(pd.DataFrame({"step": step, "axial_strain": e, "x": x, "y": y,
                                    "shear_strain": gamma}))
        rows.append({"step": step, "axial_strain": e, "stress_ratio": 1 + 10 * e,
                     "volumetric_strain": 0.1 * e})
    return pd.DataFrame(rows), pd.concat(tables, ignore_index=True)


def test_band_measures_report_the_width_and_each_band():
    measures = band_measures(*_specimen(True), HEIGHT, WIDTH)
    assert measures["band_width"] == pytest.approx(FWHM * 0.003, rel=0.10)
    assert measures["band_count"] == 2
    angles = sorted([measures["band_1_inclination_deg"], measures["band_2_inclination_deg"]])
    assert angles == pytest.approx([-55.0, 55.0], abs=2.0)
    assert {"onset", "inclination_deg", "elongation", "crossing_x"} <= set(measures)
    uniform = band_measures(*_specimen(False), HEIGHT, WIDTH)
    assert math.isnan(uniform["band_width"]) and uniform["band_count"] == 0
    assert math.isnan(uniform["band_1_inclination_deg"])


def test_the_summary_adds_the_width_and_the_bands():
    steps, points = _specimen(True)
    result = SimpleNamespace(steps=steps, points=points, row_nearest=lambda e: 2)
    summary = band_summary(result, [0.1], 3.0)
    assert {"shear_bands", "shear_band_final", "mohr_coulomb_inclination_deg"} <= set(summary)
    assert summary["band_width"] == pytest.approx(FWHM * 0.003, rel=0.10)
    assert len(summary["bands_final"]) == 2
    assert summary["bands_final"][0]["width"] == summary["band_width"]
    assert sorted(b["inclination_deg"] for b in summary["bands_final"]) == pytest.approx(
        [-55.0, 55.0], abs=2.0)
    flat = SimpleNamespace(steps=steps, points=_specimen(False)[1], row_nearest=lambda e: 2)
    summary = band_summary(flat, [0.1], 3.0)
    assert math.isnan(summary["band_width"]) and summary["bands_final"] == []


def test_a_cross_of_a_strong_and_a_weak_band_gives_both():
    """The weaker band of a cross, half the stronger's excess, at its own angle and width;
    the stronger one is listed first."""
    x, y = gauss_points(16, 32, 3)
    weak = 0.01 + 0.1 * np.exp(-distance(x, y, -57.0) ** 2 / (2 * 0.004 ** 2))
    bands = find_bands(table(x, y, np.maximum(gaussian(x, y, 55.0, 0.003), weak)))
    assert len(bands) == 2
    assert angle_error(bands[0].inclination_deg, 55.0) < 1.5
    assert angle_error(bands[1].inclination_deg, -57.0) < 1.5
    assert bands[0].width == pytest.approx(FWHM * 0.003, rel=0.10)
    assert bands[1].width == pytest.approx(FWHM * 0.004, rel=0.10)
    assert bands[0].strength > bands[1].strength
    assert bands[1].peak_shear_strain == pytest.approx(0.11, rel=0.05)


@pytest.mark.parametrize("mesh", [(8, 16, 2), (16, 32, 3)])
def test_noise_on_the_field_moves_the_width_little(mesh):
    """γ of a band with 10 % of noise at every point: within 10 % of its width still."""
    x, y = gauss_points(*mesh)
    rng = np.random.default_rng(7)
    for _ in range(5):
        gamma = gaussian(x, y, 55.0, 0.003) * (1 + 0.1 * rng.standard_normal(x.size))
        bands = find_bands(table(x, y, gamma))
        assert len(bands) == 1
        assert bands[0].width == pytest.approx(FWHM * 0.003, rel=0.10)
        assert angle_error(bands[0].inclination_deg, 55.0) < 1.5


def test_a_band_reflected_at_a_side_gives_its_two_legs():
    """A band rising at 50° from the bottom-left corner to the right side, reflected there
    into −50° up to the top: two bands, each at its own angle and in its own place."""
    x, y = gauss_points(16, 32, 3)
    turn = (WIDTH, WIDTH * math.tan(math.radians(50.0)))
    legs = np.where(y < turn[1], np.exp(-distance(x, y, 50.0, (0.0, 0.0)) ** 2 / 18e-6),
                    np.exp(-distance(x, y, -50.0, turn) ** 2 / 18e-6))
    bands = find_bands(table(x, y, 0.01 + 0.2 * legs))
    assert [round(b.inclination_deg) for b in bands] == [50, -50]
    assert [b.width for b in bands] == pytest.approx([FWHM * 0.003] * 2, rel=0.10)
    assert (bands[1].centre_x, bands[1].centre_y) == pytest.approx(
        ((WIDTH + WIDTH - (HEIGHT - turn[1]) / math.tan(math.radians(50.0))) / 2,
         (turn[1] + HEIGHT) / 2), abs=3e-3)


# The bands active over an increment (results.active_bands): the shear strain of the change
# of strain between two steps, fitted as Gaussian ridges.

def _strain_table(x: np.ndarray, y: np.ndarray, steps: dict[int, tuple[float, np.ndarray,
                                                                     np.ndarray, np.ndarray]]
                  ) -> pd.DataFrame:
    """A points table with strain columns: step → (axial strain, exx, eyy, exy)."""
    return pd.concat([pd.DataFrame({"step": step, "axial_strain": e, "point": np.arange(x.size),
                                    "x": x, "y": y, "exx": exx, "eyy": eyy, "exy": exy,
                                    "shear_strain": np.hypot(exx - eyy, 2 * exy)})
                      for step, (e, exx, eyy, exy) in steps.items()], ignore_index=True)


def _simple_shear(x: np.ndarray, y: np.ndarray, angle_deg: float, s: float,
                  amount: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The strain (exx, eyy, exy) of a Gaussian band of simple shear along ``angle_deg``:
    its shear strain is amount · exp(−d²/2s²)."""
    g = amount * np.exp(-distance(x, y, angle_deg) ** 2 / (2 * s * s))
    t = math.radians(angle_deg)
    # shear γ along the axis (cos t, sin t) with normal (−sin t, cos t): ε = γ/2 (a⊗n + n⊗a)
    a, n = (math.cos(t), math.sin(t)), (-math.sin(t), math.cos(t))
    return g * a[0] * n[0], g * a[1] * n[1], 0.5 * g * (a[0] * n[1] + a[1] * n[0])


def _diffuse(x: np.ndarray, y: np.ndarray, amount: float) -> tuple[np.ndarray, ...]:
    """A wide, smooth compression (more at the middle) of no band's shape."""
    bump = amount * (1 + np.exp(-((x - WIDTH / 2) ** 2 + (y - HEIGHT / 2) ** 2) / 0.03 ** 2))
    return 0.2 * bump, -bump, 0.0 * bump


@pytest.mark.parametrize("mesh", [(8, 16), (16, 32)], ids=["8x16", "16x32"])
def test_the_incremental_band_is_found_under_a_diffuse_past(mesh):
    """Up to step 2 the specimen strains diffusely; from step 2 to 3 a band of simple shear
    (s = 4 mm at 50°) forms. The accumulated field's widest feature is the diffuse past; the
    increment's band is recovered to a few per cent, whatever the mesh."""
    x, y = gauss_points(*mesh, 2)
    before = _diffuse(x, y, 0.05)
    band = _simple_shear(x, y, 50.0, 0.004, 0.1)
    after = tuple(b + d for b, d in zip(before, band, strict=True))
    points = _strain_table(x, y, {0: (0.0, *(0 * c for c in before)), 1: (0.02, *before),
                                  2: (0.04, *before), 3: (0.05, *after)})
    field = incremental_points(points)
    assert int(field["start_step"].iloc[0]) == start_step(points) == 2  # 0.8 × 5 % = 4 %
    assert field["shear_strain"].to_numpy() == pytest.approx(
        0.1 * np.exp(-distance(x, y, 50.0) ** 2 / (2 * 0.004 ** 2)), abs=1e-12)
    bands = active_bands(points)
    assert len(bands) == 1
    assert bands[0].width == pytest.approx(FWHM * 0.004, rel=0.03)
    assert angle_error(bands[0].inclination_deg, 50.0) < 1.0
    assert (bands[0].step, bands[0].start_step) == (3, 2)
    assert bands[0].start_axial_strain == pytest.approx(0.04)
    # the increment since step 1 holds the same band (the diffuse part stopped at step 1)
    assert active_bands(points, start=1)[0].width == pytest.approx(bands[0].width)


@pytest.mark.parametrize(("theta", "s"), [(50.0, 0.012), (45.0, 0.015), (55.0, 0.008)])
def test_a_cross_of_wide_overlapping_bands_gives_both_widths(theta, s):
    """Two bands each as wide as 40–60 % of the specimen, crossing at its middle: no part of an
    arm lies clear of the other (the profile search finds one arm or none), and the fit
    gives both, each at its width within a few per cent."""
    x, y = gauss_points(16, 32, 2)
    gamma = (0.002 + 0.02 * np.exp(-distance(x, y, theta) ** 2 / (2 * s * s))
             + 0.02 * np.exp(-distance(x, y, -theta) ** 2 / (2 * s * s)))
    bands = fit_bands(table(x, y, gamma))
    assert len(bands) == 2
    assert sorted(angle_error(b.inclination_deg, theta) for b in bands)[0] < 1.0
    assert sorted(angle_error(b.inclination_deg, -theta) for b in bands)[0] < 1.0
    for band in bands:
        assert band.width == pytest.approx(FWHM * s, rel=0.03)
        assert band.centre_x == pytest.approx(WIDTH / 2, abs=0.002)
        assert band.centre_y == pytest.approx(HEIGHT / 2, abs=0.002)
        assert band.background == pytest.approx(0.002, rel=0.05)
        assert band.residual < 0.02


def test_parallel_and_crossed_narrow_bands_are_each_fitted():
    """Four reflected narrow bands (two parallel pairs) give four ridges of their width."""
    x, y = gauss_points(16, 32, 3)
    s = 0.0015
    gamma = 0.01 + sum(0.2 * np.exp(-distance(x, y, a, (WIDTH / 2, c)) ** 2 / (2 * s * s))
                       for a, c in ((50, 0.035), (-50, 0.035), (50, 0.065), (-50, 0.065)))
    bands = fit_bands(table(x, y, gamma))
    assert len(bands) == 4
    assert [b.width for b in bands] == pytest.approx([FWHM * s] * 4, rel=0.05)


@pytest.mark.parametrize("name", ["uniform", "gradient", "noise", "hot spot"])
def test_no_band_gives_no_fitted_band(name):
    x, y = gauss_points(8, 16, 2)
    rng = np.random.default_rng(3)
    gamma = {"uniform": np.full(x.size, 0.02), "gradient": 0.01 + 0.5 * x,
             "noise": 0.02 + 0.002 * rng.standard_normal(x.size),
             "hot spot": 0.01 + 0.2 * np.exp(-((x - 0.025) ** 2 + (y - 0.05) ** 2)
                                              / (2 * 0.003 ** 2))}[name]
    assert fit_bands(table(x, y, gamma)) == []


def test_the_increment_refuses_what_it_cannot_read():
    x, y = gauss_points(2, 4, 2)
    zero = np.zeros(x.size)
    points = _strain_table(x, y, {0: (0.0, zero, zero, zero), 1: (0.01, zero, zero, zero)})
    with pytest.raises(ValueError, match="exx"):
        incremental_points(points.drop(columns="exx"))
    with pytest.raises(ValueError, match="no step 5"):
        incremental_points(points, step=5)
    with pytest.raises(ValueError, match="start before"):
        incremental_points(points, step=1, start=1)
    with pytest.raises(ValueError, match="first"):
        start_step(points, step=0)
    with pytest.raises(ValueError, match="share"):
        start_step(points, share=0.0)
    with pytest.raises(ValueError, match="same points"):
        incremental_points(points[~((points["step"] == 0) & (points["point"] == 0))])
    with pytest.raises(ValueError, match="max_bands"):
        fit_bands(table(x, y, zero), max_bands=0)
    # a table without strain, or of one step, has no active band
    assert active_bands(points.drop(columns=["exx", "eyy", "exy"])) == []
    assert active_bands(points[points["step"] == 1]) == []


def test_the_summary_and_the_measures_give_the_active_width():
    """A run whose band forms over the last steps: the summary's and the measures'
    active width is the band's; a table without strain gives NaN."""
    x, y = gauss_points(16, 32, 2)
    zero = np.zeros(x.size)
    band = _simple_shear(x, y, -50.0, 0.005, 0.1)
    points = _strain_table(x, y, {0: (0.0, zero, zero, zero), 1: (0.05, zero, zero, zero),
                                  2: (0.10, *band)})
    steps = pd.DataFrame({"step": [0, 1, 2], "axial_strain": [0.0, 0.05, 0.10],
                          "stress_ratio": [1.0, 3.0, 2.5], "volumetric_strain": 0.0})
    result = SimpleNamespace(steps=steps, points=points, row_nearest=lambda e: 2)
    summary = band_summary(result, [0.1], 3.0)
    assert summary["active_band_width"] == pytest.approx(FWHM * 0.005, rel=0.03)
    assert len(summary["active_bands"]) == 1
    assert summary["active_bands"][0]["start_step"] == 1
    measures = band_measures(steps, points, HEIGHT, WIDTH)
    assert measures["active_band_width"] == summary["active_band_width"]
    assert measures["active_band_count"] == 1
    plain = band_measures(*_specimen(True), HEIGHT, WIDTH)
    assert math.isnan(plain["active_band_width"]) and plain["active_band_count"] == 0


def test_a_regularised_softening_specimen_has_an_active_band_the_profile_misses():
    """The softening Mohr–Coulomb specimen regularised at ℓ = 5 mm on 4 × 8 quad8 (a real run,
    to 3 %): its localised zone is a symmetric cross as wide as half the specimen. The
    accumulated γ's profile search finds no band at its thresholds; the active bands are
    the cross, two arms at ±θ of the same width, 20–40 mm (the study: 28 mm on every mesh)."""
    from granular_material.fem import BiaxialSetup, MohrCoulomb, NewtonSettings, Regularisation
    from granular_material.runs.runner import run_biaxial

    setup = BiaxialSetup(nx=4, ny=8, element="quad8", platens="rough", axial_strain=0.03)
    material = MohrCoulomb(friction_angle=35, critical_friction_angle=28,
                           softening_strain=0.02, dilation_angle=5)
    result = run_biaxial(setup, material, 15, NewtonSettings(),
                         regularisation=Regularisation("second-gradient", 0.005))
    assert result.error is None
    summary = band_summary(result, [0.03], 3.6)
    assert math.isnan(summary["band_width"])
    bands = summary["active_bands"]
    assert len(bands) == 2
    assert bands[0]["inclination_deg"] == pytest.approx(-bands[1]["inclination_deg"], abs=1.0)
    assert bands[0]["width"] == pytest.approx(bands[1]["width"], rel=0.02)
    assert 0.020 < summary["active_band_width"] < 0.040


@settings(max_examples=60, deadline=None)
@given(rows=st.integers(1, 6), length=st.integers(1, 120), scale=st.floats(-8, 8),
       sigma=st.sampled_from([0.5, 1.0, 2.5, 4.0]), seed=st.integers(0, 2**31 - 1))
def test_the_hough_smoothing_is_scipys_gaussian_filter_to_the_last_bit(rows, length, scale,
                                                                       sigma, seed):
    """The accumulator's Gaussian smoothing, without scipy.ndimage: the same numbers as its
    ``gaussian_filter1d`` (constant mode), rows shorter than the kernel included."""
    from scipy.ndimage import gaussian_filter1d

    from granular_material.results.bands import _smoothed

    rng = np.random.default_rng(seed)
    values = rng.random((rows, length)) * 10.0 ** scale
    values[rng.random(values.shape) < 0.4] = 0.0
    np.testing.assert_array_equal(
        _smoothed(values, sigma),
        gaussian_filter1d(values, sigma=sigma, axis=1, mode="constant"))
