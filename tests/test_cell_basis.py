"""A sheared periodic cell re-described by its lattice's least skewed basis
(granular_material.dem.cell_basis): the same packing, and an RVE that shears on past the
engine's limit on its cell's height instead of failing there."""

from __future__ import annotations

import numpy as np
import pytest

from granular_material.dem import DEMBatch, load_rve
from granular_material.dem.cell_basis import reduced_basis
from granular_material.dem.model import cell_heights
from granular_material.multiscale import backend
from granular_material.multiscale.material import DEMMaterial


def _unimodular(rng: np.random.Generator, shears: int) -> np.ndarray:
    m = np.eye(2, dtype=np.int64)
    for _ in range(shears):
        e = np.eye(2, dtype=np.int64)
        i = int(rng.integers(2))
        e[i, 1 - i] = int(rng.integers(-3, 4))
        m = m @ e
    return m


@pytest.mark.parametrize("seed", range(12))
def test_the_reduced_basis_spans_the_same_lattice_with_its_largest_heights(seed):
    rng = np.random.default_rng(seed)
    lattice = np.array([[0.1, 0.05], [0.0, 0.09]]) * rng.uniform(0.5, 2.0)
    cell = lattice @ _unimodular(rng, 6)
    reduced, change = reduced_basis(cell)
    assert np.round(np.linalg.det(change)) == 1 and change.dtype.kind == "i"
    np.testing.assert_allclose(reduced, cell @ change, rtol=0, atol=1e-15)
    best = cell_heights(reduced_basis(lattice)[0])
    assert cell_heights(reduced) == pytest.approx(best, rel=1e-9)
    assert cell_heights(reduced) >= cell_heights(cell) * (1 - 1e-12)
    h1, h2 = reduced[:, 0], reduced[:, 1]
    assert h1 @ h1 <= h2 @ h2 * (1 + 1e-12) and abs(h1 @ h2) <= (0.5 + 1e-9) * (h1 @ h1)
    _, same = reduced_basis(reduced)  # a reduced basis is its own
    np.testing.assert_array_equal(same, np.eye(2, dtype=np.int64))


def _shear_on(path, increments: int, step: float) -> list[dict]:
    """Simple shear of an RVE in committed increments of ``step``: each increment's reasons,
    its cell's height against twice the cut-off, whether the commit re-described the cell,
    and how far the commit moved the Love stress of the unstepped state (relative)."""
    material = DEMMaterial(rve=path, device="cpu", max_strain_per_step=1e-4,
                           max_dem_steps=None)
    material.allocate(1)
    batch = material.backend.batch
    grad = np.array([[[0.0, step], [0.0, 0.0]]])
    out = []
    for _ in range(increments):
        response = material.evaluate(grad)
        row = {"reasons": response.reasons.tolist(),
               "height": float(cell_heights(batch.cell())[0] / (2 * batch.cutoff[0]))}
        out.append(row)
        if not response.ok:
            break
        cell, stress = batch.cell()[0], batch.homogenize().stress[0]
        material.commit()
        row["rebased"] = not np.array_equal(batch.cell()[0], cell)
        row["stress_moved"] = float(np.abs(batch.homogenize().stress[0] - stress).max()
                                    / np.abs(stress).max())
    return out


def test_an_rve_shears_past_its_cells_limit_where_it_used_to_stop(small_rve_path, monkeypatch):
    data = load_rve(small_rve_path)
    side = float(np.sqrt(abs(np.linalg.det(data.cell[0]))))
    cutoff = float(DEMBatch(data, device="cpu").cutoff[0])
    limit = float(np.sqrt((side / (2 * cutoff)) ** 2 - 1))  # simple shear γ at the limit
    step = 0.1
    increments = int(np.ceil(limit / step)) + 5
    rebased = _shear_on(small_rve_path, increments, step)
    assert all(row["reasons"] == [""] for row in rebased)
    assert min(row["height"] for row in rebased) > 1.0  # always above the engine's limit
    assert any(row["rebased"] for row in rebased)
    assert max(row["stress_moved"] for row in rebased) < 1e-12  # the same packing
    with monkeypatch.context() as m:  # never rebased: refused as a thin cell, no blow-up
        m.setattr(backend, "REBASE_MARGIN", 0.0)
        stopped = _shear_on(small_rve_path, increments, step)
    assert stopped[-1]["reasons"] == ["cell_too_thin"]
    assert not any(row.get("rebased") for row in stopped)
    assert limit - 2 * step < step * len(stopped) <= limit + 2 * step


@pytest.mark.parametrize(("dtype", "rtol"), [("float64", 1e-12), ("float32", 1e-5)])
def test_rebasing_a_batch_keeps_its_stress_and_fractions_in_the_unit_square(small_rve_path,
                                                                            dtype, rtol):
    batch = DEMBatch(load_rve(small_rve_path), device="cpu", dtype=dtype)
    # a sheared cell (the discs keep their fractions: another packing, a valid one), whose
    # basis is not the reduced one of its lattice
    batch.set_cell(batch.cell() @ np.array([[1.0, 0.8], [0.0, 1.0]]))
    before = batch.homogenize().stress[0]
    heights = cell_heights(batch.cell()[0])
    assert batch.rebase_cells(np.array([True])).tolist() == [True]
    assert cell_heights(batch.cell()[0]) > 1.1 * heights
    np.testing.assert_allclose(batch.homogenize().stress[0], before, rtol=rtol,
                               atol=rtol * np.abs(before).max())
    fractions = batch.to_data().extra["fractional_position"]
    assert fractions.min() >= 0.0 and fractions.max() < 1.0
    batch.run(50)  # steps on, its lists rebuilt for the new basis
    assert batch.rebase_cells(np.array([True])).tolist() == [False]  # reduced already
