"""The plane-strain Mohr–Coulomb material: closed forms on a point driven in biaxial
compression, softening, elastic unloading, the exact tangent in every return region, the
material protocol, and Newton on a single element."""

from __future__ import annotations

import functools
import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest

import granular_material.fem.materials.mohr_coulomb as mc_module
from granular_material.errors import ParameterError
from granular_material.fem import (
    Fixed,
    RigidBody,
    Roller,
    build_problem,
    rectangle_mesh,
    select_boundaries,
)
from granular_material.fem.boundary_value.biaxial import BiaxialSetup, build_biaxial
from granular_material.fem.materials.linear_elastic import LinearElastic, isotropic_tangent
from granular_material.fem.materials.mohr_coulomb import (
    APEX_TANGENT,
    MohrCoulomb,
    MohrCoulombParameters,
    MohrCoulombRunParameters,
)
from granular_material.fem.materials.mohr_coulomb_return import (
    APEX,
    EDGE_MAJOR,
    EDGE_MINOR,
    ELASTIC,
    FACE,
    principal_return,
)
from granular_material.fem.materials.protocol import FailureReason, Material, PointStatus
from granular_material.fem.solver.newton import NewtonSettings, NewtonSolver
from granular_material.vocabulary import RenamedWarning

P = 100e3  # confining pressure [Pa], compression positive


def ratio_of(phi_deg: float) -> float:
    s = math.sin(math.radians(phi_deg))
    return (1 + s) / (1 - s)


def drive_biaxial(material: MohrCoulomb, steps: int, deps: float = -1e-4,
                  p: float = P) -> dict[str, np.ndarray | list]:
    """One point in plane-strain biaxial compression: ε_yy changes by ``deps`` a step, σxx
    is held at −p by Newton on the lateral strain with the material's tangent."""
    eps = np.zeros(2)
    rec: dict[str, list] = {"sxx": [], "syy": [], "szz": [], "gamma": [], "exx": [],
                            "eyy": [], "phi": [], "yielding": [], "residuals": []}
    gxx = 0.0
    for _ in range(steps):
        residuals = []
        for _ in range(40):
            response = material.evaluate(np.array([[[gxx, 0.0], [0.0, deps]]]))
            residual = response.stress[0, 0, 0] + p
            residuals.append(abs(residual))
            if abs(residual) <= 1e-10 * p:
                break
            gxx -= residual / response.tangent[0, 0, 0, 0, 0]
        else:
            raise AssertionError(f"the lateral Newton did not converge: {residuals}")
        material.commit()
        eps += (gxx, deps)
        rec["residuals"].append(residuals)
        for key, value in (("sxx", material.stress[0, 0, 0]), ("syy", material.stress[0, 1, 1]),
                           ("szz", material.stress_zz[0]),
                           ("gamma", material.plastic_shear_strain[0]), ("exx", eps[0]),
                           ("eyy", eps[1]), ("phi", material.friction_angle_now[0]),
                           ("yielding", material.yielding[0])):
            rec[key].append(value)
    return {k: (v if k == "residuals" else np.array(v)) for k, v in rec.items()}


@pytest.mark.parametrize("phi", [30.0, 40.0])
def test_peak_ratio_without_cohesion(phi):
    material = MohrCoulomb(friction_angle=phi, initial_stress=-P)
    material.allocate(1)
    rec = drive_biaxial(material, 120)
    ratio = rec["syy"] / rec["sxx"]
    assert rec["yielding"].any() and not rec["yielding"][0]
    assert ratio.max() == pytest.approx(ratio_of(phi), rel=1e-8)
    np.testing.assert_allclose(ratio[rec["yielding"]], ratio_of(phi), rtol=1e-8)
    assert math.isclose(ratio_of(30.0), 3.0, rel_tol=1e-12)
    # σzz stays the intermediate stress: the face, not an edge, is active
    assert np.all((rec["szz"] <= rec["sxx"]) & (rec["szz"] >= rec["syy"]))


def test_peak_with_cohesion():
    phi, c = 30.0, 20e3
    material = MohrCoulomb(friction_angle=phi, cohesion=c, initial_stress=-P)
    material.allocate(1)
    rec = drive_biaxial(material, 120)
    s = math.sin(math.radians(phi))
    expected = P * (1 + s) / (1 - s) + 2 * c * math.cos(math.radians(phi)) / (1 - s)
    assert -rec["syy"].min() == pytest.approx(expected, rel=1e-8)
    assert -rec["syy"][-1] == pytest.approx(expected, rel=1e-8)


@pytest.mark.parametrize("psi", [0.0, 30.0])
def test_plastic_dilatancy_follows_psi(psi):
    """dεvp/dγp = sin ψ with εv tension positive (dilation > 0), i.e. −sin ψ compression
    positive, on the face."""
    young, nu = 60e6, 0.3
    material = MohrCoulomb(young=young, poisson=nu, friction_angle=30.0, dilation_angle=psi,
                           initial_stress=-P)
    material.allocate(1)
    rec = drive_biaxial(material, 80)
    total = rec["sxx"] + rec["syy"] + rec["szz"]
    elastic_v = (1 - 2 * nu) / young * (total + 3 * P)
    plastic_v = rec["exx"] + rec["eyy"] - elastic_v
    plastic = np.flatnonzero(rec["yielding"])
    assert plastic.size > 30
    k0, k1 = plastic[0], plastic[-1]
    rate = (plastic_v[k1] - plastic_v[k0]) / (rec["gamma"][k1] - rec["gamma"][k0])
    assert rate == pytest.approx(math.sin(math.radians(psi)), abs=1e-9)
    assert rec["gamma"][k1] > 0.003


def test_softening_takes_the_ratio_from_peak_to_critical():
    phi, phi_cs, gs = 35.0, 30.0, 0.01
    material = MohrCoulomb(friction_angle=phi, dilation_angle=5.0, critical_friction_angle=phi_cs,
                           softening_strain=gs, initial_stress=-P)
    material.allocate(1)
    rec = drive_biaxial(material, 160)
    ratio = rec["syy"] / rec["sxx"]
    plastic = rec["yielding"]
    # on the face the ratio is that of the softened angle at every plastic step
    expected = np.array([ratio_of(a) for a in rec["phi"][plastic]])
    np.testing.assert_allclose(ratio[plastic], expected, rtol=1e-8)
    assert np.all(np.diff(rec["phi"]) <= 1e-12)
    assert rec["phi"][0] == phi and rec["phi"][-1] == pytest.approx(phi_cs, abs=1e-12)
    assert rec["gamma"][-1] > gs
    assert ratio.max() <= ratio_of(phi) * (1 + 1e-12)
    assert ratio.max() > ratio_of(phi) - 0.05
    assert ratio[-1] == pytest.approx(ratio_of(phi_cs), rel=1e-8)
    # φ falls linearly in γp
    inside = rec["gamma"] < gs
    np.testing.assert_allclose(rec["phi"][inside],
                               phi + (phi_cs - phi) * rec["gamma"][inside] / gs, atol=1e-10)


def test_elastic_unloading_after_yield():
    material = MohrCoulomb(friction_angle=30.0, dilation_angle=10.0, initial_stress=-P)
    material.allocate(1)
    rec = drive_biaxial(material, 40)
    assert rec["yielding"][-1]
    lam, mu = material.parameters.lame
    c = isotropic_tangent(lam, mu)
    before = material.stress[0]
    grad = np.array([[[-2e-4, 0.0], [0.0, 5e-4]]])
    response = material.evaluate(grad)
    assert response.fields["return_region"][0] == ELASTIC
    np.testing.assert_allclose(response.stress[0] - before,
                               np.einsum("ijkl,kl->ij", c, grad[0]), rtol=1e-12, atol=1e-6)
    sym = 0.5 * (response.tangent[0] + np.swapaxes(response.tangent[0], 2, 3))
    np.testing.assert_allclose(sym, c, rtol=0, atol=1e-6 * np.abs(c).max())
    assert response.fields["stress_zz"][0] == pytest.approx(
        material.stress_zz[0] + lam * np.trace(grad[0]), rel=1e-12)


# -- the tangent against finite differences, every region -----------------------------------
def _cases(rotation: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
    """Initial stresses, σzz and increments that land in each region (c > 0)."""
    init = np.array([np.diag([-100e3, -100e3]), np.diag([-100e3, -295e3]),
                     np.diag([-100e3, -100e3]), [[-100e3, 1e3], [1e3, -100e3]],
                     np.diag([-250e3, -100e3]), np.zeros((2, 2))])
    zz = np.array([-100e3, -150e3, -290e3, -290e3, -250e3, 0.0])
    grad = np.array([[[1e-5, 2e-6], [0.0, -1e-5]], [[1e-3, 3e-4], [-1e-4, -2e-3]],
                     [[5e-4, 0.0], [0.0, 5e-4]], [[5e-4, 1e-5], [-3e-5, 5e-4]],
                     [[0.0, 0.0], [0.0, 3e-3]], [[5e-3, 1e-3], [0.0, 5e-3]]])
    if rotation:
        grad = grad + np.array([[0.0, 4e-3], [-4e-3, 0.0]])
    return init, zz, grad, [ELASTIC, FACE, EDGE_MAJOR, EDGE_MAJOR, EDGE_MINOR, APEX]


def _fd_errors(material: MohrCoulomb, grad: np.ndarray, h: float = 1e-8) -> np.ndarray:
    """max over the 4 components of ∇u of ‖D_fd − D‖ / ‖D‖ per point (central differences;
    a column with ‖D‖ tiny is measured against 1e-3 ‖D‖ or 1e-6 ‖C‖)."""
    response = material.evaluate(grad)
    d = response.tangent
    whole = np.sqrt((d ** 2).sum(axis=(1, 2, 3, 4)))
    floor = 1e-6 * np.abs(material._c).max()
    errors = []
    for k in range(2):
        for m in range(2):
            up, down = grad.copy(), grad.copy()
            up[:, k, m] += h
            down[:, k, m] -= h
            fd = (material.evaluate(up).stress - material.evaluate(down).stress) / (2 * h)
            col = d[:, :, :, k, m]
            scale = np.maximum(np.linalg.norm(col, axis=(1, 2)), np.maximum(1e-3 * whole, floor))
            errors.append(np.linalg.norm(fd - col, axis=(1, 2)) / scale)
    return np.max(errors, axis=0)


@pytest.mark.parametrize("rotation", [False, True])
@pytest.mark.parametrize("softening", [None, 25.0])
def test_tangent_matches_finite_differences_in_every_region(softening, rotation):
    init, zz, grad, regions = _cases(rotation)
    material = MohrCoulomb(friction_angle=30.0, dilation_angle=10.0, cohesion=20e3,
                           critical_friction_angle=softening, softening_strain=0.05,
                           initial_stress=init, initial_stress_zz=zz, apex_tangent=0.0)
    material.allocate(len(init))
    response = material.evaluate(grad)
    assert response.ok
    assert response.fields["return_region"].astype(int).tolist() == regions
    errors = _fd_errors(material, grad)
    assert errors.max() < 1e-5, errors
    if softening is not None:  # the softened apex moves with γp: a nonzero tangent there
        assert np.abs(response.tangent[-1]).max() > 0
    else:
        assert np.abs(response.tangent[-1]).max() == 0


def test_apex_iterates_with_a_floor_of_the_elastic_tangent_and_the_same_stress():
    """With c = 0 an apex point is stress-free with a zero exact tangent; by default it
    answers APEX_TANGENT × C instead (Newton's matrix stays regular), the stress unchanged."""
    init, zz, grad, _ = _cases(False)
    kwargs = dict(friction_angle=30.0, dilation_angle=10.0, cohesion=0.0,
                  initial_stress=init[-1:], initial_stress_zz=zz[-1:])
    exact, floored = MohrCoulomb(apex_tangent=0.0, **kwargs), MohrCoulomb(**kwargs)
    for material in (exact, floored):
        material.allocate(1)
    a, b = exact.evaluate(grad[-1:]), floored.evaluate(grad[-1:])
    assert b.fields["return_region"][0] == APEX
    np.testing.assert_array_equal(a.stress, b.stress)
    assert np.abs(a.tangent).max() == 0
    np.testing.assert_allclose(b.tangent[0], APEX_TANGENT * floored._c, rtol=1e-14)
    with pytest.raises(ParameterError, match="apex_tangent"):
        MohrCoulomb(apex_tangent=-1.0)


@pytest.mark.parametrize("rotation", [False, True])
def test_tangent_in_every_region_without_cohesion(rotation):
    init, zz, grad, _ = _cases(rotation)
    material = MohrCoulomb(friction_angle=30.0, dilation_angle=30.0,
                           critical_friction_angle=28.0, softening_strain=0.05,
                           initial_stress=init, initial_stress_zz=zz, apex_tangent=0.0)
    material.allocate(len(init))
    response = material.evaluate(grad)
    assert response.ok and response.fields["return_region"][-1] == APEX
    assert _fd_errors(material, grad).max() < 1e-5
    # c = 0: the apex is the origin, stress-free and status OK
    assert np.all(response.stress[-1] == 0) and response.fields["stress_zz"][-1] == 0
    assert response.status[-1] == PointStatus.OK


def test_tangent_has_the_spin_of_the_committed_stress():
    """Under a pure rotation the stress turns with W: σ = σn + Wσn − σnW, elastic."""
    init = np.array([[-100e3, 20e3], [20e3, -150e3]])
    material = MohrCoulomb(initial_stress=init)
    material.allocate(1)
    w = np.array([[0.0, 1e-3], [-1e-3, 0.0]])
    response = material.evaluate(w[None])
    np.testing.assert_allclose(response.stress[0], init + w @ init - init @ w, rtol=1e-12)
    assert not np.allclose(response.tangent[0], np.swapaxes(response.tangent[0], 2, 3))


# -- the protocol ---------------------------------------------------------------------------
def test_protocol_idempotent_commit_revert_checkpoint(tmp_path):
    material = MohrCoulomb(friction_angle=30.0, dilation_angle=5.0, critical_friction_angle=27.0,
                           softening_strain=0.02, initial_stress=-P)
    assert isinstance(material, Material)
    material.allocate(3)
    grad = np.array([[[2e-3, 0.0], [0.0, -3e-3]]] * 3)
    first, second = material.evaluate(grad), material.evaluate(grad)
    np.testing.assert_array_equal(first.stress, second.stress)
    np.testing.assert_array_equal(first.tangent, second.tangent)
    assert first.costs["return_iterations"] > 0 and first.fields["return_region"][0] == FACE
    material.revert()
    np.testing.assert_array_equal(material.stress, np.broadcast_to(-P * np.eye(2), (3, 2, 2)))
    with pytest.raises(RuntimeError, match="evaluate"):
        material.commit()
    material.evaluate(grad)
    material.commit()
    np.testing.assert_array_equal(material.stress, first.stress)
    np.testing.assert_array_equal(material.committed_grad_u, grad)
    assert material.yielding.all() and (material.plastic_shear_strain > 0).all()
    assert (material.friction_angle_now < 30.0).all()
    path = tmp_path / "mc.npz"
    material.checkpoint(path)
    after = material.evaluate(grad)
    material.commit()
    other = MohrCoulomb(friction_angle=30.0, dilation_angle=5.0, critical_friction_angle=27.0,
                        softening_strain=0.02)
    other.restore(path)
    np.testing.assert_array_equal(other.stress, first.stress)
    np.testing.assert_array_equal(other.plastic_shear_strain, first.fields["plastic_shear_strain"])
    np.testing.assert_array_equal(other.committed_grad_u, grad)
    np.testing.assert_array_equal(other.evaluate(grad).stress, after.stress)
    # the total measure of response() is the committed ∇u plus the increment
    np.testing.assert_array_equal(other.response(2 * grad).stress, after.stress)


def test_restore_refuses_other_checkpoints(tmp_path):
    elastic = LinearElastic()
    elastic.allocate(2)
    elastic.checkpoint(tmp_path / "le.npz")
    material = MohrCoulomb()
    with pytest.raises(ValueError, match="not a checkpoint"):
        material.restore(tmp_path / "le.npz")
    first = MohrCoulomb(friction_angle=35.0)
    first.allocate(2)
    first.checkpoint(tmp_path / "mc.npz")
    with pytest.raises(ValueError, match="differ"):
        material.restore(tmp_path / "mc.npz")


def test_checkpoint_is_written_whole(tmp_path, monkeypatch):
    material = MohrCoulomb(initial_stress=-P)
    material.allocate(2)
    path = tmp_path / "mc.npz"
    material.checkpoint(path)
    before = path.read_bytes()

    def broken(fh, **arrays):
        fh.write(b"half")
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(mc_module.np, "savez", broken)
    with pytest.raises(OSError, match=r"mc\.npz"):
        material.checkpoint(path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["mc.npz"]


def test_non_finite_input_fails_that_point_only():
    material = MohrCoulomb(initial_stress=-P)
    material.allocate(3)
    grad = np.zeros((3, 2, 2))
    grad[1, 0, 1] = np.nan
    grad[2, 1, 1] = -1e-4
    response = material.evaluate(grad)
    assert response.status.tolist() == [PointStatus.OK, PointStatus.FAILED, PointStatus.OK]
    assert response.reasons[1] == FailureReason.NON_FINITE_INPUT
    np.testing.assert_array_equal(response.stress[1], -P * np.eye(2))
    assert np.isfinite(response.tangent).all() and np.isfinite(response.stress).all()
    with pytest.raises(RuntimeError, match="failed"):
        material.commit()
    np.testing.assert_array_equal(material.stress, np.broadcast_to(-P * np.eye(2), (3, 2, 2)))
    material.revert()
    assert material.evaluate(np.zeros((3, 2, 2))).ok


def test_local_newton_that_does_not_converge_fails_the_point(monkeypatch):
    monkeypatch.setattr(mc_module, "principal_return",
                        functools.partial(principal_return, max_iterations=1))
    material = MohrCoulomb(friction_angle=30.0, critical_friction_angle=25.0,
                           softening_strain=0.01, initial_stress=-P)
    material.allocate(2)
    grad = np.array([np.zeros((2, 2)), [[2e-3, 0.0], [0.0, -3e-3]]])
    response = material.evaluate(grad)
    assert response.status.tolist() == [PointStatus.OK, PointStatus.FAILED]
    assert response.reasons[1] == FailureReason.FAILED
    np.testing.assert_array_equal(response.stress[1], -P * np.eye(2))


def test_initial_stress_shapes_and_refusals():
    per_point = np.array([np.diag([-100e3, -200e3]), np.diag([-50e3, -60e3])])
    material = MohrCoulomb(initial_stress=per_point, initial_stress_zz=[-120e3, -55e3])
    material.allocate(2)
    np.testing.assert_array_equal(material.stress, per_point)
    np.testing.assert_array_equal(material.stress_zz, [-120e3, -55e3])
    same = MohrCoulomb(initial_stress=np.diag([-80e3, -100e3]))
    same.allocate(4)
    np.testing.assert_array_equal(same.stress_zz, np.full(4, -80e3))  # σzz = σxx
    with pytest.raises(ParameterError, match="3 points") as info:
        MohrCoulomb(initial_stress=per_point).allocate(3)
    assert info.value.field == "initial_stress"
    with pytest.raises(ParameterError) as info:
        MohrCoulomb(initial_stress=-P, initial_stress_zz=np.zeros(3)).allocate(2)
    assert info.value.field == "initial_stress_zz"
    outside = np.array([np.diag([-100e3, -100e3]), np.diag([-100e3, -500e3]),
                        np.diag([-100e3, -400e3])])
    with pytest.raises(ParameterError, match=r"2 of 3 points; the worst, point 1") as info:
        MohrCoulomb(initial_stress=outside).allocate(3)
    assert info.value.field == "initial_stress"
    for bad in ([1.0, 2.0], np.zeros((2, 3)), [[0.0, 1.0], [2.0, 0.0]], np.nan):
        with pytest.raises(ParameterError) as info:
            MohrCoulomb(initial_stress=bad)
        assert info.value.field == "initial_stress"


@pytest.mark.parametrize(("field", "kwargs"), [
    ("young", {"young": -1.0}),
    ("poisson", {"poisson": 0.5}),
    ("friction_angle", {"friction_angle": -1.0}),
    ("cohesion", {"friction_angle": 0.0}),
    ("critical_friction_angle", {"friction_angle": 0.0, "cohesion": 10e3,
                                 "critical_friction_angle": 0.0, "softening_strain": 0.1}),
    ("friction_angle", {"friction_angle": 90.0}),
    ("dilation_angle", {"dilation_angle": 31.0}),
    ("dilation_angle", {"dilation_angle": -1.0}),
    ("cohesion", {"cohesion": -1.0}),
    ("critical_friction_angle", {"critical_friction_angle": 31.0, "softening_strain": 0.1}),
    ("softening_strain", {"critical_friction_angle": 25.0}),
    ("softening_strain", {"softening_strain": -0.1}),
    ("young", {"young": "soft"}),
])
def test_refused_parameters_name_their_field(field, kwargs):
    with pytest.raises(ParameterError) as info:
        MohrCoulomb(**kwargs)
    assert info.value.field == field and isinstance(info.value, ValueError)


def test_aliases_and_run_parameters():
    with pytest.warns(RenamedWarning) as caught:
        material = MohrCoulomb(E=10e6, nu=0.2)
    assert "`E` is deprecated: it is now `young`" in str(caught[0].message)
    assert material.parameters == MohrCoulombParameters(young=10e6, poisson=0.2)
    assert MohrCoulomb.Parameters is MohrCoulombRunParameters
    run = MohrCoulombRunParameters(young=20e6, poisson=0.25, friction_angle=35.0,
                                   dilation_angle=5.0, cohesion=1e3,
                                   critical_friction_angle=30.0, softening_strain=0.05)
    with pytest.warns(RenamedWarning) as caught:
        old = MohrCoulombRunParameters(E=20e6, nu=0.25, phi=35.0, psi=5.0, cohesion=1e3,
                                       phi_cs=30.0, softening_strain=0.05)
    assert old == run and len(caught) == 5  # E, nu, phi, psi, phi_cs: each named
    made = MohrCoulomb.for_run(run, SimpleNamespace(confining=50e3))
    assert made.parameters == MohrCoulombParameters(20e6, 0.25, 35.0, 5.0, 1e3, 30.0, 0.05)
    made.allocate(1)
    np.testing.assert_array_equal(made.stress[0], -50e3 * np.eye(2))


# -- Newton ----------------------------------------------------------------------------------
def test_point_driver_newton_converges_quadratically():
    material = MohrCoulomb(friction_angle=30.0, dilation_angle=10.0,
                           critical_friction_angle=27.0, softening_strain=0.02,
                           initial_stress=-P)
    material.allocate(1)
    rec = drive_biaxial(material, 12, deps=-3e-4)
    first = int(np.argmax(rec["yielding"]))
    assert rec["yielding"][first] and first > 0
    seen = 0
    for residuals in rec["residuals"][first:]:
        r = np.array(residuals) / P
        assert len(r) <= 6, r
        for prev, nxt in itertools.pairwise(r[1:]):
            if prev > 1e-12:
                assert nxt <= 10.0 * prev ** 2, r
                seen += 1
    assert seen >= 3


@pytest.mark.parametrize("phi_cs", [None, 27.0])
def test_single_element_biaxial_with_newton_solver(phi_cs):
    """The project's Newton driver on one quad4 element to 2 % axial strain in 10 steps: the
    peak σ1/σ3 of the closed form, few iterations a step, and the residuals of the steps
    past yield falling quadratically."""
    problem = build_biaxial(BiaxialSetup(width=1.0, height=1.0, nx=1, ny=1, confining=P,
                                         axial_strain=0.02))
    material = MohrCoulomb(friction_angle=30.0, dilation_angle=10.0,
                           critical_friction_angle=phi_cs, softening_strain=0.01,
                           initial_stress=-P)
    solver = NewtonSolver(problem.basis, material, problem.loading, NewtonSettings(rtol=1e-9))
    ratios = []

    def observe(s: NewtonSolver, record) -> None:
        ratios.append(problem.axial_stress(s.reaction) / P)
    records = solver.run(10, on_step=observe)
    assert all(r.iterations <= 6 and r.cutbacks == 0 for r in records), [
        r.iterations for r in records]
    assert all(set(r.converged_by) == {"force"} for r in records)
    assert material.yielding.all()
    assert ratios[0] < 3.0 - 1e-3  # the first step is elastic
    assert ratios[-1] == pytest.approx(ratio_of(material.friction_angle_now[0]), rel=1e-7)
    if phi_cs is None:
        assert max(ratios) == pytest.approx(3.0, rel=1e-7)
    else:
        assert ratios[-1] == pytest.approx(ratio_of(phi_cs), rel=1e-7)
        assert 2.9 < max(ratios) < 3.0
    quadratic = 0
    for record in records:
        history = record.residual_history[0]
        for prev, nxt in itertools.pairwise(history):
            if prev > 1e-10:
                assert nxt <= 10.0 * prev ** 2, history
                quadratic += 1
    assert quadratic >= (1 if phi_cs is None else 4)


@pytest.mark.parametrize(("phi", "psi", "c", "phi_cs", "gs"), [
    (30.0, 0.0, 0.0, 30.0, 0.0), (30.0, 30.0, 0.0, 30.0, 0.0),
    (35.0, 10.0, 20e3, 25.0, 0.01)])
def test_return_lands_on_the_surface_in_order(phi, psi, c, phi_cs, gs):
    """Random trials: every returned state satisfies all six planes, keeps σ1 ≥ σ2 ≥ σ3,
    γp never falls, and on the face the stress drop follows the potential's normal."""
    lam, mu = MohrCoulombParameters().lame
    strength = MohrCoulombParameters(friction_angle=phi, dilation_angle=psi, cohesion=c,
                                     critical_friction_angle=phi_cs if gs else None,
                                     softening_strain=gs).strength()
    rng = np.random.default_rng(3)
    trial = rng.normal(scale=300e3, size=(20000, 3)) - rng.uniform(0, 300e3, size=(20000, 1))
    trial = -np.sort(-trial, axis=1)
    gamma_n = rng.uniform(0, 0.02, 20000)
    result = principal_return(trial, gamma_n, strength)
    assert result.converged.all()
    assert set(np.unique(result.region)) == {ELASTIC, FACE, EDGE_MAJOR, EDGE_MINOR, APEX}
    s = result.stress
    scale = np.abs(trial).max(axis=1) + c
    assert np.all(np.diff(s, axis=1) <= 1e-12 * scale[:, None])
    phi_now = strength.angles(result.gamma)[0]
    f = (s[:, 0] - s[:, 2]) + (s[:, 0] + s[:, 2]) * np.sin(phi_now) - 2 * c * np.cos(phi_now)
    assert np.all(f <= 1e-12 * scale)
    plastic = result.region != ELASTIC
    np.testing.assert_array_less(-1e-14, result.gamma - gamma_n)
    assert np.all(np.abs(f[plastic]) <= 1e-12 * scale[plastic])
    face = result.region == FACE
    t = np.sin(strength.angles(result.gamma[face])[1])
    normal = np.stack([1 + t, 0 * t, -(1 - t)], axis=1)
    drop = (trial - s)[face]
    expected = lam * normal.sum(axis=1)[:, None] + 2 * mu * normal
    factor = drop[:, 0] / expected[:, 0]
    np.testing.assert_allclose(drop, factor[:, None] * expected, rtol=1e-9,
                               atol=1e-9 * scale[face].max())
    np.testing.assert_allclose(result.gamma[face] - gamma_n[face], 2 * factor, rtol=1e-9)


# -- Tresca: φ = 0 (undrained clay) ----------------------------------------------------------
def test_tresca_yields_at_twice_the_cohesion():
    """φ = 0: a plane-strain biaxial path yields where σ1 − σ3 = 2c, whatever the pressure,
    with no plastic volume change (ψ = 0)."""
    c = 30e3
    for p in (50e3, 200e3):
        material = MohrCoulomb(friction_angle=0.0, cohesion=c, initial_stress=-p)
        material.allocate(1)
        rec = drive_biaxial(material, 60, p=p)
        plastic = rec["yielding"]
        assert plastic.any() and not plastic[0]
        deviator = rec["sxx"] - rec["syy"]
        assert deviator.max() == pytest.approx(2 * c, rel=1e-10)
        np.testing.assert_allclose(deviator[plastic], 2 * c, rtol=1e-10)
        assert np.all(deviator[~plastic] < 2 * c)
        assert np.all(rec["phi"] == 0.0)
        assert rec["gamma"][-1] > 0


def test_tresca_single_element_with_newton_solver():
    """One quad4 element under the Newton driver: the axial stress reaches p + 2c."""
    c = 25e3
    problem = build_biaxial(BiaxialSetup(width=1.0, height=1.0, nx=1, ny=1, confining=P,
                                         axial_strain=0.01))
    material = MohrCoulomb(friction_angle=0.0, cohesion=c, initial_stress=-P)
    solver = NewtonSolver(problem.basis, material, problem.loading, NewtonSettings(rtol=1e-9))
    axial = []
    records = solver.run(8, on_step=lambda s, r: axial.append(problem.axial_stress(s.reaction)))
    assert all(r.iterations <= 5 and r.cutbacks == 0 for r in records)
    assert material.yielding.all()
    assert axial[-1] == pytest.approx(P + 2 * c, rel=1e-8)


def _tresca_cases(rotation: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
    """Initial stresses, σzz and increments that land in each region of Tresca (c = 20 kPa)."""
    init = np.array([np.diag([-100e3, -100e3]), np.diag([-100e3, -130e3]),
                     np.diag([-100e3, -100e3]), [[-100e3, 1e3], [1e3, -100e3]],
                     np.diag([-100e3, -135e3])])
    zz = np.array([-100e3, -115e3, -135e3, -135e3, -135e3])
    grad = np.array([[[1e-5, 2e-6], [0.0, -1e-5]], [[2e-4, 3e-5], [-1e-5, -4e-4]],
                     [[5e-4, 0.0], [0.0, 5e-4]], [[5e-4, 1e-5], [-3e-5, 5e-4]],
                     [[2e-3, 0.0], [0.0, -1e-3]]])
    if rotation:
        grad = grad + np.array([[0.0, 4e-3], [-4e-3, 0.0]])
    return init, zz, grad, [ELASTIC, FACE, EDGE_MAJOR, EDGE_MAJOR, EDGE_MINOR]


@pytest.mark.parametrize("rotation", [False, True])
def test_tresca_tangent_matches_finite_differences_in_every_region(rotation):
    init, zz, grad, regions = _tresca_cases(rotation)
    material = MohrCoulomb(friction_angle=0.0, cohesion=20e3, initial_stress=init,
                           initial_stress_zz=zz, apex_tangent=0.0)
    material.allocate(len(init))
    response = material.evaluate(grad)
    assert response.ok
    assert response.fields["return_region"].astype(int).tolist() == regions
    assert np.isfinite(response.tangent).all()
    assert _fd_errors(material, grad).max() < 1e-5


def test_tresca_return_lands_on_the_prism_without_an_apex():
    """Random trials, φ = 0: no apex, every returned state has σ1 − σ3 ≤ 2c (= 2c where it
    yielded) in order, and the return keeps the mean stress (ψ = 0: no plastic volume)."""
    c = 20e3
    strength = MohrCoulombParameters(friction_angle=0.0, cohesion=c).strength()
    rng = np.random.default_rng(5)
    trial = rng.normal(scale=300e3, size=(20000, 3)) + rng.uniform(-300e3, 300e3, (20000, 1))
    trial = -np.sort(-trial, axis=1)
    result = principal_return(trial, np.zeros(20000), strength)
    assert result.converged.all() and np.isfinite(result.stress).all()
    assert set(np.unique(result.region)) == {ELASTIC, FACE, EDGE_MAJOR, EDGE_MINOR}
    s = result.stress
    scale = np.abs(trial).max(axis=1) + c
    assert np.all(np.diff(s, axis=1) <= 1e-12 * scale[:, None])
    plastic = result.region != ELASTIC
    np.testing.assert_allclose((s[:, 0] - s[:, 2])[plastic], 2 * c, rtol=0,
                               atol=1e-12 * scale.max())
    np.testing.assert_allclose(s.sum(axis=1), trial.sum(axis=1), rtol=0,
                               atol=1e-12 * scale.max())


def test_tresca_strip_footing_from_a_stress_free_start_near_prandtl():
    """A smooth rigid strip footing (half of it, B = 1 m) on weightless Tresca clay in small
    strain, from a stress-free start: the pressure levels off a little above Prandtl's
    (2 + π) c (measured 1.090 on this 10 × 6 quad8 mesh, 1.047 on 20 × 12)."""
    c, half = 10e3, 0.5
    data = select_boundaries(rectangle_mesh(2.5, 1.5, 10, 6, "quad8", grading=(1.0, 0.3),
                                            origin=(0.0, -1.5)),
                             {"footing": f"y = top and x <= {half}"})
    problem = build_problem(data, [Fixed("bottom"), Roller("left", 0), Roller("right", 0),
                                   RigidBody("footing", (0.0, -0.05), rough=False)])
    assert problem.boundaries["footing"].locations[0].max() == pytest.approx(half)
    material = MohrCoulomb(young=10e6, poisson=0.3, friction_angle=0.0, cohesion=c)
    solver = NewtonSolver(problem.basis, material, problem.loading,
                          NewtonSettings(formulation="small-strain", rtol=1e-8))
    q: list[float] = []
    solver.run(10, on_step=lambda s, r: q.append(
        -problem.boundary_force("footing", s.reaction)[1] / half))
    ratio = q[-1] / ((2 + math.pi) * c)
    assert 1.0 < ratio < 1.15, ratio
    assert q[-1] - q[-2] < 0.002 * q[-1]  # a plateau
