"""Boundary-value problems: the drained biaxial specimen and its one-element version.

Plane strain, small strain, thickness 1 m (forces in N/m). The specimen occupies
[0, width] × [0, height]; the top nodes move down by ``axial_strain · height``, the bottom
nodes stay at u_y = 0, the sides carry the confining traction t = −p·n (tension positive,
n the outward normal). Smooth platens (default): the platen nodes slide freely, but for one
bottom node pinned (u_x = 0, the one nearest x = width/2). Rough platens: no platen node
moves sideways (u_x = 0 on top and bottom).

Elements (:data:`ELEMENTS`): ``quad4`` (bilinear, 4 nodes, default), ``quad8`` (serendipity,
4 corner + 4 midside nodes: scikit-fem's ``ElementQuadS2``) and ``quad9`` (biquadratic
Lagrange, 8 + 1 centre node: ``ElementQuad2``), on the same rectangular grid of straight-
sided elements. "Nodes" above means every node an element has, midside and centre nodes
included: the platen conditions hold the midside nodes of the platens too, and the
confining traction is integrated over the side facets with the element's own shape
functions (consistent nodal forces: p·L·(1/6, 2/3, 1/6) on a quadratic edge of length L).

Quadrature (``gauss``: Gauss–Legendre points per direction, ``gauss × gauss`` per element):
the default is 2 × 2 for quad4 (full) and quad8 (*reduced*: the serendipity element's full
rule is 3 × 3; 2 × 2 is what Guo & Zhao's FEM×DEM biaxial uses, one RVE per point, at the
price of one spurious zero-energy (hourglass) mode per element, see docs/physics.md) and 3 × 3
for quad9 (full). Elements are numbered up the columns (element ``e = ix · ny + iy``, ix
along x, iy along y); Gauss point ``p = e · gauss² + q``, ``q = i · gauss + j`` with i the
point's index along y and j along x, each from the lower coordinate up (the mesh's elements
run their corners clockwise from the lower left, so the reference ξ lies along y).

Triangles: ``tri3`` (linear, 3 nodes, 1 point at the centroid: exact) and ``tri6``
(quadratic, 3 corner + 3 midside nodes, 3 points: exact for a constant tangent), each
rectangle of the grid cut into two (scikit-fem's ``MeshTri.init_tensor``). For them
``gauss`` is the number of points per triangle, one of 1, 3, 6, 7, 12 (scikit-fem's rules of
degree 1, 2, 4, 5, 6), numbered as scikit-fem's rule numbers them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from skfem import (
    Basis,
    ElementQuad1,
    ElementQuad2,
    ElementQuadS2,
    ElementTriP1,
    ElementTriP2,
    ElementVector,
    FacetBasis,
    LinearForm,
    MeshQuad,
    MeshTri,
)

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.loading import Loading
from granular_material.fem.layout import to_points
from granular_material.reference_values import DEFAULT_PRESSURE

__all__ = ["DEFAULT_GAUSS", "ELEMENTS", "PLATENS", "TRIANGLES", "TRIANGLE_RULES", "BiaxialProblem",
           "BiaxialSetup", "build_biaxial", "element_of"]

#: the elements a problem may be meshed with: name → scikit-fem element (scalar)
ELEMENTS = {"quad4": ElementQuad1, "quad8": ElementQuadS2, "quad9": ElementQuad2,
            "tri3": ElementTriP1, "tri6": ElementTriP2}
#: the triangles among them
TRIANGLES = frozenset({"tri3", "tri6"})
#: Gauss points of each element by default, per direction (quadrilaterals) or per triangle:
#: full integration for quad4, quad9, tri3 and tri6, reduced (2 × 2, Guo & Zhao) for quad8
#: the platens of a specimen: smooth (its nodes slide, one bottom node pinned) or rough
PLATENS = ("smooth", "rough")
DEFAULT_GAUSS = {"quad4": 2, "quad8": 2, "quad9": 3, "tri3": 1, "tri6": 3}
#: the triangle rules: points per triangle → scikit-fem intorder (1: the centroid, by hand)
TRIANGLE_RULES = {1: 1, 3: 2, 6: 4, 7: 5, 12: 6}


def element_of(name: str) -> ElementVector:
    """The vector (u_x, u_y) scikit-fem element of the element named ``name``."""
    if name not in ELEMENTS:
        raise ParameterError("element", f"must be one of {', '.join(ELEMENTS)}, got {name!r}")
    return ElementVector(ELEMENTS[name]())


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
        element: "quad4", "quad8", "quad9", "tri3" or "tri6" (:data:`ELEMENTS`).
        gauss: Gauss points per direction of every quadrilateral, 1 to 10, or per triangle
            (1, 3, 6, 7, 12), or None for the element's default (:data:`DEFAULT_GAUSS`).
    """

    width: float = 0.05
    height: float = 0.10
    nx: int = 10
    ny: int = 15
    confining: float = DEFAULT_PRESSURE
    axial_strain: float = 0.10
    platens: str = "smooth"
    element: str = "quad4"
    gauss: int | None = None

    def __post_init__(self) -> None:
        if self.element not in ELEMENTS:
            raise ParameterError("element", f"must be one of {', '.join(ELEMENTS)}, "
                                            f"got {self.element!r}")
        if self.element in TRIANGLES:
            if self.gauss is not None and self.gauss not in TRIANGLE_RULES:
                raise ParameterError("gauss", "of a triangle must be one of "
                                              f"{', '.join(map(str, TRIANGLE_RULES))} (points "
                                              f"per triangle), got {self.gauss!r}")
        elif self.gauss is not None and (int(self.gauss) != self.gauss
                                         or not 1 <= self.gauss <= 10):
            raise ParameterError("gauss", "must be an integer in [1, 10] (points per "
                                          f"direction), got {self.gauss!r}")
        if self.platens not in PLATENS:
            raise ParameterError("platens", f"must be 'smooth' or 'rough', got {self.platens!r}")
        for name in ("width", "height"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ParameterError(name, f"must be a positive length in m, got {value!r}")
        for name in ("nx", "ny"):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise ParameterError(name, f"must be an integer >= 1, got {value!r}")
        if not (math.isfinite(self.confining) and self.confining >= 0):
            raise ParameterError("confining",
                                 f"must be a pressure >= 0 Pa, got {self.confining!r}")
        if not (math.isfinite(self.axial_strain) and 0 < self.axial_strain <= 0.5):
            raise ParameterError("axial_strain",
                                 f"must lie in (0, 0.5], got {self.axial_strain!r}")

    @property
    def gauss_per_direction(self) -> int:
        """Gauss points per direction of each quadrilateral, or per triangle (``gauss`` or
        the element's default)."""
        return DEFAULT_GAUSS[self.element] if self.gauss is None else int(self.gauss)

    @property
    def points_per_element(self) -> int:
        """Gauss points of one element (gauss × gauss, or gauss for a triangle)."""
        n = self.gauss_per_direction
        return n if self.element in TRIANGLES else n ** 2

    @property
    def n_elements(self) -> int:
        """Elements of the mesh (nx · ny, twice as many triangles)."""
        return self.nx * self.ny * (2 if self.element in TRIANGLES else 1)

    @property
    def intorder(self) -> int:
        """scikit-fem's ``intorder`` of the rule: the polynomial degree 2·gauss − 1 that
        gauss × gauss Gauss–Legendre points integrate exactly (scikit-fem takes 2 × 2 points
        for any intorder <= 3: one point per direction is built by hand); for a triangle
        the degree of its rule (:data:`TRIANGLE_RULES`)."""
        if self.element in TRIANGLES:
            return TRIANGLE_RULES[self.gauss_per_direction]
        return 2 * self.gauss_per_direction - 1

    @property
    def n_points(self) -> int:
        """Gauss points of the mesh (gauss × gauss per quadrilateral, gauss per triangle)."""
        return self.points_per_element * self.n_elements


@dataclass(frozen=True)
class BiaxialProblem:
    """The assembled pieces of a biaxial problem.

    Attributes:
        setup: the geometry and loading it was built from.
        basis: vector basis of the element, with the setup's Gauss quadrature.
        loading: prescribed displacements and forces against the load factor.
        top_dofs: u_y degrees of freedom of the top platen (every node on it, midside
            nodes included), ascending.
        weights: integration weight (area [m²]) of every Gauss point, shape (n,).
    """

    setup: BiaxialSetup
    basis: Basis
    loading: Loading
    top_dofs: np.ndarray
    weights: np.ndarray

    def force_tolerance(self, stress: float) -> float:
        """‖R‖₂ [N/m] that a stress error of ``stress`` [Pa] at every Gauss point leaves.

        Nodal forces from a stress error τ scale as τ·h (h = √(area / elements), every
        triangle counted, unit
        thickness); uncorrelated errors add in quadrature over the free degrees of freedom:
        ‖R‖ ≈ τ · h · √n_free. Used as the absolute Newton tolerance for noisy (DEM) stress.
        """
        s = self.setup
        h = math.sqrt(s.width * s.height / s.n_elements)
        n_free = self.basis.N - self.loading.dirichlet_dofs.size
        return float(stress * h * math.sqrt(n_free))

    def nodes(self) -> tuple[np.ndarray, np.ndarray, str, np.ndarray]:
        """Every node of the mesh, midside and centre nodes included, for output.

        Returns (coordinates [m] (k, 2), connectivity (nelems, 3 | 4 | 6 | 8 | 9) in the
        VTK/meshio order: corners, then the midsides of edges 01, 12, 23 (20 for a triangle),
        30, then the centre; the meshio cell type "quad" | "quad8" | "quad9" | "triangle" |
        "triangle6"; the (u_x, u_y) degrees of freedom of every node, shape (2, k)).
        """
        basis = self.basis
        triangle = self.setup.element in TRIANGLES
        if basis.facet_dofs.size == 0 and basis.interior_dofs.size == 0:
            return (basis.mesh.p.T, basis.mesh.t.T, "triangle" if triangle else "quad",
                    basis.nodal_dofs)
        scalar = Basis(basis.mesh, ELEMENTS[self.setup.element](), quadrature=basis.quadrature)
        k = np.arange(scalar.N)
        kind = {6: "triangle6", 8: "quad8", 9: "quad9"}[scalar.element_dofs.shape[0]]
        return scalar.doflocs.T, scalar.element_dofs.T, kind, np.vstack([2 * k, 2 * k + 1])

    def axial_stress(self, reaction: np.ndarray, u: np.ndarray | None = None) -> float:
        """Axial stress from the platen reaction [Pa], compression positive (σ = −ΣR_y / W),
        W the platen's reference width, or with the displacement ``u`` [m] (ndofs,) its
        current width (the spread of the top nodes' current x)."""
        width = self.setup.width
        if u is not None:  # u_x of a node is the dof before its u_y (scikit-fem's order)
            x = self.basis.doflocs[0, self.top_dofs - 1] + u[self.top_dofs - 1]
            width = float(x.max() - x.min())
        return float(-reaction[self.top_dofs].sum() / width)


def _component_dofs(basis: Basis, component: int) -> tuple[np.ndarray, np.ndarray]:
    """The degrees of freedom of displacement ``component`` (0: u_x, 1: u_y) at every node
    of the basis (corner, midside, centre), ascending, and their locations (2, k)."""
    parts = [basis.nodal_dofs, basis.facet_dofs, basis.interior_dofs]
    dofs = np.sort(np.concatenate([d[component] for d in parts if d.size]))
    return dofs, basis.doflocs[:, dofs]


def build_biaxial(setup: BiaxialSetup) -> BiaxialProblem:
    """Mesh, basis, boundary conditions and loads of a drained biaxial test."""
    xs = np.linspace(0.0, setup.width, setup.nx + 1)
    ys = np.linspace(0.0, setup.height, setup.ny + 1)
    triangle = setup.element in TRIANGLES
    mesh = (MeshTri if triangle else MeshQuad).init_tensor(xs, ys)
    if setup.gauss_per_direction == 1:  # scikit-fem's least rules have 2 × 2 or 3 points
        centre, weight = (1 / 3, 0.5) if triangle else (0.5, 1.0)
        basis = Basis(mesh, element_of(setup.element),
                      quadrature=(np.full((2, 1), centre), np.full(1, weight)))
    else:
        basis = Basis(mesh, element_of(setup.element), intorder=setup.intorder)
    if basis.X.shape[-1] != setup.points_per_element:
        raise RuntimeError(f"intorder {setup.intorder} gave {basis.X.shape[-1]} points per "
                           f"element, not {setup.points_per_element}")
    tol = 1e-9 * max(setup.width, setup.height)
    ux, (x, _) = _component_dofs(basis, 0)
    uy, (_, y) = _component_dofs(basis, 1)
    bottom = np.abs(y) < tol
    top = np.abs(y - setup.height) < tol
    if setup.platens == "rough":
        held = np.concatenate([ux[bottom], ux[top]])
    else:
        x_bottom = x[bottom]
        held = ux[bottom][[np.argmin(np.abs(x_bottom - setup.width / 2))]]
    dofs = np.concatenate([uy[bottom], held, uy[top]])
    end = np.concatenate([np.zeros(int(bottom.sum()) + held.size),
                          np.full(int(top.sum()), -setup.axial_strain * setup.height)])
    sides = mesh.facets_satisfying(
        lambda p: (np.abs(p[0]) < tol) | (np.abs(p[0] - setup.width) < tol)
    )
    # the traction is constant on a side: 2 Gauss points per facet integrate it exactly
    # against linear and quadratic shape functions (consistent nodal forces)
    facet_basis = FacetBasis(mesh, basis.elem, facets=sides, intorder=2)
    traction = confining_traction.assemble(facet_basis, p=setup.confining)

    def on_current_sides(u: np.ndarray) -> np.ndarray:
        return follower_traction.assemble(facet_basis, p=setup.confining,
                                          u=facet_basis.interpolate(u))

    loading = Loading(
        dirichlet_dofs=dofs.astype(np.int64), dirichlet_end=end,
        force_start=traction, force_end=traction.copy(), follower=on_current_sides,
    )
    weights = to_points(basis.dx)
    return BiaxialProblem(setup, basis, loading, uy[top].astype(np.int64), weights)


@LinearForm
def follower_traction(v, w):
    """∫ −p n · v ds over the *current* facets, taken on the reference ones by Nanson's
    n ds = cof(F) N dS (F = I + ∇u of ``w.u``, N the reference normal; ``w.p`` in Pa)."""
    g = w.u.grad
    n0 = (1.0 + g[1, 1]) * w.n[0] - g[1, 0] * w.n[1]
    n1 = -g[0, 1] * w.n[0] + (1.0 + g[0, 0]) * w.n[1]
    return -w.p * (n0 * v[0] + n1 * v[1])


@LinearForm
def confining_traction(v, w):
    """∫ t · v ds with t = −p n [Pa] on the facets of the basis (``w.p`` in Pa)."""
    return -w.p * (w.n[0] * v[0] + w.n[1] * v[1])
