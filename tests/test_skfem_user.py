"""What a scikit-fem user sees of the materials: layouts, totals, reasons, names, warnings."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest
from skfem import Basis, ElementQuad1, ElementVector, MeshQuad

from granular_material.fem import (
    BiaxialSetup,
    FailureReason,
    LinearElastic,
    MaterialResponse,
    NewtonSettings,
    PointStatus,
    QuadratureResponse,
    create_material,
    to_points,
    to_quadrature,
)
from granular_material.multiscale import DEMMaterial, UnconfinedWarning
from granular_material.results.summary import run_summary
from granular_material.runs import run_biaxial

RNG = np.random.default_rng(5)


@pytest.fixture
def basis():
    return Basis(MeshQuad().refined(1), ElementVector(ElementQuad1()), intorder=2)


def _elastic(n):
    m = LinearElastic(young=60e6, poisson=0.3, initial_stress=-100e3)
    m.allocate(n)
    return m


def test_response_answers_in_the_layout_it_was_given(basis):
    n, nqp = basis.nelems * 4, 4
    u = 1e-3 * RNG.normal(size=basis.N)
    field = basis.interpolate(u)
    m = _elastic(n)
    by_field = m.response(field)
    by_array = m.response(field.grad)
    by_points = m.response(to_points(field.grad))
    assert isinstance(by_field, QuadratureResponse) and isinstance(by_points, MaterialResponse)
    assert by_field.stress.shape == (2, 2, basis.nelems, nqp)
    assert by_field.tangent.shape == (2, 2, 2, 2, basis.nelems, nqp)
    assert by_field.status.shape == by_field.reasons.shape == (basis.nelems, nqp)
    np.testing.assert_array_equal(by_field.stress, by_array.stress)
    np.testing.assert_array_equal(by_field.stress, to_quadrature(by_points.stress, nqp))
    np.testing.assert_array_equal(by_field.points.stress, by_points.stress)
    assert by_field.ok and not by_field.failed.any()


def test_shape_errors_name_the_layouts_and_the_converters():
    m = _elastic(16)
    for bad in (np.zeros((15, 2, 2)), np.zeros((2, 2, 3, 4)), np.zeros((4, 4))):
        with pytest.raises(ValueError, match=r"batch-first \(n, 2, 2\).*quadrature-last "
                                             r"\(2, 2, nelems, nqp\).*DiscreteField.*"
                                             r"to_points / to_quadrature"):
            m.response(bad)
    with pytest.raises(ValueError, match="to_points / to_quadrature"):
        m.evaluate(np.zeros((2, 2, 4, 4)))
    with pytest.raises(ValueError, match="measure"):
        m.response(np.zeros((16, 2, 2)), measure="totals")


def test_total_is_the_increment_from_the_committed_state():
    m, other = _elastic(3), _elastic(3)
    g1, g2 = 1e-3 * RNG.normal(size=(2, 3, 2, 2))
    m.response(g1)
    m.commit()
    np.testing.assert_array_equal(m.committed_grad_u, g1)
    total = m.response(g1 + g2)
    other.evaluate(g1)
    other.commit()
    increment = other.response(g2, measure="increment")
    np.testing.assert_allclose(total.stress, increment.stress, rtol=1e-12, atol=1e-6)
    again = m.response(g1 + g2)  # idempotent: from the committed state
    np.testing.assert_array_equal(again.stress, total.stress)
    m.revert()
    np.testing.assert_array_equal(m.committed_grad_u, g1)
    # the protocol's evaluate keeps the increment, and the total follows it
    other.commit()
    np.testing.assert_allclose(other.committed_grad_u, g1 + g2, atol=1e-18)


def test_linear_elastic_checkpoint_keeps_the_committed_total(tmp_path):
    m = _elastic(2)
    g = 1e-3 * RNG.normal(size=(2, 2, 2))
    m.response(g)
    m.commit()
    m.checkpoint(tmp_path / "le.npz")
    back = _elastic(2)
    back.restore(tmp_path / "le.npz")
    np.testing.assert_array_equal(back.committed_grad_u, g)


def test_linear_elastic_takes_the_old_names_with_a_warning():
    from granular_material.vocabulary import RenamedWarning

    with pytest.warns(RenamedWarning) as caught:
        old = LinearElastic(E=1e7, nu=0.2)
    assert "`nu` is deprecated: it is now `poisson`" in str(caught[1].message)
    assert old.parameters == LinearElastic(young=1e7, poisson=0.2).parameters


def test_dem_material_total_form_checkpoint_and_committed_stress_on_failure(
        small_rve_path, tmp_path):
    m = DEMMaterial(rve=small_rve_path, device="cpu", max_dem_steps=40)
    m.allocate(2)
    committed = m.response(np.zeros((2, 2, 2)))
    g = np.array([[[0.0, 0.0], [0.0, -2e-4]], [[1e-4, 0.0], [0.0, -1e-4]]])
    first = m.response(g)
    assert first.ok
    m.commit()
    np.testing.assert_array_equal(m.committed_grad_u, g)
    # 40 DEM steps allow 4e-4 strain: point 1's further 1e-3 needs 100 and fails
    big = g.copy()
    big[1, 1, 1] -= 1e-3
    r = m.response(big)
    assert r.status.tolist() == [PointStatus.OK, PointStatus.FAILED]
    assert r.reasons.tolist() == ["", FailureReason.MAX_DEM_STEPS]
    assert r.failure_counts() == {"max_dem_steps": 1}
    np.testing.assert_array_equal(r.stress[1], first.stress[1])  # committed, not NaN
    m.revert()
    m.checkpoint(tmp_path / "dem.npz")
    back = DEMMaterial(rve=small_rve_path, device="cpu")
    back.restore(tmp_path / "dem.npz")
    np.testing.assert_array_equal(back.committed_grad_u, g)
    assert np.isfinite(committed.stress).all()


def test_a_dem_checkpoint_keeps_what_unconfined_and_failed_points_answer_by(
        small_rve_path, tmp_path):
    # the floor of an unconfined point's tangent is the tangent of the first evaluation (the
    # initial state's), and a failed point answers by the committed response: a restored
    # material answers by the same ones, not by those of its own first evaluation (issue 61)
    from dataclasses import replace

    from granular_material.dem import load_rve, save_rve

    m = DEMMaterial(rve=small_rve_path, device="cpu")
    m.allocate(2)
    m.evaluate(np.zeros((2, 2, 2)))
    m.revert()
    g = np.array([[[0.0, 0.0], [0.0, -2e-4]], [[1e-4, 0.0], [0.0, -1e-4]]])
    m.evaluate(g)
    m.commit()
    m.checkpoint(tmp_path / "dem.npz")
    back = DEMMaterial(rve=small_rve_path, device="cpu")
    back.restore(tmp_path / "dem.npz")
    assert not np.array_equal(m._initial_tangent, m._committed_response.tangent)
    np.testing.assert_array_equal(back._initial_tangent, m._initial_tangent)
    for name in ("stress", "tangent"):
        np.testing.assert_array_equal(getattr(back._committed_response, name),
                                      getattr(m._committed_response, name))
    assert back._committed_response.fields.keys() == m._committed_response.fields.keys()
    # a checkpoint written before the floor was kept in it is refused, not resumed to
    # another run
    data = load_rve(tmp_path / "dem.npz")
    extra = {k: v for k, v in data.extra.items() if k != "backend_material_initial_tangent"}
    save_rve(tmp_path / "old.npz", replace(data, extra=extra), compress=False, validate=False)
    with pytest.raises(ValueError, match=r"initial tangent.*start the run afresh"):
        DEMMaterial(rve=small_rve_path, device="cpu").restore(tmp_path / "old.npz")


def test_dem_failure_before_any_commit_reports_the_prepared_stress(small_rve_path):
    m = DEMMaterial(rve=small_rve_path, device="cpu")
    m.allocate(1)
    r = m.response(np.array([[[0.0, 1.2], [0.97, 0.0]]]))  # det(I + ∇u) < 0
    assert r.reasons.tolist() == ["cell_inverted"]
    at_rest = m.response(np.zeros((1, 2, 2)))
    np.testing.assert_allclose(r.stress, at_rest.stress, rtol=0.02, atol=50.0)


def test_pressure_is_the_deprecated_name_of_confining():
    with pytest.warns(DeprecationWarning, match="confining"):
        old = DEMMaterial(particles=16, pressure=50e3)
    assert old.confining == 50e3 == DEMMaterial(particles=16, confining=50e3).confining
    with pytest.raises(ValueError, match="not both"):
        DEMMaterial(particles=16, pressure=1.0, confining=2.0)


def test_an_unconfined_rve_warns_once(small_rve_path):
    m = DEMMaterial(rve=small_rve_path, device="cpu")
    m.allocate(1)
    with pytest.warns(UnconfinedWarning, match="lost their confinement"):
        m.response(np.array([[[1e-2, 0.0], [0.0, 1e-2]]]))  # 2 % dilation: a gas
    with warnings.catch_warnings():
        warnings.simplefilter("error", UnconfinedWarning)
        m.response(np.array([[[1e-2, 0.0], [0.0, 1e-2]]]))  # once per material
    confined = DEMMaterial(rve=small_rve_path, device="cpu")
    confined.allocate(1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UnconfinedWarning)
        confined.response(np.array([[[0.0, 0.0], [0.0, -1e-4]]]))


def test_failures_are_counted_by_reason_in_the_run_summary(small_rve_path):
    material = create_material("dem", rve=small_rve_path, device="cpu", replicate=True,
                               max_dem_steps=3)
    setup = BiaxialSetup(nx=1, ny=1, axial_strain=0.01, confining=100e3)
    result = run_biaxial(setup, material, 1, NewtonSettings(max_cutbacks=1))
    assert result.error is not None and "max_dem_steps" in result.error
    assert result.failures.get("max_dem_steps", 0) >= 4
    assert run_summary(result, 0.0)["failed_points"] == result.failures


def test_warp_is_silent_unless_asked():
    code = ("import granular_material{extra}\n"
            "import warp as wp\n"
            "wp.init()\n")
    quiet = subprocess.run([sys.executable, "-c", code.format(extra="")],
                           capture_output=True, text=True, timeout=300)
    loud = subprocess.run([sys.executable, "-c", code.format(
        extra="; granular_material.verbose(True)")], capture_output=True, text=True,
        timeout=300)
    assert quiet.returncode == loud.returncode == 0, quiet.stderr + loud.stderr
    assert "initialized" not in quiet.stdout and "initialized" in loud.stdout


def test_isotropic_start_removes_the_shear_stress_of_the_packing():
    raw = DEMMaterial(particles=24, seed=1, device="cpu", replicate=True)
    raw.allocate(1)
    iso = DEMMaterial(particles=24, seed=1, device="cpu", replicate=True, isotropic=True)
    iso.allocate(1)
    zero = np.zeros((1, 2, 2))
    before, after = raw.response(zero).stress[0], iso.response(zero).stress[0]
    assert abs(after[0, 1]) <= 1e3 < abs(before[0, 1])  # |σxy| under 1 % of 100 kPa
    np.testing.assert_allclose(np.diag(after), [-100e3, -100e3], atol=1.5e3)
    np.testing.assert_array_equal(iso.committed_grad_u, zero)
