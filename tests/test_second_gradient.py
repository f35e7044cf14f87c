"""Chambon's local second gradient (granular_material.fem.regularisation): the patch test,
the tangent against finite differences, Newton's quadratic convergence with Mohr–Coulomb,
a resume that continues exactly, the refusals, and runs without it unchanged."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pytest
import tomllib
from run_helpers import PRESSED_BLOCK
from skfem import (
    Basis,
    ElementQuad1,
    ElementQuad2,
    ElementQuadS2,
    ElementTriP1,
    ElementTriP2,
    ElementVector,
    MeshQuad,
    MeshTri,
    asm,
    condense,
    solve,
)
from skfem.models.elasticity import lame_parameters, linear_elasticity

from granular_material.errors import ParameterError
from granular_material.fem import (
    BiaxialSetup,
    MohrCoulomb,
    NewtonSettings,
    NewtonSolver,
    Regularisation,
    SecondGradient,
    add_second_gradient,
    build_biaxial,
)
from granular_material.fem.forms import gauss_points_grad, internal_force, stiffness
from granular_material.fem.kinematics import Kinematics
from granular_material.fem.regularisation import initial_shear_modulus, second_gradient_modulus
from granular_material.runs.boundary_value.runner import run_boundary_value
from granular_material.runs.boundary_value.spec import bvp_from_dict
from granular_material.runs.checkpoint_files import state_arrays
from granular_material.runs.runner import run_biaxial
from granular_material.runs.spec import (
    MaterialSpec,
    ProblemSpec,
    RegularisationSpec,
    RunSpec,
    SpecError,
)

QUADRATIC = [(MeshQuad, ElementQuadS2, 2), (MeshQuad, ElementQuad2, 3), (MeshTri, ElementTriP2, 3)]


def _softening() -> MohrCoulomb:
    return MohrCoulomb(friction_angle=35, critical_friction_angle=28, softening_strain=0.02,
                       dilation_angle=5)


def _linear_field(basis: Basis, grad: np.ndarray) -> np.ndarray:
    x = basis.doflocs
    u = np.zeros(basis.N)
    u[0::2] = grad[0, 0] * x[0, 0::2] + grad[0, 1] * x[1, 0::2]
    u[1::2] = grad[1, 0] * x[0, 1::2] + grad[1, 1] * x[1, 1::2]
    return u


@pytest.mark.parametrize("mesh_type, element, order", QUADRATIC)
def test_a_linear_displacement_gives_v_equal_to_its_gradient_and_no_double_stress(
        mesh_type, element, order):
    """Patch test: the boundary displaced as a linear field, the interior free; u is that
    field, v = ∇u everywhere (so Σ = D ∇v = 0) and λ = 0, on a distorted mesh."""
    mesh = mesh_type.init_tensor(np.linspace(0, 1, 5), np.linspace(0, 2, 7))
    mesh = mesh.__class__(mesh.p + 0.05 * np.sin(3 * mesh.p[::-1]), mesh.t)  # distorted
    basis = Basis(mesh, ElementVector(element()), intorder=order)
    k = asm(linear_elasticity(*lame_parameters(1e7, 0.3)), basis)
    terms = SecondGradient(basis, 50.0)
    grad = np.array([[0.01, 0.003], [-0.002, 0.02]])
    exact = _linear_field(basis, grad)
    boundary = basis.get_dofs().all()
    k_all, residual = add_second_gradient(terms, k, np.zeros(basis.N), np.zeros(basis.N),
                                          np.zeros(terms.n_extra))
    x = np.zeros(k_all.shape[0])
    x[boundary] = exact[boundary]
    x = solve(*condense(k_all, -residual, x=x, D=boundary))
    u, extra = x[:basis.N], x[basis.N:]
    np.testing.assert_allclose(u, exact, atol=1e-14)
    np.testing.assert_allclose(terms.microstructure(extra), np.repeat(
        grad.reshape(4, 1), terms.n_v, axis=1), atol=1e-13)
    assert np.abs(terms.multipliers(extra)).max() < 1e-6 * 1e7 * 0.02  # ≪ the stress
    # and the terms' own residual of (u, v = ∇u, λ = 0) vanishes
    v_exact = np.concatenate([np.full(terms.n_v, g) for g in grad.ravel()])
    state = np.concatenate([v_exact, np.zeros(4 * terms.n_lambda)])
    assert np.abs(terms.residual(exact, state)).max() < 1e-12


@pytest.mark.parametrize("element", [ElementQuad1, ElementTriP1])
def test_linear_elements_are_refused_naming_those_that_work(element):
    mesh = (MeshQuad if element is ElementQuad1 else MeshTri)()
    with pytest.raises(ParameterError, match="quad8, quad9, tri6"):
        SecondGradient(Basis(mesh, ElementVector(element())), 1.0)


def test_the_run_spec_refuses_a_linear_element_and_a_length_without_the_model():
    with pytest.raises(SpecError, match="quad8, quad9, tri6") as refused:
        RunSpec(problem=ProblemSpec(test="biaxial", element="quad4"),
                material=MaterialSpec(name="mohr-coulomb"),
                regularisation=RegularisationSpec(model="second-gradient",
                                                  internal_length=0.005))
    assert refused.value.field == "model"
    with pytest.raises(SpecError) as refused:
        RegularisationSpec(internal_length=0.005)
    assert refused.value.field == "internal_length"
    for length in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(SpecError):
            RegularisationSpec(model="second-gradient", internal_length=length)


def test_the_modulus_follows_the_initial_shear_modulus_and_the_length():
    material = _softening()
    material.allocate(4)
    response = material.evaluate(np.zeros((4, 2, 2)))
    g0 = initial_shear_modulus(response.tangent)
    assert g0 == pytest.approx(60e6 / (2 * 1.3), rel=1e-12)  # E / 2(1 + ν)
    assert second_gradient_modulus(g0, 0.005) == pytest.approx(g0 * 0.0005 ** 2)
    with pytest.raises(ValueError, match="shear modulus"):
        initial_shear_modulus(np.zeros((3, 2, 2, 2, 2)))


def _plastic_state(formulation: str):
    """A regularised 2 × 4 quad8 specimen's solver, its state moved by a field of ∇u that
    makes points yield, and the residual function of [u, extra] at it."""
    setup = BiaxialSetup(nx=2, ny=4, element="quad8", platens="rough")
    problem = build_biaxial(setup)
    material = _softening()
    solver = NewtonSolver(problem.basis, material, problem.loading,
                          NewtonSettings(formulation=formulation),
                          Regularisation("second-gradient", 0.01))
    terms = solver.second_gradient
    rng = np.random.default_rng(3)
    basis = problem.basis
    u0 = _linear_field(basis, np.array([[0.004, 0.0], [0.0, -0.012]]))
    u0 += 2e-4 * rng.standard_normal(basis.N) * 0.05
    extra0 = 1e-3 * rng.standard_normal(terms.n_extra)
    kin = Kinematics(formulation)
    grad_n = np.zeros((setup.n_points, 2, 2))

    def residual(u: np.ndarray, extra: np.ndarray) -> np.ndarray:
        grad = gauss_points_grad(basis, u)
        response = material.evaluate(kin.material_gradient(grad_n, grad))
        f = internal_force(basis, kin.assembled_stress(response.stress, grad))
        return np.concatenate([f, np.zeros(terms.n_extra)]) + terms.residual(u, extra)

    grad = gauss_points_grad(basis, u0)
    response = material.evaluate(kin.material_gradient(grad_n, grad))
    tangent = terms.augment(stiffness(basis, kin.assembled_tangent(
        response.tangent, response.stress, grad_n, grad)))
    return basis, terms, u0, extra0, residual, tangent


@pytest.mark.parametrize("formulation", ["small-strain", "updated-lagrangian"])
def test_the_block_tangent_matches_finite_differences(formulation):
    basis, terms, u0, extra0, residual, tangent = _plastic_state(formulation)
    rng = np.random.default_rng(7)
    direction = rng.standard_normal(basis.N + terms.n_extra)
    direction[:basis.N] *= 1e-3 * np.abs(u0).max()
    direction[basis.N:] *= 1e-3 * np.abs(extra0).max()
    h = 1e-3
    plus = residual(u0 + h * direction[:basis.N], extra0 + h * direction[basis.N:])
    minus = residual(u0 - h * direction[:basis.N], extra0 - h * direction[basis.N:])
    numeric = (plus - minus) / (2 * h)
    analytic = tangent @ direction
    scale = np.abs(analytic).max()
    assert np.abs(numeric - analytic).max() < 1e-4 * scale
    # the second gradient's own blocks are exact: the rows of v and λ agree to round-off
    np.testing.assert_allclose(numeric[basis.N:], analytic[basis.N:], rtol=0,
                               atol=1e-8 * np.abs(analytic[basis.N:]).max())


def test_newton_converges_quadratically_with_mohr_coulomb():
    """Past the peak, with plastic points in every step (small strain, where the
    Mohr–Coulomb tangent is consistent): the order log r_{k+1} / log r_k of the residuals
    below 1e-3 is near 2 (a linear rate of 1e-2 would give at most 1.5), and no step is cut
    back."""
    setup = BiaxialSetup(nx=4, ny=8, element="quad8", platens="rough", axial_strain=0.02)
    result = run_biaxial(setup, _softening(), 8, NewtonSettings(rtol=1e-12, atol=1e-12,
                                                                 formulation="small-strain"),
                         regularisation=Regularisation("second-gradient", 0.005))
    assert result.error is None
    orders = []
    for record in result.records:
        assert record.cutbacks == 0
        for attempt in record.residual_history:
            r = np.asarray(attempt)
            orders += [np.log(b) / np.log(a) for a, b in pairwise(r)
                       if a < 1e-3 and b > 1e-14]
    assert len(orders) >= 8
    assert np.median(orders) >= 1.6, orders


@pytest.mark.parametrize("formulation", ["small-strain", "updated-lagrangian"])
def test_a_regularised_run_resumed_from_its_state_continues_exactly(formulation):
    """Bit for bit, in small strain and in finite strain (the state keeps the internal force
    its step assembled, the second gradient's part included)."""
    setup = BiaxialSetup(nx=2, ny=4, element="tri6", platens="rough", axial_strain=0.02)
    regularisation = Regularisation("second-gradient", 0.005)

    def solver_of(material):
        problem = build_biaxial(setup)
        return NewtonSolver(problem.basis, material, problem.loading,
                            NewtonSettings(formulation=formulation), regularisation)

    whole = solver_of(_softening())
    whole.run(4)
    first_material = _softening()
    first = solver_of(first_material)
    for k in range(2):
        first.step((k + 1) / 4, k + 1)
    state = first.committed_state()
    assert state.second_gradient is not None and state.second_gradient_modulus > 0
    arrays = state_arrays(2, "material.npz", state, {"step": 2, "files": {}})
    assert set(arrays) >= {"second_gradient", "second_gradient_modulus"}
    second = solver_of(first_material)  # the material holds the committed state
    second.resume(state)
    for k in range(2, 4):
        second.step((k + 1) / 4, k + 1)
    np.testing.assert_array_equal(second.u, whole.u)
    np.testing.assert_array_equal(second.extra, whole.extra)
    plain = solver_of(_softening())
    plain.regularisation = Regularisation()
    with pytest.raises(ValueError, match="regularised"):
        plain.resume(state)


#: σ1/σ3 of a 2 × 4 Mohr–Coulomb softening specimen at each of 6 steps, as the code gave
#: them before the second gradient existed (hex floats): without it, a run is unchanged
BEFORE = {
    "quad8": ["-0x0.0p+0", "0x1.caeb30ccd2d43p+1", "0x1.70e883cf51ce7p+1", "0x1.6ac20fd3ee384p+1",
              "0x1.6b5c9116bcc7ep+1", "0x1.6bbb0dfd0c329p+1", "0x1.6bd109b42b8a6p+1"],
    "tri6": ["-0x0.0p+0", "0x1.c9d2c162f6d77p+1", "0x1.8e54367bf55a6p+1", "0x1.87675e55994eep+1",
             "0x1.81e5f73376870p+1", "0x1.8319d98ab112fp+1", "0x1.8438972bd1ab6p+1"],
}


@pytest.mark.parametrize("element, formulation", [("quad8", "updated-lagrangian"),
                                                  ("tri6", "small-strain")])
def test_without_the_option_a_run_is_what_it_was(element, formulation):
    setup = BiaxialSetup(nx=2, ny=4, element=element, platens="rough", axial_strain=0.03)
    settings = NewtonSettings(formulation=formulation, rtol=1e-8)
    default = run_biaxial(setup, _softening(), 6, settings)
    named = run_biaxial(setup, _softening(), 6, settings, regularisation=Regularisation())
    np.testing.assert_array_equal(default.steps["stress_ratio"], named.steps["stress_ratio"])
    before = np.array([float.fromhex(v) for v in BEFORE[element]])
    np.testing.assert_allclose(default.steps["stress_ratio"], before, rtol=1e-11, atol=0)


def _scene(element: str) -> str:
    return (f'test = "boundary-value"\nsteps = 3\n[mesh]\nsize = [0.2, 0.1]\n'
            f'elements = [4, 2]\nelement = "{element}"\n'
            '[regularisation]\nmodel = "second-gradient"\ninternal_length = 0.02\n'
            + PRESSED_BLOCK.format(base="bottom"))


def test_a_boundary_value_scene_runs_regularised_and_refuses_linear_elements(tmp_path):
    spec = bvp_from_dict(tomllib.loads(_scene("tri6")), tmp_path)
    assert spec.regularisation == RegularisationSpec(model="second-gradient",
                                                     internal_length=0.02)
    outcome = run_boundary_value(spec, out=tmp_path / "run")
    assert outcome.error is None and len(outcome.steps) == 4  # step 0 and three
    # the summary says what ran: D = G (ℓ/10)², G = E / 2(1 + ν) of the linear-elastic block
    said = outcome.summary["regularisation"]
    assert said["model"] == "second-gradient" and said["internal_length"] == 0.02
    assert said["second_gradient_modulus"] == pytest.approx(60e6 / 2.6 * 0.002 ** 2,
                                                            rel=1e-12)
    with pytest.raises(SpecError) as refused:
        bvp_from_dict(tomllib.loads(_scene("quad4")), tmp_path)
    assert refused.value.field == "regularisation.model"
    assert "quad8, quad9, tri6" in str(refused.value)


def test_a_regularised_step_with_nothing_to_do_is_accepted(tmp_path):
    """The block held where it stands: once step 1 has brought the free sides into
    equilibrium with the initial pressure, steps 2 and 3 have nothing to do, regularised
    too (one evaluation each)."""
    text = _scene("quad8").replace("value = -0.001", "value = 0.0")
    outcome = run_boundary_value(bvp_from_dict(tomllib.loads(text), tmp_path),
                                 out=tmp_path / "held")
    assert outcome.error is None and len(outcome.steps) == 4
    assert outcome.steps["iterations"].iloc[2:].tolist() == [1, 1]
