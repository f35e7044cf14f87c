"""Pore images of periodic RVEs, the post-processor and the ``fractal`` command."""

from __future__ import annotations

import json
from importlib.metadata import entry_points

import numpy as np
import pytest
from granular_material_pore_fractal import (
    choose_window,
    multifractal_spectrum,
    pore_fractal,
    pore_image,
    pore_images,
    rasterize_pores,
    rve_porosity,
)

from granular_material.cli import main
from granular_material.dem.rve.file import RVEData, load_rve, save_rve

R_MIN, R_MAX = 3e-3, 7e-3  # radii of Wu et al. 2025, Table 1 (docs/design.md#wu-2025)


def random_packing(
    n_disc: int, porosity: float, seed: int, max_iter: int = 2000
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random non-overlapping periodic packing in a square cell (test data, not a DEM).

    Discs with radii uniform in [3, 7] mm are dropped at random in a cell sized for
    ``porosity`` and pushed apart pairwise (minimum image) until no two overlap.

    Returns radius (N,) [m], position (N, 2) [m] inside the cell, cell (2, 2) [m].
    """
    rng = np.random.default_rng(seed)
    radius = rng.uniform(R_MIN, R_MAX, n_disc)
    side = np.sqrt(np.pi * (radius**2).sum() / (1.0 - porosity))
    frac = rng.random((n_disc, 2))
    i, j = np.triu_indices(n_disc, 1)
    contact = radius[i] + radius[j]
    for _ in range(max_iter):
        d = frac[i] - frac[j]
        d -= np.round(d)
        dist = side * np.sqrt((d**2).sum(axis=1))
        if (contact - dist).max() < 0:
            break
        gap = 1.002 * contact - dist  # aim slightly apart so the loop ends
        hit = gap > 0
        push = (0.5 * gap[hit] / dist[hit])[:, None] * d[hit]
        delta = np.zeros((n_disc, 2))
        np.add.at(delta, i[hit], push)
        np.add.at(delta, j[hit], -push)
        frac += delta
    else:
        raise RuntimeError("packing did not separate")
    frac -= np.floor(frac)
    return radius, frac * side, np.diag([side, side])


def as_rve_data(radius, position, cell) -> RVEData:
    """A batch of RVEs from stacked arrays (B, N), (B, N, 2), (B, 2, 2), at rest."""
    radius, position, cell = np.asarray(radius), np.asarray(position), np.asarray(cell)
    return RVEData(
        radius=radius, position=position, cell=cell,
        velocity=np.zeros_like(position), angular_velocity=np.zeros_like(radius),
    )


@pytest.fixture(scope="module")
def packing():
    """400 discs (Wu et al.'s RVE size), porosity 0.3, seed 7."""
    return random_packing(400, 0.3, seed=7)


@pytest.fixture(scope="module")
def rve_file(tmp_path_factory, packing):
    """A batch file of two RVEs: the packing above and a second one (seed 8)."""
    other = random_packing(400, 0.3, seed=8)
    data = as_rve_data(*(np.stack([a, b]) for a, b in zip(packing, other, strict=True)))
    path = tmp_path_factory.mktemp("pore_fractal") / "rve.npz"
    save_rve(path, data)
    return path


def brute_force_pores(radius, position, cell, n, pixel, origin=(0.0, 0.0), reach=3):
    """Pore mask by testing every pixel centre against every periodic image with
    |n1|, |n2| ≤ reach, no wrapping, no bounding boxes: an independent reference."""
    offsets = (np.arange(n) + 0.5) * pixel
    px, py = np.meshgrid(origin[0] + offsets, origin[1] + offsets)  # rows along y
    pts = np.stack([px.ravel(), py.ravel()], axis=1)
    covered = np.zeros(pts.shape[0], dtype=bool)
    span = range(-reach, reach + 1)
    lattice = np.array([[a, b] for a in span for b in span])
    for r, x in zip(radius, position, strict=True):
        images = x + lattice @ np.asarray(cell).T
        d2 = ((pts[:, None, :] - images[None, :, :]) ** 2).sum(axis=2)
        covered |= (d2 <= r * r).any(axis=1)
    return ~covered.reshape(n, n)


def test_choose_window_picks_the_pixel_nearest_the_request():
    # 0.2 m cell: 0.2/0.3e-3 = 667 px; sides 512 (0.391 mm) or 768 (0.260 mm): 768 is nearer
    n, pixel = choose_window(np.diag([0.2, 0.2]))
    assert (n, pixel) == (768, pytest.approx(0.2 / 768, rel=1e-15))
    # 0.1 m: 256 px (0.391 mm, off by 0.091) beats 512 px (0.195 mm, off by 0.105)
    assert choose_window(np.diag([0.1, 0.1]))[0] == 256
    # a sheared cell: the window has the cell's area, det H = 0.2 · 0.18
    n, pixel = choose_window(np.array([[0.2, 0.05], [0.0, 0.18]]))
    assert n * pixel == pytest.approx(np.sqrt(0.2 * 0.18), rel=1e-14)
    assert n % 256 == 0
    # never fewer than one block, however small the cell
    assert choose_window(np.diag([0.01, 0.01]))[0] == 256
    assert choose_window(np.diag([0.2, 0.2]), multiple_of=64)[0] == 64 * 10  # 0.2/640 = 0.31 mm
    with pytest.raises(ValueError, match="pixel_size"):
        choose_window(np.eye(2), pixel_size=-1.0)
    with pytest.raises(ValueError, match="area"):
        choose_window(np.array([[1.0, 1.0], [1.0, 1.0]]))


def test_single_disc_matches_brute_force_across_the_corner():
    # a disc centred on the cell corner shows as four quarter discs in the window
    cell = np.diag([0.05, 0.05])
    radius, position = np.array([6e-3]), np.array([[0.0005, 0.0499]])
    n, pixel = 128, 0.05 / 128
    got = rasterize_pores(radius, position, cell, n, pixel)
    np.testing.assert_array_equal(got, brute_force_pores(radius, position, cell, n, pixel))
    assert (~got[0, 0]) and (~got[-1, 0]) and got[n // 2, n // 2]


def test_sheared_cell_matches_brute_force():
    # a general cell (both off-diagonals non-zero), discs may overlap: coverage is exact
    rng = np.random.default_rng(11)
    cell = np.array([[0.08, 0.035], [0.012, 0.07]])
    radius = rng.uniform(R_MIN, R_MAX, 30)
    position = rng.random((30, 2)) @ cell.T
    n, pixel = 128, np.sqrt(np.linalg.det(cell)) / 128
    origin = (-0.013, 0.021)
    got = rasterize_pores(radius, position, cell, n, pixel, origin)
    want = brute_force_pores(radius, position, cell, n, pixel, origin)
    np.testing.assert_array_equal(got, want)
    assert 0.05 < got.mean() < 0.95  # the comparison is not trivial


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_pixels": 0}, "n_pixels"),
        ({"pixel_size": 0.0}, "pixel_size"),
        ({"radius": np.array([-1e-3])}, "radius"),
        ({"cell": np.diag([0.05, -0.05])}, "area"),
        ({"position": np.zeros((2, 2))}, "position"),
    ],
)
def test_rasterize_rejects_bad_input(kwargs, match):
    args = {"radius": np.array([5e-3]), "position": np.array([[0.01, 0.02]]),
            "cell": np.diag([0.05, 0.05]), "n_pixels": 64, "pixel_size": 0.05 / 64, **kwargs}
    with pytest.raises(ValueError, match=match):
        rasterize_pores(**args)


def test_translation_by_whole_pixels_rolls_the_image(packing):
    # for a square cell the window is one period: moving every disc by (17, −40) pixels
    # rolls the image by the same amount, wrapping across the cell boundary
    radius, position, cell = packing
    image = pore_image(radius, position, cell)
    shift = np.array([17, -40]) * image.pixel_size
    moved = pore_image(radius, position + shift, cell)
    np.testing.assert_array_equal(moved.pore, np.roll(image.pore, (-40, 17), axis=(0, 1)))


def test_lattice_shift_gives_the_same_image_and_spectrum():
    # a sheared cell; discs moved by the lattice vector H·(3, −2), or the window moved by
    # H·(−1, 2): the periodic medium is the same, so is every pixel and the spectrum
    rng = np.random.default_rng(5)
    radius, position, square = random_packing(100, 0.35, seed=5)
    cell = square @ np.array([[1.0, 0.3], [0.0, 1.0]])  # simple shear γ = 0.3
    position = position @ np.array([[1.0, 0.0], [0.3, 1.0]])  # affine map of the centres
    base = pore_image(radius, position, cell, multiple_of=128)
    shifted = pore_image(radius, position + cell @ np.array([3, -2]), cell, multiple_of=128)
    np.testing.assert_array_equal(shifted.pore, base.pore)
    moved = pore_image(radius, position, cell, multiple_of=128, origin=cell @ np.array([-1, 2]))
    np.testing.assert_array_equal(moved.pore, base.pore)
    a = multifractal_spectrum(base.pore, k=range(1, 8))
    b = multifractal_spectrum(shifted.pore, k=range(1, 8))
    np.testing.assert_array_equal(a.Dq, b.Dq)
    assert a.alpha0 == b.alpha0 and a.D0 == b.D0
    # a shift that is not a lattice vector does change the image
    other = pore_image(radius, position + rng.random(2) * 0.01, cell, multiple_of=128)
    assert (other.pore != base.pore).any()


def test_image_porosity_matches_the_rve(packing):
    radius, position, cell = packing
    image = pore_image(radius, position, cell)
    assert image.n_pixels == 768 and image.pore.dtype == bool
    assert image.rve_porosity == pytest.approx(0.3, abs=1e-12)  # built for porosity 0.3
    assert image.rve_porosity == pytest.approx(rve_porosity(radius, cell), abs=1e-15)
    # pixel-centre sampling of ~400 disc edges at 0.28 mm: a sampling error, not a bias,
    # measured 9e-5 for this seed; 2e-3 would flag a lost disc (one 5 mm disc is 1.7e-3)
    assert image.porosity == pytest.approx(image.rve_porosity, abs=2e-3)


def test_postprocessor_entry_point(packing, rve_file):
    (ep,) = [e for e in entry_points(group="granular_material.postprocessors")
             if e.name == "pore-fractal"]
    assert ep.load() is pore_fractal
    data = load_rve(rve_file)
    result = pore_fractal(data)
    n, pixel = choose_window(packing[2])
    assert result["image_size"] == n == 768
    assert result["pixel_size"] == pytest.approx(pixel, rel=1e-15)
    for key in ("D0", "alpha0", "alpha0_over_D0", "porosity", "pixel_size", "image_size"):
        assert np.isfinite(result[key]), key
    # the pore space has positive area but fits over finite box sizes: 1 < D0 < 2
    assert 1.0 < result["D0"] < 2.0
    assert result["alpha0"] >= result["D0"]
    assert result["alpha0_over_D0"] == pytest.approx(result["alpha0"] / result["D0"])
    second = pore_fractal(data, rve_index=1)
    assert second["D0"] != result["D0"]
    batch = pore_images(data)
    assert [im.n_pixels for im in batch] == [768, 768]
    assert batch[1].porosity == pytest.approx(second["porosity"], abs=0)
    with pytest.raises(ValueError, match="out of range"):
        pore_fractal(data, rve_index=2)


def test_cli_json_matches_the_postprocessor(rve_file, capsys):
    assert main(["fractal", str(rve_file), "--json", "--rve-index", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    expected = pore_fractal(load_rve(rve_file), rve_index=1)
    for key, value in expected.items():
        assert out[key] == pytest.approx(value, rel=1e-15), key
    assert out["rve_index"] == 1
    assert isinstance(out["poor_fit_q"], list)


def test_cli_text_and_plot(rve_file, tmp_path, capsys):
    png = tmp_path / "spectrum.png"
    assert main(["fractal", str(rve_file), "--plot", str(png), "--q-step", "1"]) == 0
    text = capsys.readouterr().out
    assert "D0" in text and "alpha0/D0" in text and "porosity" in text
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--rve-index", "5"], "out of range"),
        (["--pixel=-1e-3"], "--pixel"),
        (["--q-step", "0"], "--q-step"),
        (["--k-max", "1"], "--k-max"),
    ],
)
def test_cli_bad_input_exits_2(rve_file, capsys, extra, message):
    assert main(["fractal", str(rve_file), *extra]) == 2
    assert message in capsys.readouterr().err


def test_cli_missing_file_exits_2(tmp_path, capsys):
    assert main(["fractal", str(tmp_path / "none.npz")]) == 2
    assert "none.npz" in capsys.readouterr().err


def test_cli_help(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["fractal", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for option in ("--pixel", "--plot", "--json", "--rve-index"):
        assert option in text
