"""Contact law against closed forms: normal spring, stick-slip, periodic images."""

from __future__ import annotations

import math

import numpy as np
import pytest

from granular_material.dem import DEMBatch


def _force_on_b(batch: DEMBatch) -> np.ndarray:
    """Contact force on disc 1 [N] from one step's velocity change, damping off."""
    v0 = batch.shards[0].state.velocity.numpy().copy()
    batch.set_affine(np.zeros((1, 2, 2)))
    batch.run(1)
    dv = batch.shards[0].state.velocity.numpy() - v0
    model = batch.shards[0].model
    meta = model.meta
    m = meta.density * meta.thickness * math.pi * model.radius[0] ** 2
    return dv[1] * m[1] / batch.dt[0]


def test_two_disc_normal_force_is_kn_times_overlap(two_discs):
    overlap = 2e-4
    data = two_discs((0.05, 0.1), (0.06 - overlap, 0.1), damping=0.0)
    batch = DEMBatch(data, device="cpu")
    kn = data.meta.stiffness["kn"]
    h = batch.homogenize()
    branch = 0.01 - overlap
    volume = 0.2 * 0.2 * data.meta.thickness
    # Love: sigma_xx = -(1/V) f d with f = kn * overlap (tension positive)
    assert h.stress[0, 0, 0] == pytest.approx(-kn * overlap * branch / volume, rel=1e-12)
    assert h.stress[0, 1, 1] == pytest.approx(0.0, abs=1e-9)
    force = _force_on_b(batch)
    assert force[0] == pytest.approx(kn * overlap, rel=1e-12)
    assert force[1] == pytest.approx(0.0, abs=1e-9)


def test_frictmat_stiffness_follows_radii(two_discs):
    # docs/design.md#guo-zhao-rve: kn = 2 E r1 r2 / (r1 + r2) = 3e6 N/m for two 5 mm discs,
    # E = 6e8 Pa
    overlap = 1e-4
    data = two_discs((0.05, 0.1), (0.06 - overlap, 0.1), damping=0.0,
                     stiffness={"law": "frictmat", "young": 6e8, "kt_over_kn": 0.8})
    force = _force_on_b(DEMBatch(data, device="cpu"))
    assert force[0] == pytest.approx(3e6 * overlap, rel=1e-12)


def test_stick_then_slip_follows_coulomb(two_discs):
    """Discs sheared past each other: fs grows by kt·α·v·dt a step, then stays at tan(φ)·kn·δ;
    α = (r_a + r_c)/|d| scales the centres' relative velocity to the contact (YADE's ScGeom
    with avoidGranularRatcheting, which makes a rigid rotation objective)."""
    overlap, v_t, dt = 1e-4, 0.1, 1e-4
    data = two_discs((0.05, 0.1), (0.06 - overlap, 0.1), damping=0.0, density=1e9,
                     timestep=dt, friction_angle=0.5)
    vel = np.array([[[0.0, -v_t / 2], [0.0, v_t / 2]]])
    data = type(data)(**{**data.__dict__, "velocity": vel})
    batch = DEMBatch(data, device="cpu")
    kn, kt = data.meta.stiffness["kn"], data.meta.stiffness["kt"]
    cap = math.tan(0.5) * kn * overlap
    batch.set_affine(np.zeros((1, 2, 2)))
    history = []
    for _ in range(12):
        batch.run(1)
        history.append(batch.shards[0].state.contact_shear_force.numpy()[0])
    history = np.array(history)
    alpha = 0.01 / (0.01 - overlap)  # (r_a + r_c) / |d|, radii 5 mm
    stick = np.arange(1, 13) * kt * alpha * v_t * dt
    n_stick = int(np.sum(stick < cap * 0.98))
    assert n_stick >= 5
    np.testing.assert_allclose(history[:n_stick], stick[:n_stick], rtol=2e-3)
    # slipping: capped at mu * kn * current overlap (overlap changes by < 1 % here)
    np.testing.assert_allclose(history[n_stick + 1:], cap, rtol=1e-2)
    assert batch.homogenize().sliding_fraction[0] == 1.0


def _expected_love_xx(cell: np.ndarray, x_a, x_b, radius: float, kn: float, t: float):
    """Minimal-image branch over the 9 nearest lattice images and the Love stress."""
    best = None
    for i in (-1, 0, 1):
        for j in (-1, 0, 1):
            d = np.asarray(x_b) + cell @ np.array([i, j]) - np.asarray(x_a)
            if best is None or np.linalg.norm(d) < np.linalg.norm(best):
                best = d
    dist = np.linalg.norm(best)
    n = best / dist
    f_a = -kn * (2 * radius - dist) * n
    return np.outer(f_a, best) / (np.linalg.det(cell) * t)


@pytest.mark.parametrize("shear", [0.0, 0.4, 1.0])
def test_contact_across_periodic_boundary(two_discs, shear):
    """Discs touching through the cell's top/bottom edge, in a square and sheared cells."""
    side = 0.1
    cell = np.array([[side, shear * side], [0.0, side]])
    # disc b sits 9 mm straight below disc a, i.e. in the image across the s1 = 0 edge
    x_a = cell @ np.array([0.3, 0.02])
    s_b = np.linalg.solve(cell, x_a + np.array([0.0, -0.009]))
    x_b = cell @ (s_b - np.floor(s_b))
    assert x_b[1] > 0.5 * side  # stored on the far side of the cell
    data = two_discs(tuple(x_a), tuple(x_b), cell=cell, damping=0.0)
    batch = DEMBatch(data, device="cpu")
    h = batch.homogenize()
    expected = _expected_love_xx(cell, x_a, x_b, 5e-3, data.meta.stiffness["kn"], 0.1)
    assert h.n_contacts[0] == 1
    assert np.abs(expected).max() > 1e3  # they do overlap through the boundary
    np.testing.assert_allclose(h.stress[0], expected, rtol=1e-10, atol=1e-6)


def _brute_force_contacts(radius: np.ndarray, frac: np.ndarray, cell: np.ndarray) -> int:
    """Overlapping pairs over the 9 nearest lattice images, by plain numpy."""
    count = 0
    shifts = [np.array([i, j]) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    for a in range(len(radius)):
        for b in range(a + 1, len(radius)):
            dist = min(np.linalg.norm(cell @ (frac[b] + s - frac[a])) for s in shifts)
            count += dist < radius[a] + radius[b]
    return count


@pytest.mark.parametrize("shear", [0.0, 0.5, 1.0])
def test_binned_detection_finds_every_contact_in_sheared_cells(small_rve_path, shear):
    """Shear the cell of a dense packing (fractional coordinates kept): the binned search
    finds exactly the overlapping pairs a brute-force minimum-image search finds."""
    from granular_material.dem import load_rve

    data = load_rve(small_rve_path)
    batch = DEMBatch(data, device="cpu")
    cell = data.cell[0].copy()
    cell[0, 1] = shear * cell[1, 1]
    batch.set_cell(cell[None])
    h = batch.homogenize()
    frac = batch.shards[0].state.fractional_position.numpy()
    expected = _brute_force_contacts(data.radius[0], frac, cell)
    assert expected > 50
    assert h.n_contacts[0] == expected
