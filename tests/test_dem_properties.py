"""Invariants of the DEM engine: energy, objectivity, batch independence, exact resume."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from granular_material.dem import DEMBatch, RVEMeta, load_rve, save_rve
from granular_material.procedures import drive_grad_u, random_gas


def _overlaps(data) -> np.ndarray:
    """Overlap [m] of every pair of discs of RVE 0 (minimum image), shape (N, N)."""
    r = data.radius[0]
    cell = data.cell[0]
    frac = np.linalg.solve(cell, data.position[0].T).T
    ds = frac[None, :, :] - frac[:, None, :]
    ds -= np.round(ds)
    dist = np.linalg.norm(ds @ cell.T, axis=2)
    overlap = np.clip(r[:, None] + r[None, :] - dist, 0.0, None)
    np.fill_diagonal(overlap, 0.0)
    return overlap


def _energy(batch: DEMBatch) -> float:
    """Kinetic + rotational + normal-spring energy [J] of RVE 0 (frictionless, fixed cell)."""
    data = batch.to_data()
    meta = data.meta
    r = data.radius[0]
    m = meta.density * meta.thickness * math.pi * r**2
    kinetic = 0.5 * np.sum(m * np.sum(data.velocity[0] ** 2, axis=1))
    kinetic += 0.5 * np.sum(0.5 * m * r**2 * data.angular_velocity[0] ** 2)
    overlap = _overlaps(data)
    potential = 0.5 * 0.5 * meta.stiffness["kn"] * np.sum(overlap**2)  # each pair twice
    return float(kinetic + potential)


def test_energy_drift_bounded_without_damping():
    meta = RVEMeta(friction_angle=0.0, damping=0.0)
    gas = random_gas(n_disc=60, seed=7, solid_fraction=0.5, meta=meta)
    rng = np.random.default_rng(0)
    gas = replace(gas, velocity=rng.normal(0.0, 0.5, size=gas.velocity.shape))
    batch = DEMBatch(gas, device="cpu")
    e0 = _energy(batch)
    batch.set_affine(np.zeros((1, 2, 2)))
    energies = []
    for _ in range(10):
        batch.run(300)
        energies.append(_energy(batch))
    drift = np.abs(np.array(energies) - e0).max() / e0
    assert drift < 5e-3, f"energy drift {drift:.2e}"


def _rotation(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def test_rigid_rotation_rotates_the_stress(small_rve_path):
    """Objectivity: ∇u = R − I leaves the stress unchanged in the rotated frame."""
    batch = DEMBatch(load_rve(small_rve_path), device="cpu")
    sigma0 = batch.homogenize().stress[0]
    rot = _rotation(0.15)
    drive_grad_u(batch, rot - np.eye(2))
    sigma = batch.homogenize().stress[0]
    p0 = -0.5 * np.trace(sigma0)
    np.testing.assert_allclose(rot.T @ sigma @ rot, sigma0, atol=0.01 * p0)
    np.testing.assert_allclose(batch.cell()[0], rot @ load_rve(small_rve_path).cell[0],
                               rtol=1e-12)


def test_copies_in_a_batch_are_identical_and_independent(small_rve_path):
    one = load_rve(small_rve_path)
    grads = np.array([[[0.0, 2e-3], [0.0, 0.0]], [[-1e-3, 0.0], [0.0, 1e-3]],
                      [[0.0, 2e-3], [0.0, 0.0]]])
    batch = DEMBatch(one.replicate(3), device="cpu")
    drive_grad_u(batch, grads)
    stress = batch.homogenize().stress
    # copies 0 and 2 got the same path: bit-identical
    assert np.array_equal(stress[0], stress[2])
    # RVE 0 alone gives exactly what it gave beside its neighbours
    alone = DEMBatch(one, device="cpu")
    drive_grad_u(alone, grads[0])
    assert np.array_equal(alone.homogenize().stress[0], stress[0])
    assert not np.allclose(stress[1], stress[0])


def test_snapshot_restore_and_file_resume_are_exact(small_rve_path, tmp_path):
    batch = DEMBatch(load_rve(small_rve_path), device="cpu")
    grad = np.array([[0.0, 1e-3], [0.0, -5e-4]])
    snap = batch.snapshot()
    drive_grad_u(batch, grad)
    first = batch.homogenize().stress.copy()
    batch.restore(snap)
    drive_grad_u(batch, grad)
    assert np.array_equal(batch.homogenize().stress, first)
    # save mid-path, reload, continue: identical to continuing in memory
    save_rve(tmp_path / "mid.npz", batch.to_data())
    resumed = DEMBatch(load_rve(tmp_path / "mid.npz"), device="cpu")
    drive_grad_u(batch, grad)
    drive_grad_u(resumed, grad)
    np.testing.assert_array_equal(resumed.homogenize().stress, batch.homogenize().stress)


def test_consolidated_packing_is_at_p0_and_love_stress_symmetric(small_rve_path):
    batch = DEMBatch(load_rve(small_rve_path), device="cpu")
    h = batch.homogenize()
    # the engine's contacts are the overlapping pairs of a brute-force minimum-image search
    assert h.n_contacts[0] == np.count_nonzero(_overlaps(batch.to_data())) // 2
    sigma = h.stress[0]
    # consolidation target 100 kPa, tolerance 1 % on each diagonal component
    assert sigma[0, 0] == pytest.approx(-100e3, rel=0.01)
    assert sigma[1, 1] == pytest.approx(-100e3, rel=0.01)
    # at equilibrium the moment balance of every disc makes Love's stress symmetric
    assert abs(sigma[0, 1] - sigma[1, 0]) < 2e-3 * 100e3
    assert h.unbalanced_force[0] < 0.02
    # dense, frictionless-prepared packing: e close to Guo & Zhao's 0.175
    # (docs/design.md#yade-anchors)
    assert 0.12 < h.void_ratio[0] < 0.22
    assert 3.5 < h.coordination[0] < 4.6


def test_tangent_predicts_a_small_strain_increment(small_rve_path):
    """KR tangent is the affine (upper-bound) stiffness: same sign and order as the response."""
    batch = DEMBatch(load_rve(small_rve_path), device="cpu")
    h0 = batch.homogenize()
    grad = np.array([[-2e-5, 0.0], [0.0, 0.0]])
    drive_grad_u(batch, grad, max_strain_per_step=1e-6)
    d_sigma = batch.homogenize().stress[0] - h0.stress[0]
    predicted = np.einsum("ijkl,kl->ij", h0.tangent[0], grad)
    assert predicted[0, 0] < 0 and d_sigma[0, 0] < 0
    assert 0.2 < d_sigma[0, 0] / predicted[0, 0] <= 1.05
    # major symmetry C_ijkl = C_klij of the KR form
    c = h0.tangent[0]
    np.testing.assert_allclose(c, c.transpose(2, 3, 0, 1), rtol=1e-12)


def test_float32_agrees_with_float64(small_rve_path):
    data = load_rve(small_rve_path)
    grad = np.array([[0.0, 1e-3], [0.0, 0.0]])
    results = []
    for dtype in ("float64", "float32"):
        batch = DEMBatch(data, device="cpu", dtype=dtype)
        drive_grad_u(batch, grad)
        results.append(batch.homogenize().stress[0])
    np.testing.assert_allclose(results[1], results[0], atol=0.02 * 100e3)


def test_target_void_ratio_is_reached_then_held_at_p0():
    """Wu et al. (2025): compact to e0, then consolidate at p0 = 100 kPa."""
    from granular_material.procedures import prepare_packing

    batch = prepare_packing(n_disc=100, seed=11, pressure=100e3, target_void_ratio=0.2,
                            device="cpu")
    h = batch.homogenize()
    assert h.void_ratio[0] == pytest.approx(0.2, abs=0.01)
    assert h.mean_stress[0] == pytest.approx(-100e3, rel=0.01)


def test_parallel_shards_are_safe_and_change_nothing(small_rve_path):
    """Two CPU shards step in two threads (each with its own kernel module): many short
    parallel runs must neither crash the interpreter nor differ from one shard."""
    data = load_rve(small_rve_path).replicate(6)
    grad = np.array([[0.0, 1e-3], [0.0, 0.0]])
    results = []
    for shards in (1, 2):
        batch = DEMBatch(data, device="cpu", shards=shards)
        assert len(batch.lanes) == shards
        for _ in range(20):
            drive_grad_u(batch, grad / 20)
        results.append(batch.homogenize().stress)
    np.testing.assert_array_equal(results[0], results[1])


def test_friction_change_keeps_the_servo_loading(small_rve_path):
    """set_friction replaces the model only: a servo set before it still drives the cell."""
    data = load_rve(small_rve_path)
    batch = DEMBatch(data, device="cpu")
    reference = DEMBatch(data, device="cpu")
    target = np.array([[-100e3, -2e-5]])  # sxx held, eyy compressed 2e-5 a step
    control = np.array([[1, 0]])
    for b in (batch, reference):
        b.set_servo(control, target, gain=0.5, max_strain=1e-4)
    batch.set_friction(data.meta.friction_angle)  # same value: nothing may change
    batch.run(300)
    reference.run(300)
    np.testing.assert_array_equal(batch.cell(), reference.cell())
    assert batch.cell()[0, 1, 1] < data.cell[0, 1, 1] * (1 - 300 * 1.9e-5)


def test_each_pair_is_one_contact_with_one_history(small_rve_path):
    """A pair appears in both lists and, written to a file, carries one tangential force."""
    batch = DEMBatch(load_rve(small_rve_path), device="cpu")
    batch.set_affine(np.array([[[0.0, 2e-5 / batch.dt[0]], [0.0, 0.0]]]))
    batch.run(400)
    extra = batch.to_data().extra
    partner, count = extra["contact_partner"][0], extra["contact_count"][0]
    shear = extra["contact_shear_force"][0]
    pairs = {}
    for i in range(partner.shape[0]):
        for k in range(count[i]):
            pairs.setdefault(frozenset((i, int(partner[i, k]))), []).append(shear[i, k])
    assert all(len(forces) == 2 for forces in pairs.values())
    assert all(forces[0] == forces[1] for forces in pairs.values())
    assert sum(1 for forces in pairs.values() if forces[0] != 0.0) > len(pairs) // 4


def test_a_thread_stepping_several_shards_changes_nothing(small_rve_path, monkeypatch):
    """Small CPU shards (several a thread, stepped one after the other) give the same
    result as one shard holding the batch."""
    import granular_material.dem.batch as batch_module

    data = load_rve(small_rve_path).replicate(5)
    grad = np.array([[2e-4, 1e-3], [0.0, -5e-4]])
    one = DEMBatch(data, device="cpu", shards=1)
    monkeypatch.setattr(batch_module, "CPU_SHARD_DISCS", data.n_disc)  # one RVE a shard
    many = DEMBatch(data, device="cpu", shards=2)
    assert len(many.shards) == 5 and [len(lane) for lane in many.lanes] == [3, 2]
    for batch in (one, many):
        drive_grad_u(batch, grad)
    np.testing.assert_array_equal(one.homogenize().stress, many.homogenize().stress)
    np.testing.assert_array_equal(one.to_data().position, many.to_data().position)


def test_cpu_graph_replay_matches_step_by_step(small_rve_path):
    """Blocks of steps replayed from the captured graph (rebuilds under their condition)
    give exactly what the same steps launched one at a time give."""
    data = load_rve(small_rve_path).replicate(2)
    shear = np.array([[0.0, 4e-5], [0.0, -2e-5]])  # strain a step: the lists get rebuilt
    runs = []
    for chunk in (475, 1):
        batch = DEMBatch(data, device="cpu", shards=1)
        batch.set_affine(np.repeat(shear[None], 2, axis=0) / batch.dt[:, None, None])
        for _ in range(475 // chunk):
            batch.run(chunk)
        runs.append(batch.to_data())
    assert not np.array_equal(runs[0].extra["cell_at_list_build"], data.cell)  # rebuilt
    for key in ("position", "velocity", "angular_velocity", "cell"):
        np.testing.assert_array_equal(getattr(runs[0], key), getattr(runs[1], key))
    for key in ("contact_partner", "contact_count", "contact_shear_force"):
        np.testing.assert_array_equal(runs[0].extra[key], runs[1].extra[key])
