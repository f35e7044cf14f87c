"""Chambon's local second gradient: a regularisation that gives softening a width.

Past a peak, a softening material localises into one row of elements and the answer depends
on the mesh. The local second gradient model (Chambon, Caillerie & Matsushima 2001;
Matsushima, Chambon & Caillerie 2002; Collin, Chambon & Charlier 2006) adds to the virtual
work of the classical medium that of a *microkinematic gradient* field v, a second-order
tensor tied to the displacement gradient by a Lagrange multiplier λ:

    ∫ σ : ∇u* dV  +  ∫ Σ ⋮ ∇v* dV  −  ∫ λ : (∇u* − v*) dV  =  W_ext(u*)
                                       ∫ λ* : (∇u − v) dV  =  0

In 2D v has four components, so the unknowns are u (quadratic: quad8, quad9, tri6), v
(linear, four scalar fields on the corner nodes) and λ (four constants per element). The
double stress Σ_ijk [N/m] comes from the simplest isotropic elastic second-gradient law,
one modulus D [N]:

    Σ_ijk = D ∂v_ij/∂X_k,    D = G₀ (ℓ / 10)²,

where ℓ is the internal length [m] a user chooses and G₀ [Pa] the shear modulus of the
material's tangent in its initial state (the median over the Gauss points of the average of
D_xyxy, D_yxyx, D_xyyx and D_yxxy: the shear modulus G of an isotropic elastic material).
ℓ is ten times the gradient-elasticity length √(D/G₀) of Mindlin's theory: in a
one-dimensional shear layer whose material softens with tangent modulus A < 0 the band the
model admits is w = 2π √(−D/A) = 0.63 ℓ √(−G₀/A) wide. On the Mohr–Coulomb softening
specimen of docs/validation/regularisation (G₀ = 23 MPa) the bands measured 7–8 ℓ wide, the
same on two meshes. How to choose ℓ: docs/guide/regularisation.md.

The second-gradient terms are linear and written on the reference configuration: their
blocks of Newton's tangent are constant, so the material's own tangent alone decides how
Newton converges. With the updated-Lagrangian formulation this takes ∇_X u, not ∇_x u, for
the microstructure: the two differ by the strain (a few per cent in the biaxial and footing
runs), in the regularising term only, not in the material's stress.

Boundary conditions: v and λ are free everywhere; the weak form then leaves the double
traction Σ·n at zero on every boundary (the natural condition of the model), and the
classical conditions on u are the run's own.

The material sees only ∇u and returns only σ and its tangent: a DEM material runs as it
does without the regularisation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import bmat, csr_matrix
from skfem import Basis, BilinearForm
from skfem.element import (
    ElementQuad0,
    ElementQuad1,
    ElementQuad2,
    ElementQuadS2,
    ElementTriP0,
    ElementTriP1,
    ElementTriP2,
)

from granular_material.errors import ParameterError

__all__ = [
    "LENGTH_RATIO",
    "REGULARISATIONS",
    "SECOND_GRADIENT_ELEMENTS",
    "Regularisation",
    "SecondGradient",
    "check_element",
    "check_element_name",
    "initial_shear_modulus",
    "second_gradient_modulus",
]

#: the regularisations a FEM run may use (``Regularisation.model``)
REGULARISATIONS = ("none", "second-gradient")
#: the displacement elements the second gradient runs on, by the run's element name
SECOND_GRADIENT_ELEMENTS = ("quad8", "quad9", "tri6")

#: the displacement element's scalar type → (the element of v, the element of λ)
_FIELDS = {ElementQuadS2: (ElementQuad1, ElementQuad0),
           ElementQuad2: (ElementQuad1, ElementQuad0),
           ElementTriP2: (ElementTriP1, ElementTriP0)}
#: ℓ over the gradient-elasticity length √(D/G₀): D = G₀ (ℓ / LENGTH_RATIO)²
LENGTH_RATIO = 10.0
#: the components (i, j) of v and λ, in the order of their blocks of unknowns
_COMPONENTS = ((0, 0), (0, 1), (1, 0), (1, 1))


@dataclass(frozen=True)
class Regularisation:
    """The regularisation of a FEM run.

    Attributes:
        model: "none" (the classical medium) or "second-gradient" (Chambon's local second
            gradient, :class:`SecondGradient`).
        internal_length: ℓ [m] of the second gradient, > 0 (unused with "none").
    """

    model: str = "none"
    internal_length: float = 0.0

    def __post_init__(self) -> None:
        if self.model not in REGULARISATIONS:
            raise ParameterError("regularisation", f"must be one of "
                                 f"{', '.join(REGULARISATIONS)}, got {self.model!r}")
        length = self.internal_length
        if self.model == "second-gradient":
            if not (isinstance(length, (int, float)) and math.isfinite(length) and length > 0):
                raise ParameterError("internal_length", "the second gradient needs an internal "
                                     f"length > 0 [m], got {length!r}")
        elif length not in (0, None):
            raise ParameterError("internal_length", "is the second gradient's: give it with "
                                 "regularisation 'second-gradient'")

    @property
    def active(self) -> bool:
        """True when the run is regularised."""
        return self.model != "none"


def initial_shear_modulus(tangent: np.ndarray) -> float:
    """G₀ [Pa]: the median over the points of the shear part of the tangent ``tangent``
    [Pa] (n, 2, 2, 2, 2), ¼ (D_xyxy + D_yxyx + D_xyyx + D_yxxy); ValueError where it is not
    a positive number."""
    d = np.asarray(tangent, dtype=np.float64)
    shear = 0.25 * (d[:, 0, 1, 0, 1] + d[:, 1, 0, 1, 0] + d[:, 0, 1, 1, 0] + d[:, 1, 0, 0, 1])
    modulus = float(np.median(shear)) if shear.size else math.nan
    if not (math.isfinite(modulus) and modulus > 0):
        raise ValueError(f"the material's initial tangent has no positive shear modulus "
                         f"(median {modulus!r} Pa): the second gradient's modulus D = G₀ (ℓ/10)² "
                         "cannot be set from it")
    return modulus


def second_gradient_modulus(shear_modulus: float, internal_length: float) -> float:
    """D = G₀ (ℓ / :data:`LENGTH_RATIO`)² [N] from G₀ [Pa] and ℓ [m]."""
    return shear_modulus * (internal_length / LENGTH_RATIO) ** 2


def _scalar_element(basis: Basis) -> type:
    elem = basis.elem
    return type(getattr(elem, "elem", elem))


@BilinearForm
def _laplace(u, v, _):
    return u.grad[0] * v.grad[0] + u.grad[1] * v.grad[1]


@BilinearForm
def _product(u, v, _):
    return u * v


def _gradient_component(i: int, j: int) -> BilinearForm:
    """The form ∫ λ* ∂u_i/∂X_j dV of a vector trial u and a scalar test λ*."""
    @BilinearForm
    def form(u, v, _):
        return u.grad[i][j] * v
    return form


def _refuse_element(name: str) -> None:
    raise ParameterError("regularisation", f"the second gradient needs quadratic "
                         f"displacement elements ({', '.join(SECOND_GRADIENT_ELEMENTS)}), "
                         f"not {name}")


def check_element_name(element: str) -> None:
    """ParameterError unless the run's element ``element`` (quad4, quad8, …) is one the
    second gradient runs on (:data:`SECOND_GRADIENT_ELEMENTS`)."""
    if element not in SECOND_GRADIENT_ELEMENTS:
        _refuse_element(element)


def check_element(basis: Basis, element: str | None = None) -> None:
    """ParameterError unless ``basis`` is one the second gradient runs on (quad8, quad9,
    tri6); ``element`` names the run's element in the message."""
    if _scalar_element(basis) not in _FIELDS:
        _refuse_element(element or _scalar_element(basis).__name__)


class SecondGradient:
    """The second-gradient terms of one displacement basis (see the module docstring).

    The unknowns beyond the displacement, ``extra``, are v's four components on the corner
    nodes (component by component, (i, j) = (0, 0), (0, 1), (1, 0), (1, 1)), then λ's four
    per element; :attr:`matrix` K acts on [u, extra] and is the whole of the terms: their
    residual is K [u, extra], their tangent K.
    """

    def __init__(self, basis: Basis, modulus: float, element: str | None = None) -> None:
        """``basis``: the displacement's (a 2D vector basis of quad8, quad9 or tri6);
        ``modulus``: D [N], > 0; ``element``: the run's element name, for the refusal."""
        check_element(basis, element)
        fields = _FIELDS[_scalar_element(basis)]
        if not (math.isfinite(modulus) and modulus > 0):
            raise ParameterError("internal_length", f"gives the modulus D = {modulus!r} N: "
                                 "it must be a number > 0")
        self.modulus = float(modulus)
        mesh, quadrature = basis.mesh, basis.quadrature
        v_basis = Basis(mesh, fields[0](), quadrature=quadrature)
        l_basis = Basis(mesh, fields[1](), quadrature=quadrature)
        self.n_u, self.n_v, self.n_lambda = int(basis.N), int(v_basis.N), int(l_basis.N)
        stiffness = (self.modulus * _laplace.assemble(v_basis)).tocsr()
        coupling = _product.assemble(v_basis, l_basis).tocsr()  # (λ, v): ∫ λ* v
        gradients = [_gradient_component(i, j).assemble(basis, l_basis).tocsr()
                     for i, j in _COMPONENTS]  # (λ, u): ∫ λ* ∂u_i/∂X_j
        k = 4
        blocks: list[list[csr_matrix | None]] = [[None] * (1 + 2 * k) for _ in range(1 + 2 * k)]
        blocks[0][0] = csr_matrix((self.n_u, self.n_u))
        for c in range(k):
            blocks[0][1 + k + c] = -gradients[c].T
            blocks[1 + c][1 + c] = stiffness
            blocks[1 + c][1 + k + c] = coupling.T
            blocks[1 + k + c][0] = -gradients[c]
            blocks[1 + k + c][1 + c] = coupling
        self.matrix = bmat(blocks, format="csr")

    @property
    def n_extra(self) -> int:
        """How many unknowns the terms add to the displacement's: 4 × (corner nodes +
        elements)."""
        return 4 * (self.n_v + self.n_lambda)

    def augment(self, stiffness: csr_matrix) -> csr_matrix:
        """The tangent of the whole problem: the displacement's ``stiffness`` (ndofs, ndofs)
        bordered by zeros, plus :attr:`matrix`."""
        n = self.n_extra
        return (bmat([[stiffness, None], [None, csr_matrix((n, n))]], format="csr")
                + self.matrix).tocsr()

    def residual(self, u: np.ndarray, extra: np.ndarray) -> np.ndarray:
        """The terms' residual K [u, extra]: the first ``ndofs`` entries are −∫ λ : ∇u* [N/m]
        (added to the internal force), the rest the rows of v and λ."""
        return self.matrix @ np.concatenate([u, extra])

    def microstructure(self, extra: np.ndarray) -> np.ndarray:
        """v [-] on the corner nodes, shape (4, corner nodes): v_xx, v_xy, v_yx, v_yy."""
        return np.asarray(extra[: 4 * self.n_v]).reshape(4, self.n_v)

    def multipliers(self, extra: np.ndarray) -> np.ndarray:
        """λ [Pa] per element, shape (4, elements): λ_xx, λ_xy, λ_yx, λ_yy."""
        return np.asarray(extra[4 * self.n_v:]).reshape(4, self.n_lambda)


def add_second_gradient(terms: SecondGradient, stiffness: csr_matrix, residual: np.ndarray,
                        u: np.ndarray, extra: np.ndarray) -> tuple[csr_matrix, np.ndarray]:
    """A scikit-fem problem's tangent and residual with the second gradient added.

    ``stiffness`` (ndofs, ndofs) and ``residual`` (ndofs,) [N/m] are the user's own, of the
    displacement ``u`` [m]; ``extra`` the second gradient's unknowns (``terms.n_extra``,
    zeros at the start). Returns the tangent and residual of [u, extra]: solve
    ``condense(K, -R, D=D)`` with the displacement's Dirichlet dofs ``D`` (v and λ are free)
    and add the correction's first ndofs entries to u, the rest to ``extra``.
    """
    bordered = np.concatenate([residual, np.zeros(terms.n_extra)])
    return terms.augment(stiffness), bordered + terms.residual(u, extra)
