"""Model only what the scene requires: reuse of undisturbed RVEs, continued driving, tracked
post-processors, the stepping of a subset.

Smoke scale: the 100-disc RVE of the session fixture ``small_rve_path`` (seed 3), copied to
four Gauss points.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from granular_material.cli import main
from granular_material.dem import DEMBatch, load_rve
from granular_material.dem.homogenization import objective_tangent
from granular_material.fem import BiaxialSetup, NewtonSettings, Tracking
from granular_material.multiscale import DEMMaterial
from granular_material.procedures import drive_grad_u, path_steps
from granular_material.runs import run_biaxial

GRAD = np.array([
    [[0.0, 0.0], [0.0, -2e-4]],
    [[1e-4, 5e-5], [-5e-5, -3e-4]],
    [[-1e-4, 2e-4], [0.0, 1e-4]],
    [[0.0, -1e-4], [1e-4, 0.0]],
])


def _material(path, **options) -> DEMMaterial:
    material = DEMMaterial(rve=path, device="cpu", **options)
    material.allocate(4)
    return material


def _as_material(h) -> tuple[np.ndarray, np.ndarray]:
    """What the DEM material answers for homogenised RVEs ``h``: the Love stress
    symmetrised and the objective tangent."""
    stress = 0.5 * (h.stress + np.swapaxes(h.stress, 1, 2))
    return stress, objective_tangent(h.tangent, stress)


def test_reuse_off_is_bit_identical_to_restarting_every_rve(small_rve_path):
    """reuse_tol = 0: every evaluation drives every RVE from the committed state, exactly as
    a batch that is restored and driven by hand."""
    material = _material(small_rve_path, reuse_tol=0.0)
    batch = DEMBatch(load_rve(small_rve_path).replicate(4), device="cpu")
    committed = batch.snapshot()
    for grad in (GRAD, GRAD * (1 + 1e-9), 0.5 * GRAD):
        response = material.evaluate(grad)
        batch.restore(committed)
        drive_grad_u(batch, grad)
        stress, tangent = _as_material(batch.homogenize())
        np.testing.assert_array_equal(response.stress, stress)
        np.testing.assert_array_equal(response.tangent, tangent)
        assert response.costs["rve_evaluations"] == 4
        assert response.costs["particle_steps"] == path_steps(grad).sum() * 100
    material.commit()
    committed = batch.snapshot()
    response = material.evaluate(GRAD)
    batch.restore(committed)
    drive_grad_u(batch, GRAD)
    np.testing.assert_array_equal(response.stress, _as_material(batch.homogenize())[0])


def test_an_unchanged_point_is_not_stepped_and_answers_the_same(small_rve_path):
    material = _material(small_rve_path, reuse_tol=1e-6)
    first = material.evaluate(GRAD)
    assert first.costs["rve_evaluations"] == 4
    moved = GRAD.copy()
    moved[1, 0, 0] += 5e-6  # beyond the tolerance: only point 1 is stepped
    moved[2, 1, 1] += 5e-7  # within it: reused
    second = material.evaluate(moved)
    assert second.costs["rve_evaluations"] == 1
    assert second.costs["particle_steps"] == path_steps(moved[1:2]).sum() * 100
    for p in (0, 2, 3):
        np.testing.assert_array_equal(second.stress[p], first.stress[p])
        np.testing.assert_array_equal(second.tangent[p], first.tangent[p])
    # the stepped point is exactly a fresh restart to its ∇u
    fresh = _material(small_rve_path, reuse_tol=0.0).evaluate(moved)
    np.testing.assert_array_equal(second.stress[1], fresh.stress[1])
    third = material.evaluate(moved)
    assert third.costs["rve_evaluations"] == 0 and third.costs["particle_steps"] == 0
    np.testing.assert_array_equal(third.stress, second.stress)


def test_first_order_correction_adds_the_tangent_times_the_change(small_rve_path):
    material = _material(small_rve_path, reuse_tol=1e-6, reuse_correction="tangent")
    first = material.evaluate(GRAD)
    moved = GRAD.copy()
    moved[:, 0, 1] += 4e-7
    second = material.evaluate(moved)
    assert second.costs["rve_evaluations"] == 0
    change = np.zeros((4, 2, 2))
    change[:, 0, 1] = 4e-7
    expected = first.stress + np.einsum("bijkl,bkl->bij", first.tangent, change)
    np.testing.assert_allclose(second.stress, expected, rtol=1e-12, atol=1e-9)
    assert not np.array_equal(second.stress, first.stress)


def test_a_committed_reused_point_lags_within_the_tolerance_and_catches_up(small_rve_path):
    """After a commit with reused points, each one's committed state is the state a fresh
    evaluation of the FEM's ∇u gives, within the stress that the tolerance's strain makes;
    the next step drives it by the lag as well, so nothing accumulates."""
    tol = 2e-6
    reuse = _material(small_rve_path, reuse_tol=tol)
    exact = _material(small_rve_path, reuse_tol=0.0)
    reuse.evaluate(GRAD)
    final = GRAD + 1.5e-6  # within the tolerance everywhere: all four reused
    response = reuse.evaluate(final)
    assert response.costs["rve_evaluations"] == 0
    reuse.commit()
    exact.evaluate(final)
    exact.commit()
    lag = reuse.backend.lag
    assert np.abs(lag).max() <= 1.01 * 1.5e-6 and np.abs(lag).min() > 0
    committed = DEMBatch(reuse.committed_rves(), device="cpu").homogenize()
    reference = DEMBatch(exact.committed_rves(), device="cpu").homogenize()
    bound = 4 * tol * np.abs(reference.tangent).max(axis=(1, 2, 3, 4))
    assert (np.abs(committed.stress - reference.stress).max(axis=(1, 2)) <= bound).all()
    # a zero ∇u in the next step is within the tolerance of where the RVEs are: reused
    assert reuse.evaluate(np.zeros((4, 2, 2))).costs["rve_evaluations"] == 0
    # a real step drives each RVE by (I + ∇u)(I + lag) − I from its committed state
    step = reuse.evaluate(GRAD)
    assert step.costs["rve_evaluations"] == 4
    target = GRAD + lag + GRAD @ lag
    np.testing.assert_array_equal(reuse.backend.trial.reached, target)


def test_continue_drives_from_the_trial_state_with_fewer_steps(small_rve_path):
    restart = _material(small_rve_path)
    cont = _material(small_rve_path, drive="continue")
    for m in (restart, cont):
        m.evaluate(GRAD)
    nudged = GRAD * 1.01
    a, b = restart.evaluate(nudged), cont.evaluate(nudged)
    assert b.costs["particle_steps"] < a.costs["particle_steps"] / 5
    p = 0.5 * np.abs(np.trace(a.stress, axis1=1, axis2=2))
    # the same response up to the path dependence of a small detour
    assert (np.abs(a.stress - b.stress).max(axis=(1, 2)) < 0.05 * p).all()
    again = cont.evaluate(nudged)  # already there: not stepped, the same answer
    assert again.costs["rve_evaluations"] == 0
    np.testing.assert_array_equal(again.stress, b.stress)
    with pytest.raises(ValueError, match="continue"):
        DEMMaterial(drive="continue", tangent="perturbation")


def test_a_path_over_the_step_cap_is_a_failed_point_not_a_crash(small_rve_path):
    material = _material(small_rve_path, max_dem_steps=25)  # GRAD[1] needs 30 steps
    response = material.evaluate(GRAD)
    assert response.failed_points().tolist() == [1]
    assert material.evaluate(0.5 * GRAD).ok


def test_drive_grad_u_leaves_frozen_rves_untouched(small_rve_path):
    batch = DEMBatch(load_rve(small_rve_path).replicate(4), device="cpu")
    before = batch.to_data()
    active = np.array([True, False, True, False])
    steps = drive_grad_u(batch, GRAD, active=active)
    assert steps == path_steps(GRAD[active]).max()
    after = batch.to_data()
    for b in (1, 3):
        for name in ("position", "velocity", "angular_velocity", "cell"):
            np.testing.assert_array_equal(getattr(after, name)[b], getattr(before, name)[b])
    assert not np.array_equal(after.position[0], before.position[0])
    with pytest.raises(ValueError, match="more than the cap"):
        drive_grad_u(batch, GRAD, max_steps=10)
    with pytest.raises(ValueError, match="DEM steps"):
        path_steps(np.array([[[1e300, 0.0], [0.0, 0.0]]]))


def test_tracked_postprocessor_runs_exactly_on_the_named_points_and_steps(small_rve_path):
    setup = BiaxialSetup(width=1.0, height=1.0, nx=1, ny=1, confining=100e3,
                         axial_strain=0.006)
    material = DEMMaterial(rve=small_rve_path, device="cpu")
    tracking = Tracking(("pore-fractal",), points=(1, 3), every=2)
    result = run_biaxial(setup, material, 3, NewtonSettings(predictor="extrapolate"),
                         stress_tol=500.0, tracking=tracking)
    assert result.error is None
    tracked = result.tracked
    assert sorted(zip(tracked["step"], tracked["point"], strict=True)) == [
        (0, 1), (0, 3), (2, 1), (2, 3)]
    assert (tracked["postprocessor"] == "pore-fractal").all()
    assert tracked["D0"].between(1.0, 2.0).all() and (tracked["seconds"] > 0).all()
    with pytest.raises(ValueError, match="does not exist"):
        Tracking(("pore-fractal",), points=(4,)).check_points(4)
    with pytest.raises(ValueError, match="not registered"):
        Tracking(("no-such-thing",))


def test_cli_refuses_reuse_with_the_displacement_test(small_rve_path, capsys):
    """Reused RVEs answer in steps: with either displacement test (the residual one is the
    default) no increment could converge, so the pair is refused before any work, naming
    both options."""
    for test in ([], ["--convergence", "displacement"]):
        code = main(["single-element", "--rve", str(small_rve_path), "--steps", "2",
                     "--reuse-tol", "1e-6", *test])
        assert code == 2
        assert "--reuse-tol 1e-06 needs --convergence force" in capsys.readouterr().err


def test_cli_reports_counts_and_writes_tracked_csv(small_rve_path, tmp_path, capsys):
    out = tmp_path / "se"
    code = main(["single-element", "--rve", str(small_rve_path), "--steps", "2",
                 "--axial-strain", "0.004", "--reuse-tol", "1e-6", "--convergence", "force",
                 "--track", "0", "2", "--every", "2", "--out", str(out), "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["rve_evaluations"] > 0 and summary["particle_steps"] > 0
    assert json.loads((out / "summary.json").read_text()) == summary
    assert summary["tracked_rows"] == 4
    steps = (out / "steps.csv").read_text().splitlines()[0].split(",")
    assert {"dem_steps", "rve_evaluations", "particle_steps"} <= set(steps)
    tracked = (out / "tracked.csv").read_text().splitlines()
    assert len(tracked) == 5 and tracked[0].startswith("step,axial_strain,point,postprocessor")
    bad = tmp_path / "bad"
    assert main(["single-element", "--rve", str(small_rve_path), "--track", "9",
                 "--out", str(bad)]) == 2
    assert not bad.exists()
