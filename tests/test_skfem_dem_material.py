"""The scikit-fem DEM material: engine equivalence, commit/revert, single-element agreement.

Smoke scale: RVEs of 100 discs (the session fixture ``small_rve_path``, seed 3). Batches use
the default CPU sharding (one thread per core), which never changes a result.
"""

from __future__ import annotations

import numpy as np
import pytest

from granular_material.dem import DEMBatch, DEMInstabilityError, RVEFileError, RVEMeta, load_rve
from granular_material.dem.homogenization import objective_tangent
from granular_material.fem import (
    BiaxialSetup,
    NewtonSettings,
    PointStatus,
    create_material,
)
from granular_material.multiscale import DEMMaterial
from granular_material.procedures import PackingParameters, biaxial_test, drive_grad_u
from granular_material.results import summarize_biaxial
from granular_material.runs import run_biaxial

GRAD = np.array([
    [[0.0, 0.0], [0.0, -2e-4]],
    [[1e-4, 5e-5], [-5e-5, -3e-4]],
    [[-1e-4, 2e-4], [0.0, 1e-4]],
    [[0.0, -1e-4], [1e-4, 0.0]],  # a rigid rotation
])


@pytest.fixture
def material(small_rve_path) -> DEMMaterial:
    m = create_material("dem", rve=small_rve_path, device="cpu")
    m.allocate(4)
    return m


def test_packing_parameters_are_checked_where_built():
    """The RVE material the material prepares is checked when its parameters are built:
    radii, target void ratio, the meta, and the fewest discs for the radii given."""
    with pytest.raises(ValueError, match=r"r_min = 0\.005 exceeds r_max = 0\.003"):
        PackingParameters(radius_range=(5e-3, 3e-3))
    with pytest.raises(ValueError, match="target_void_ratio"):
        PackingParameters(target_void_ratio=0.0)
    with pytest.raises(RVEFileError, match=r"meta\.damping"):
        PackingParameters(meta=RVEMeta(damping=1.0))
    wide = PackingParameters(radius_range=(3e-3, 2e-2))
    DEMMaterial(particles=12)  # the fewest for 3-7 mm radii
    with pytest.raises(ValueError, match="particles must be an integer >= "):
        DEMMaterial(particles=12, packing=wide)


def test_entry_point_builds_the_dem_material(material):
    assert isinstance(material, DEMMaterial)
    assert material.n_points == 4 and material.committed_rves().n_disc == 100


def test_stress_and_tangent_equal_the_engine(material, small_rve_path):
    response = material.evaluate(GRAD)
    batch = DEMBatch(load_rve(small_rve_path).replicate(4), device="cpu")
    steps = drive_grad_u(batch, GRAD)
    h = batch.homogenize()
    # the material returns the Love stress symmetrised, its skew part as a field, and the
    # objective tangent of the engine's Kruyt–Rothenburg one
    symmetric = 0.5 * (h.stress + np.swapaxes(h.stress, 1, 2))
    np.testing.assert_allclose(response.stress, symmetric, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(response.fields["stress_skew"],
                               0.5 * (h.stress[:, 0, 1] - h.stress[:, 1, 0]), atol=1e-9)
    np.testing.assert_allclose(response.tangent, objective_tangent(h.tangent, symmetric),
                               rtol=1e-12, atol=1e-3)
    np.testing.assert_allclose(response.fields["void_ratio"], h.void_ratio, rtol=1e-12)
    # ⌈3e-4 / 1e-5⌉ DEM steps for the largest |∇u|
    assert response.costs["dem_steps"] == steps == 30
    assert (response.status == PointStatus.OK).all()


def test_evaluate_is_idempotent_and_commit_revert_are_exact(material, tmp_path):
    first = material.evaluate(GRAD).stress
    np.testing.assert_array_equal(material.evaluate(GRAD).stress, first)
    material.commit()
    committed = material.committed_rves()
    second = material.evaluate(0.5 * GRAD).stress
    assert not np.allclose(second, first)
    material.revert()
    after = material.committed_rves()
    for name in ("position", "cell", "velocity", "angular_velocity"):
        np.testing.assert_array_equal(getattr(after, name), getattr(committed, name))
    np.testing.assert_array_equal(material.evaluate(0.5 * GRAD).stress, second)
    # checkpoint writes the committed state, not the trial one
    material.checkpoint(tmp_path / "committed.npz")
    other = DEMMaterial(device="cpu")
    other.restore(tmp_path / "committed.npz")
    np.testing.assert_allclose(other.evaluate(0.5 * GRAD).stress, second, rtol=1e-9, atol=1e-6)


def test_cell_inverting_gradient_is_reported_failed(material):
    grad = GRAD.copy()
    grad[2] = [[-1.5, 0.0], [0.0, 0.0]]  # det(I + ∇u) < 0
    grad[3] = [[-2.5, 0.0], [0.0, -2.5]]  # det > 0, but I + ∇u = −1.5 I has no real log
    response = material.evaluate(grad)
    assert response.status.tolist() == [0, 0, PointStatus.FAILED, PointStatus.FAILED]
    assert response.failed_points().tolist() == [2, 3]


def test_layout_of_an_rve_file_must_match_the_points(small_rve_path, tmp_path):
    from granular_material.dem import save_rve

    three = tmp_path / "three.npz"
    save_rve(three, load_rve(small_rve_path).replicate(3))
    with pytest.raises(ValueError, match="3 RVEs"):
        DEMMaterial(rve=three, device="cpu").allocate(4)
    with pytest.raises(ValueError, match="particles"):
        DEMMaterial(particles=2)


def test_single_element_agrees_with_pure_dem_biaxial(small_rve_path):
    """One Q4 element, 4 copies of the RVE, σxx = 100 kPa: peak σ1/σ3 within 5 % of the
    pure-DEM drained biaxial test of the same RVE (the acceptance band of issue 3)."""
    setup = BiaxialSetup(width=1.0, height=1.0, nx=1, ny=1, confining=100e3,
                         axial_strain=0.03)
    material = DEMMaterial(rve=small_rve_path, device="cpu")
    settings = NewtonSettings(predictor="extrapolate", relaxation="aitken")
    result = run_biaxial(setup, material, 15, settings, stress_tol=200.0)
    assert result.error is None
    fem = result.steps
    curve = biaxial_test(DEMBatch(load_rve(small_rve_path), device="cpu"),
                         axial_strain=0.03, confining=100e3)
    dem = summarize_biaxial(curve)
    fem_peak = fem["stress_ratio"].max()
    assert fem_peak == pytest.approx(dem.peak_stress_ratio, rel=0.05)
    assert fem_peak > 1.5  # the test loads beyond the elastic range
    # the lateral stress is held by the traction, within the Newton tolerance
    np.testing.assert_allclose(fem["sxx"].iloc[1:], -100e3, rtol=0.01)
    # Newton converges every step, with at most two halvings of an increment in all: the
    # branch past this RVE's peak is chaotic, and on another CPU (an AMD EPYC here, its own
    # BLAS kernels) the collapse at step 13 took two cut-backs where it took none before
    assert fem["cutbacks"].sum() <= 2 and fem["dem_steps"].sum() > 0
    assert fem["iterations"].iloc[1:].median() <= 5


def test_perturbation_tangent_predicts_the_rve_response_better_than_kruyt_rothenburg(
        small_rve_path):
    """Forward differences of the RVE's own response against the affine (KR) estimate.

    From ∇u = G, a further δ changes the stress by Δσ = σ(G + δ) − σ(G) (both runs from
    the committed state); the perturbation tangent, taken at G with h = 10 % of |G|, must
    predict Δσ for a δ it was not built from (a combination of all four components) better
    than the Kruyt–Rothenburg tangent, which leaves out the particles' rearrangement.
    """
    grad = np.repeat(np.array([[[3e-4, 0.0], [0.0, -1e-3]]]), 2, axis=0)
    delta = np.array([[2e-5, 1.5e-5], [-0.5e-5, -4e-5]])
    kr = create_material("dem", rve=small_rve_path, device="cpu")
    kr.allocate(2)
    fd = create_material("dem", rve=small_rve_path, device="cpu", tangent="perturbation")
    fd.allocate(2)
    at_g = fd.evaluate(grad)
    # the main run and four perturbed ones, of 100 DEM steps but the ∂u_y/∂y one (90)
    assert at_g.costs["dem_steps"] == 4 * 100 + 90
    np.testing.assert_array_equal(at_g.stress, kr.evaluate(grad).stress)
    change = kr.evaluate(grad + delta).stress - at_g.stress
    kr_tangent = kr.evaluate(grad).tangent

    def error(tangent):
        predicted = np.einsum("bijkl,kl->bij", tangent, delta)
        return np.linalg.norm(predicted - change) / np.linalg.norm(change)

    assert error(at_g.tangent) < 0.5 * error(kr_tangent)
    assert error(at_g.tangent) < 0.3
    with pytest.raises(ValueError, match="tangent"):
        create_material("dem", rve=small_rve_path, tangent="secant")


def test_every_dem_run_fails_points_without_a_constant_velocity_gradient(material):
    """Each run of an evaluation (the perturbed ones too) checks its own ∇u: one with
    det(I + ∇u) <= 0, or with a negative eigenvalue of I + ∇u, fails that point only."""
    grad = np.repeat(GRAD[:1], 4, axis=0)
    grad[1] = [[0.0, 1.2], [0.97, 0.0]]  # det(I + ∇u) = −0.164
    grad[2] = [[-2.5, 0.0], [0.0, -2.5]]  # I + ∇u = −1.5 I: det > 0, no real logarithm
    response = material.evaluate(grad)
    ok = np.isfinite(response.stress[[0, 3]]).all()  # the batch came through the run
    failed = response.status == PointStatus.FAILED
    steps = response.costs["dem_steps"]
    assert ok and steps == 20 and failed.tolist() == [False, True, True, False]


def test_perturbation_tangent_stops_at_the_first_dem_run_that_fails(small_rve_path,
                                                                    monkeypatch):
    """Once one perturbed run has failed, the evaluation fails whatever the others give:
    none of them is run, and the failed points of that run are reported."""
    material = create_material("dem", rve=small_rve_path, device="cpu", tangent="perturbation")
    material.allocate(2)
    calls = []

    def blow_up(batch, plan):  # the first DEM run (a perturbed one) blows up
        calls.append(plan)
        raise DEMInstabilityError([1], ["test: RVE 1 blew up"])

    monkeypatch.setattr("granular_material.multiscale.backend.drive_planned", blow_up)
    response = material.evaluate(np.repeat(GRAD[:1], 2, axis=0))
    assert len(calls) == 1 and not response.ok
    # the whole batch went back to its committed state: RVE 1 blew up, RVE 0 is aborted
    assert response.status.tolist() == [PointStatus.FAILED, PointStatus.FAILED]
    assert response.reasons.tolist() == ["aborted", "blow_up"]
    assert np.isfinite(response.stress).all()  # the committed stress, not NaN
    assert response.costs["dem_steps"] == 0
