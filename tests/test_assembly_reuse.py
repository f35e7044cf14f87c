"""Assembly that keeps what does not change (issue 62): the tangent stiffness from a basis's
kept pattern equals scikit-fem's assembly to round-off on every element the meshes use, the
finite-strain tangent by batched products equals the einsum one to round-off, and a noisy
material (the DEM) keeps the assembly of before, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
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
)

from granular_material.fem import kinematics
from granular_material.fem.forms import stiffness, tangent_form
from granular_material.fem.layout import to_quadrature
from granular_material.fem.solver.newton import NewtonSolver


def _basis(mesh, element) -> Basis:
    return Basis(mesh.refined(2), ElementVector(element))


@pytest.mark.parametrize(("mesh", "element"), [
    (MeshQuad(), ElementQuad1()), (MeshQuad(), ElementQuadS2()), (MeshQuad(), ElementQuad2()),
    (MeshTri(), ElementTriP1()), (MeshTri(), ElementTriP2())])
def test_the_kept_pattern_assembles_scikit_fems_matrix(mesh, element):
    basis = _basis(mesh, element)
    n = basis.nelems * basis.X.shape[-1]
    rng = np.random.default_rng(4)
    before = None
    for _ in range(2):  # the second assembly reuses the pattern
        d = rng.standard_normal((n, 2, 2, 2, 2)) * 1e7
        reference = tangent_form.assemble(basis, D=to_quadrature(d, basis.X.shape[-1]))
        kept = stiffness(basis, d)
        assert kept.shape == reference.shape
        assert abs(kept - reference).max() <= 1e-14 * abs(reference).max()
        assert np.array_equal(kept.indptr, reference.indptr)
        assert np.array_equal(kept.indices, reference.indices)
        exact = stiffness(basis, d, kept=False)  # as before issue 62, bit for bit
        assert (exact != reference).nnz == 0
        assert before is None or not np.array_equal(before, kept.data)
        before = kept.data


@pytest.mark.parametrize("geometric", [True, False])
def test_the_batched_tangent_is_the_einsum_one(geometric):
    rng = np.random.default_rng(5)
    n = 300
    d = rng.standard_normal((n, 2, 2, 2, 2)) * 1e7
    sigma = rng.standard_normal((n, 2, 2)) * 1e5
    f = np.eye(2) + rng.standard_normal((n, 2, 2)) * 0.05
    f_n = np.eye(2) + rng.standard_normal((n, 2, 2)) * 0.05
    einsum = kinematics.reference_tangent(d, sigma, f, f_n, geometric, batched=False)
    batched = kinematics.reference_tangent(d, sigma, f, f_n, geometric)
    assert np.abs(batched - einsum).max() <= 1e-14 * np.abs(einsum).max()
    # the geometric terms alone (no material tangent)
    zero = np.zeros_like(d)
    einsum = kinematics.reference_tangent(zero, sigma, f, f_n, geometric, batched=False)
    batched = kinematics.reference_tangent(zero, sigma, f, f_n, geometric)
    assert np.abs(batched - einsum).max() <= 1e-14 * max(np.abs(einsum).max(), 1.0)


class _Material:
    """The least a Newton solver asks of a material at construction."""

    noisy = False

    def __init__(self, n_points: int) -> None:
        self.n_points = n_points


class _NoisyMaterial(_Material):
    noisy = True


def test_a_noisy_material_assembles_as_before():
    from granular_material.fem import BiaxialSetup, build_biaxial

    problem = build_biaxial(BiaxialSetup(nx=1, ny=2))
    points = problem.setup.n_points
    plain = NewtonSolver(problem.basis, _Material(points), problem.loading)
    noisy = NewtonSolver(problem.basis, _NoisyMaterial(points), problem.loading)
    assert plain.kinematics.batched and plain._kept
    assert not noisy.kinematics.batched and not noisy._kept
