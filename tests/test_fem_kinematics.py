"""The finite-strain (updated-Lagrangian) formulation: its linearisation against finite
differences, the follower pressure, rigid rotations of a DEM element, and the small-strain
limit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from skfem import Basis, ElementQuad1, ElementVector, FacetBasis, MeshQuad

from granular_material.dem import DEMBatch, load_rve, save_rve
from granular_material.fem import (
    BiaxialSetup,
    LinearElastic,
    Loading,
    NewtonSettings,
    NewtonSolver,
    build_biaxial,
)
from granular_material.fem.boundary_value.biaxial import follower_traction
from granular_material.fem.kinematics import (
    Kinematics,
    first_piola,
    logarithmic_strain,
    reference_tangent,
)
from granular_material.multiscale import DEMMaterial
from granular_material.procedures import prepare_packing
from granular_material.runs import run_biaxial

EYE = np.eye(2)
small = arrays(np.float64, (2, 2), elements=st.floats(-0.2, 0.2))


@settings(max_examples=40, deadline=None)
@given(committed=small, step=small, seed=st.integers(0, 2**31 - 1),
       geometric=st.booleans())
def test_reference_tangent_is_the_derivative_of_the_first_piola_stress(
        committed: np.ndarray, step: np.ndarray, seed: int, geometric: bool) -> None:
    """For a material σ(G) = σ_n + D:G with G = ∇_X Δu F_n⁻¹, ∂P/∂(∇_X u) of
    P = J σ F⁻ᵀ is reference_tangent (the geometric terms included); without them it is
    the material part alone."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(2, 2, 2, 2)) * 3e7
    sigma_n = rng.normal(size=(2, 2)) * 1e5
    sigma_n = 0.5 * (sigma_n + sigma_n.T)
    f_n = EYE + committed

    def piola(grad_step: np.ndarray) -> np.ndarray:
        g = grad_step @ np.linalg.inv(f_n)
        sigma = sigma_n + np.einsum("ijkl,kl->ij", d, g)
        return first_piola(sigma[None], (f_n + grad_step)[None])[0]

    g = step @ np.linalg.inv(f_n)
    sigma = sigma_n + np.einsum("ijkl,kl->ij", d, g)
    analytic = reference_tangent(d[None], sigma[None], (f_n + step)[None], f_n[None],
                                 geometric=True)[0]
    h = 1e-7
    numeric = np.zeros((2, 2, 2, 2))
    for k in range(2):
        for m in range(2):
            e = np.zeros((2, 2))
            e[k, m] = h
            numeric[:, :, k, m] = (piola(step + e) - piola(step - e)) / (2 * h)
    np.testing.assert_allclose(analytic, numeric, rtol=1e-5, atol=1e-4 * np.abs(d).max())
    if not geometric:
        material = reference_tangent(d[None], sigma[None], (f_n + step)[None], f_n[None],
                                     geometric=False)[0]
        j = np.linalg.det(f_n + step)
        f_inv, fn_inv = np.linalg.inv(f_n + step), np.linalg.inv(f_n)
        np.testing.assert_allclose(
            material, j * np.einsum("ijkm,Mm,Jj->iJkM", d, fn_inv, f_inv), rtol=1e-12)


def test_material_gradients_of_the_steps_multiply_to_the_deformation_gradient() -> None:
    """Driven step by step with G = ∇_X Δu F_n⁻¹, the products (I + G) telescope to F."""
    kin = Kinematics("updated-lagrangian")
    rng = np.random.default_rng(3)
    total = np.zeros((1, 2, 2))
    product = np.eye(2)[None]
    for _ in range(6):
        step = rng.normal(size=(1, 2, 2)) * 0.05
        product = (EYE + kin.material_gradient(total, step)) @ product
        total = total + step
    np.testing.assert_allclose(product, EYE + total, rtol=1e-12, atol=1e-14)
    assert np.array_equal(Kinematics("small-strain").material_gradient(total, step), step)


def test_logarithmic_strain_of_a_stretch_and_a_rotation() -> None:
    """Hencky strain: ln λ along a stretch's axes, nothing for a rigid rotation, tr = ln J."""
    theta = 0.7
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    stretch = np.diag([1.3, 0.8])
    eps = logarithmic_strain(np.stack([stretch - EYE, rot - EYE, rot @ stretch - EYE]))
    np.testing.assert_allclose(eps[0], np.diag(np.log([1.3, 0.8])), atol=1e-14)
    np.testing.assert_allclose(eps[1], 0.0, atol=1e-14)
    np.testing.assert_allclose(eps[2], rot @ np.diag(np.log([1.3, 0.8])) @ rot.T, atol=1e-14)
    assert np.trace(eps[2]) == pytest.approx(np.log(1.3 * 0.8))


def _rotation(theta: float) -> np.ndarray:
    return np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])


@settings(max_examples=200, deadline=None)
@given(log_stretch=st.lists(st.floats(-3.0, 3.0), min_size=2, max_size=2),
       scale=st.sampled_from([1e-9, 1e-5, 1e-2, 1.0]),
       theta=st.floats(0.0, 2 * np.pi), phi=st.floats(0.0, 2 * np.pi),
       flip=st.booleans())
def test_logarithmic_strain_closed_form(log_stretch: list[float], scale: float, theta: float,
                                        phi: float, flip: bool) -> None:
    """The closed form against F = R diag(λ) Q, whose Hencky strain is R diag(ln λ) Rᵀ, from
    strains of 10⁻⁹ to stretches of e³ (an inverted F, a reflection Q, included: b = F Fᵀ
    stays positive definite), and against the eigendecomposition of F Fᵀ."""
    log_lam = scale * np.asarray(log_stretch)
    rot = _rotation(theta)
    q = _rotation(phi) @ (np.diag([1.0, -1.0]) if flip else EYE)
    f = rot @ np.diag(np.exp(log_lam)) @ q
    exact = rot @ np.diag(log_lam) @ rot.T
    eps = logarithmic_strain((f - EYE)[None])[0]
    size = max(1.0, float(np.abs(log_lam).max()))
    np.testing.assert_allclose(eps, exact, rtol=0, atol=4e-15 * size * np.exp(abs(log_lam).max()))
    b = f @ f.T
    values, vectors = np.linalg.eigh(b)
    by_eigh = 0.5 * vectors @ np.diag(np.log(values)) @ vectors.T
    np.testing.assert_allclose(eps, by_eigh, rtol=0, atol=1e-8 * size)
    assert eps[0, 1] == eps[1, 0]


def test_follower_pressure_acts_on_the_current_sides() -> None:
    """A unit square deformed by F: the pressure's nodal forces on the right side add up to
    −p·cof(F)·N·L, the force of p on the current side (its length and its normal)."""
    mesh = MeshQuad.init_tensor(np.linspace(0, 1, 3), np.linspace(0, 1, 3))
    basis = Basis(mesh, ElementVector(ElementQuad1()))
    right = mesh.facets_satisfying(lambda x: np.abs(x[0] - 1.0) < 1e-12)
    facets = FacetBasis(mesh, basis.elem, facets=right, intorder=2)
    f = np.array([[0.9, 0.2], [-0.1, 1.2]])
    u = basis.project(lambda x: np.einsum("ij,j...->i...", f - EYE, x))
    forces = follower_traction.assemble(facets, p=1e5, u=facets.interpolate(u))
    current = f @ np.array([0.0, 1.0])  # the side's current tangent vector, length L = 1
    normal_length = np.array([current[1], -current[0]])  # outward n·ds
    np.testing.assert_allclose([forces[0::2].sum(), forces[1::2].sum()],
                               -1e5 * normal_length, rtol=1e-12)


def test_small_strain_formulation_is_unchanged_and_finite_strain_tends_to_it() -> None:
    """A linear-elastic element: small strain as before; at 0.01 % axial strain the two
    formulations agree to 1e-3 relative; at 10 % the finite-strain one holds the current
    sides at σxx = −p exactly (a follower pressure) and reports the current width."""
    setup = BiaxialSetup(width=1.0, height=1.0, nx=1, ny=1, confining=1e5, axial_strain=1e-4)
    results = {}
    for formulation in ("small-strain", "updated-lagrangian"):
        material = LinearElastic(young=60e6, poisson=0.3, initial_stress=-1e5)
        results[formulation] = run_biaxial(
            setup, material, 4, NewtonSettings(formulation=formulation, rtol=1e-10))
    small_strain, finite = results["small-strain"], results["updated-lagrangian"]
    np.testing.assert_allclose(finite.steps["syy"], small_strain.steps["syy"], rtol=1e-3)
    big = BiaxialSetup(width=1.0, height=1.0, nx=2, ny=2, confining=1e5, axial_strain=0.1)
    result = run_biaxial(big, LinearElastic(young=60e6, poisson=0.3, initial_stress=-1e5), 10,
                         NewtonSettings(formulation="updated-lagrangian", rtol=1e-10))
    assert result.error is None
    last = result.steps.iloc[-1]
    assert last["sxx"] == pytest.approx(-1e5, rel=1e-9)
    # the platen stress is the reaction over the current width, the volume average σyy
    assert last["platen_stress"] == pytest.approx(-last["syy"], rel=1e-9)


@pytest.fixture(scope="module")
def rve64(tmp_path_factory: pytest.TempPathFactory):
    """A frictional 64-disc RVE (seed 1) at 100 kPa, as a file."""
    path = tmp_path_factory.mktemp("rve") / "rve64.npz"
    save_rve(path, prepare_packing(n_disc=64, seed=1, pressure=1e5, device="cpu").to_data())
    return path


def test_a_rigidly_rotated_dem_element_rotates_its_stress(rve64) -> None:
    """Every node of a DEM element prescribed on a rigid rotation of 0.3 rad in 6 steps:
    with finite strain the RVEs are turned by exactly that rotation (the stress becomes
    RσRᵀ within the DEM's own drift); small strain stretches them instead."""
    theta = 0.3
    data = load_rve(rve64)
    problem = build_biaxial(BiaxialSetup(width=0.01, height=0.01, nx=1, ny=1,
                                         confining=1e5, axial_strain=0.1))
    basis = problem.basis
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    end = basis.project(lambda x: np.einsum("ij,j...->i...", rot - EYE, x))
    dofs = np.arange(basis.N)
    loading = Loading(dirichlet_dofs=dofs, dirichlet_end=end,
                      force_start=np.zeros(basis.N), force_end=np.zeros(basis.N))
    sigma0 = DEMBatch(data, device="cpu").homogenize().stress[0]
    sigma0 = 0.5 * (sigma0 + sigma0.T)
    rotated = {}
    for formulation in ("updated-lagrangian", "small-strain"):
        material = DEMMaterial(rve=rve64, replicate=True, device="cpu",
                               max_strain_per_step=1e-4)
        solver = NewtonSolver(basis, material, loading,
                              NewtonSettings(formulation=formulation))
        solver.run(6)
        rotated[formulation] = solver.response.stress
    expected = rot @ sigma0 @ rot.T
    scale = abs(np.trace(sigma0)) / 2
    assert np.abs(rotated["updated-lagrangian"] - expected).max() < 0.01 * scale
    assert np.abs(rotated["small-strain"] - expected).max() > 0.2 * scale
