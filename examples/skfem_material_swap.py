"""A plain scikit-fem script whose constitutive law is a granular-material plugin.

A 2 × 2-element block (plane strain) under 100 kPa lateral confinement is compressed
by 1 % through its top edge: the script assembles the tangent stiffness and the internal
force from per-Gauss-point arrays and runs its own Newton loop. Swap the material by
changing the one line marked below:

    MATERIAL = "linear-elastic"   ->   MATERIAL = "dem"

(or pass the name as the first argument: ``python skfem_material_swap.py dem``).
"""

import sys

import numpy as np
from skfem import (
    Basis,
    BilinearForm,
    ElementQuad1,
    ElementVector,
    FacetBasis,
    LinearForm,
    MeshQuad,
    condense,
    solve,
)

from granular_material.fem import create_material, to_points, to_quadrature

MATERIAL = "linear-elastic"  # <- the one line: "linear-elastic" or "dem"

P = 100e3  # lateral confinement [Pa], compression
PARAMETERS = {
    "linear-elastic": {"young": 60e6, "poisson": 0.3, "initial_stress": -P},
    "dem": {"particles": 64, "seed": 1, "pressure": P, "device": "cpu"},
}


@BilinearForm
def stiffness(u, v, w):
    return np.einsum("ijkl...,kl...,ij...->...", w.D, u.grad, v.grad)  # ∫ ∇v : D : ∇u


@LinearForm
def internal_force(v, w):
    return np.einsum("ij...,ij...->...", w.sigma, v.grad)  # ∫ ∇v : σ


@LinearForm
def confinement(v, w):
    return -P * (w.n[0] * v[0] + w.n[1] * v[1])  # t = −P n on the sides


def main(name: str = MATERIAL, axial_strain: float = 0.01, steps: int = 5) -> list[float]:
    """Run the test; returns the axial stress [Pa] (compression +) after every step."""
    mesh = MeshQuad().refined(1)  # unit square, 2 × 2 elements
    basis = Basis(mesh, ElementVector(ElementQuad1()), intorder=2)  # 2 × 2 Gauss points
    nqp = basis.X.shape[-1]
    material = create_material(name, **PARAMETERS[name])
    material.allocate(basis.nelems * nqp)

    sides = mesh.facets_satisfying(lambda x: np.isclose(x[0], 0) | np.isclose(x[0], 1))
    f_ext = confinement.assemble(FacetBasis(mesh, basis.elem, facets=sides, intorder=2))
    bottom = basis.get_dofs(lambda x: np.isclose(x[1], 0))
    top = basis.get_dofs(lambda x: np.isclose(x[1], 1)).nodal["u^2"]
    corner = mesh.nodes_satisfying(lambda x: np.isclose(x[0], 0) & np.isclose(x[1], 0))
    D = np.concatenate([bottom.nodal["u^2"], basis.nodal_dofs[0, corner], top])  # + pin

    u = np.zeros(basis.N)
    response = material.evaluate(np.zeros((material.n_points, 2, 2)))
    material.revert()
    history = []
    for step in range(1, steps + 1):
        du = np.zeros_like(u)
        du[top] = -axial_strain * step / steps - u[top]  # prescribed top displacement
        for _ in range(25):
            grad = to_points(basis.interpolate(du).grad)  # ∇u since the last commit
            response = material.evaluate(grad)
            sigma = to_quadrature(response.stress, nqp)
            residual = internal_force.assemble(basis, sigma=sigma) - f_ext
            free = np.setdiff1d(np.arange(basis.N), D)
            if np.linalg.norm(residual[free]) <= 1e-3 * P * 1.0:  # 0.1 % of P on the 1 m edge
                break
            K = stiffness.assemble(basis, D=to_quadrature(response.tangent, nqp))
            du += solve(*condense(K, -residual, D=D))
        else:
            raise RuntimeError(f"step {step} did not converge")
        material.commit()
        u += du
        reaction = internal_force.assemble(basis, sigma=sigma) - f_ext
        history.append(-reaction[top].sum() / 1.0)  # axial stress [Pa], width 1 m
        print(f"{name}: step {step} axial strain {axial_strain * step / steps:.4f} "
              f"axial stress {history[-1] / 1e3:.1f} kPa")
    return history


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else MATERIAL)
