"""A scikit-fem script whose constitutive law is a granular-material plugin.

A unit block (plane strain) under a lateral confinement P = 100 kPa is compressed by 1 %
through its top edge, in the style of scikit-fem's own nonlinear examples: the forms take
the stress and the tangent at the quadrature points (``w.sigma``, ``w.D``), the material is
asked for them with the *total* displacement gradient in scikit-fem's layout
(``basis.interpolate(u)``, a ``DiscreteField``; ∇u quadrature-last, ``(2, 2, nelems, nqp)``)
and answers in the same layout, and the script runs its own Newton loop. Swap the material
by changing the one line marked below:

    MATERIAL = "linear-elastic"   ->   MATERIAL = "mohr-coulomb"   or   "dem"

and the element (``ELEMENT = "quad1"``: MeshQuad with Q1, 2 × 2 Gauss points; ``"tri2"``:
MeshTri with P2, 3 points a triangle). From the command line (installed with the package)::

    python -m granular_material_examples.skfem_material_swap dem tri2

The Newton loop converges for both materials because it judges the *correction*, not the
residual: an increment is done when ‖δu‖ ≤ 10⁻² ‖u − u_committed‖ (Guo & Zhao's test, the
one the project's commands use). The DEM stress carries noise (each evaluation re-runs the
RVEs), so ‖R‖ stalls on a floor that a tight residual test may never pass; and the DEM
tangent is stiffer than the RVE's response (the contact network without the discs'
rearrangement), so Newton converges linearly, several iterations an increment, not
quadratically. For the linear-elastic block the first correction is exact and the second is
zero. See docs/guide/scikit-fem.md.
"""

from __future__ import annotations

import sys

import numpy as np
from skfem import (
    Basis,
    BilinearForm,
    ElementQuad1,
    ElementTriP2,
    ElementVector,
    FacetBasis,
    LinearForm,
    MeshQuad,
    MeshTri,
    condense,
    solve,
)

from granular_material.fem import create_material

MATERIAL = "linear-elastic"  # <- the one line: "linear-elastic", "mohr-coulomb" or "dem"
ELEMENT = "quad1"  # "quad1" (MeshQuad, Q1) or "tri2" (MeshTri, P2)

P = 100e3  # lateral confinement [Pa], compression
PARAMETERS = {
    "linear-elastic": {"young": 60e6, "poisson": 0.3, "initial_stress": -P},
    # φ, ψ in degrees; with ψ = 0 (no dilation) plastic flow is isochoric and the P2 mesh's
    # stiffness turns singular once every point yields, so a little dilation
    "mohr-coulomb": {"young": 60e6, "poisson": 0.3, "friction_angle": 30.0, "dilation_angle": 10.0,
                     "initial_stress": -P},
    "dem": {"particles": 64, "seed": 1, "confining": P, "device": "cpu"},
}
ELEMENTS = {  # mesh, element, quadrature order
    "quad1": (MeshQuad, ElementQuad1, 2),  # 2 × 2 Gauss points (scikit-fem's default: 3 × 3)
    "tri2": (MeshTri, ElementTriP2, 2),  # 3 points: exact for P2 stiffness on straight sides
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


def response(material, basis, u, u_committed, measure="total"):
    """σ and D at the quadrature points for the displacement ``u``: the material takes the
    total ∇u (a DiscreteField) and answers quadrature-last (``r.stress`` (2, 2, nelems,
    nqp), ``r.tangent`` (2, 2, 2, 2, nelems, nqp))."""
    if measure == "total":
        return material.response(basis.interpolate(u))
    return material.response(basis.interpolate(u - u_committed), measure="increment")


def main(name: str = MATERIAL, element: str = ELEMENT, axial_strain: float = 0.01,
         steps: int = 5, refine: int = 1, rtol: float = 1e-2, max_iterations: int = 50,
         measure: str = "total") -> list[float]:
    """Run the test; returns the axial stress [Pa] (compression +) after every step.

    ``measure="increment"`` hands the material ∇(u − u_committed) instead of the total ∇u
    (the protocol's form): the same answer.
    """
    mesh_type, element_type, intorder = ELEMENTS[element]
    mesh = mesh_type().refined(refine)  # unit square
    basis = Basis(mesh, ElementVector(element_type()), intorder=intorder)
    material = create_material(name, **PARAMETERS[name])
    material.allocate(basis.nelems * basis.X.shape[-1])  # one state per quadrature point

    sides = mesh.facets_satisfying(lambda x: np.isclose(x[0], 0) | np.isclose(x[0], 1))
    f_ext = confinement.assemble(FacetBasis(mesh, basis.elem, facets=sides, intorder=4))
    bottom = basis.get_dofs(lambda x: np.isclose(x[1], 0)).all("u^2")  # P2: mid-sides too
    top = basis.get_dofs(lambda x: np.isclose(x[1], 1)).all("u^2")
    corner = basis.nodal_dofs[0, mesh.nodes_satisfying(lambda x: (x[0] == 0) & (x[1] == 0))]
    fixed = np.concatenate([bottom, top, corner])  # rollers, the platen, one pin

    u = basis.zeros()  # total displacement [m]
    history = []
    for step in range(1, steps + 1):
        u_committed = u.copy()
        u[top] = -axial_strain * step / steps  # prescribed total displacement of the top
        iterations = 0
        while iterations < max_iterations:
            iterations += 1
            r = response(material, basis, u, u_committed, measure)
            if not r.ok:  # e.g. {"max_dem_steps": 2}: the failed points keep their committed σ
                raise RuntimeError(f"{name}: step {step}: points failed {r.failure_counts()}")
            residual = internal_force.assemble(basis, sigma=r.stress) - f_ext
            K = stiffness.assemble(basis, D=r.tangent)
            du = solve(*condense(K, -residual, D=fixed))
            u += du
            if np.linalg.norm(du) <= rtol * np.linalg.norm(u - u_committed):
                break
        else:
            raise RuntimeError(f"{name}: step {step} did not converge")
        r = response(material, basis, u, u_committed, measure)  # the converged state ...
        if not r.ok:
            raise RuntimeError(f"{name}: step {step}: points failed {r.failure_counts()}")
        material.commit()  # ... becomes the committed one
        reaction = internal_force.assemble(basis, sigma=r.stress) - f_ext
        history.append(-reaction[top].sum())  # axial stress [Pa] on the 1 m wide top
        print(f"{name} {element}: step {step} axial strain {axial_strain * step / steps:.4f} "
              f"axial stress {history[-1] / 1e3:.1f} kPa ({iterations} iterations)")
    return history


if __name__ == "__main__":
    main(*sys.argv[1:3])
