"""Boundary-value problems: the drained biaxial specimen and its one-element version.

Plane strain, small strain, thickness 1 m (forces in N/m). The specimen occupies
[0, width] × [0, height]; the top nodes move down by ``axial_strain · height``, the bottom
nodes stay at u_y = 0, the sides carry the confining traction t = −p·n (tension positive,
n the outward normal). Smooth platens (default): the platen nodes slide freely, but for one
bottom node pinned (u_x = 0, the one nearest x = width/2). Rough platens: no platen node
moves sideways (u_x = 0 on top and bottom).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from skfem import Basis, ElementQuad1, ElementVector, FacetBasis, LinearForm, MeshQuad

from granular_material.fem.layout import to_points
from granular_material.fem.loading import Loading

__all__ = ["BiaxialProblem", "BiaxialSetup", "build_biaxial"]


@dataclass(frozen=True)
class BiaxialSetup:
    """Geometry and loading of a drained biaxial test.

    Attributes:
        width: specimen width [m] (x), > 0.
        height: specimen height [m] (y), > 0.
        nx: elements across the width, >= 1.
        ny: elements along the height, >= 1.
        confining: lateral confining pressure p [Pa], compression positive, >= 0.
        axial_strain: final axial strain, compression positive, in (0, 0.5].
        platens: "smooth" (platen nodes slide freely, one bottom node pinned) or "rough"
            (u_x = 0 on every platen node).
    """

    width: float = 0.05
    height: float = 0.10
    nx: int = 10
    ny: int = 15
    confining: float = 100.0e3
    axial_strain: float = 0.10
    platens: str = "smooth"

    def __post_init__(self) -> None:
        if self.platens not in ("smooth", "rough"):
            raise ValueError(f"platens must be 'smooth' or 'rough', got {self.platens!r}")
        for name in ("width", "height"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive length in m, got {value!r}")
        for name in ("nx", "ny"):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        if not (math.isfinite(self.confining) and self.confining >= 0):
            raise ValueError(f"confining must be a pressure >= 0 Pa, got {self.confining!r}")
        if not (math.isfinite(self.axial_strain) and 0 < self.axial_strain <= 0.5):
            raise ValueError(f"axial_strain must lie in (0, 0.5], got {self.axial_strain!r}")

    @property
    def n_points(self) -> int:
        """Gauss points of the mesh (2×2 per element)."""
        return 4 * self.nx * self.ny


@dataclass(frozen=True)
class BiaxialProblem:
    """The assembled pieces of a biaxial problem.

    Attributes:
        setup: the geometry and loading it was built from.
        basis: vector Q1 basis with 2×2 Gauss quadrature (``intorder=2``).
        loading: prescribed displacements and forces against the load factor.
        top_dofs: u_y degrees of freedom of the top platen, shape (nx + 1,).
        weights: integration weight (area [m²]) of every Gauss point, shape (n,).
    """

    setup: BiaxialSetup
    basis: Basis
    loading: Loading
    top_dofs: np.ndarray
    weights: np.ndarray

    def force_tolerance(self, stress: float) -> float:
        """‖R‖₂ [N/m] that a stress error of ``stress`` [Pa] at every Gauss point leaves.

        Nodal forces from a stress error τ scale as τ·h (h = √(area / elements), unit
        thickness); uncorrelated errors add in quadrature over the free degrees of freedom:
        ‖R‖ ≈ τ · h · √n_free. Used as the absolute Newton tolerance for noisy (DEM) stress.
        """
        s = self.setup
        h = math.sqrt(s.width * s.height / (s.nx * s.ny))
        n_free = self.basis.N - self.loading.dirichlet_dofs.size
        return float(stress * h * math.sqrt(n_free))

    def axial_stress(self, reaction: np.ndarray) -> float:
        """Axial stress from the platen reaction [Pa], compression positive (σ = −ΣR_y / W)."""
        return float(-reaction[self.top_dofs].sum() / self.setup.width)


def build_biaxial(setup: BiaxialSetup) -> BiaxialProblem:
    """Mesh, basis, boundary conditions and loads of a drained biaxial test."""
    xs = np.linspace(0.0, setup.width, setup.nx + 1)
    ys = np.linspace(0.0, setup.height, setup.ny + 1)
    mesh = MeshQuad.init_tensor(xs, ys)
    basis = Basis(mesh, ElementVector(ElementQuad1()), intorder=2)
    x, y = mesh.p
    tol = 1e-9 * max(setup.width, setup.height)
    bottom = np.flatnonzero(np.abs(y) < tol)
    top = np.flatnonzero(np.abs(y - setup.height) < tol)
    ux, uy = basis.nodal_dofs
    if setup.platens == "rough":
        held = np.concatenate([ux[bottom], ux[top]])
    else:
        held = ux[[bottom[np.argmin(np.abs(x[bottom] - setup.width / 2))]]]
    dofs = np.concatenate([uy[bottom], held, uy[top]])
    end = np.concatenate([np.zeros(bottom.size + held.size),
                          np.full(top.size, -setup.axial_strain * setup.height)])
    sides = mesh.facets_satisfying(
        lambda p: (np.abs(p[0]) < tol) | (np.abs(p[0] - setup.width) < tol)
    )
    facet_basis = FacetBasis(mesh, basis.elem, facets=sides, intorder=2)
    traction = confining_traction.assemble(facet_basis, p=setup.confining)
    loading = Loading(
        dirichlet_dofs=dofs.astype(np.int64), dirichlet_end=end,
        force_start=traction, force_end=traction.copy(),
    )
    weights = to_points(basis.dx)
    return BiaxialProblem(setup, basis, loading, uy[top].astype(np.int64), weights)


@LinearForm
def confining_traction(v, w):
    """∫ t · v ds with t = −p n [Pa] on the facets of the basis (``w.p`` in Pa)."""
    return -w.p * (w.n[0] * v[0] + w.n[1] * v[1])
