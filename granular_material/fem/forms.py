"""scikit-fem forms of the small-strain equilibrium problem, fed with per-point arrays.

Tangent and stress arrive from a material in the batch-first layout and are converted with
:mod:`granular_material.fem.layout` before they reach the forms. Thickness is 1 m (2D plane
strain): forces are per unit thickness [N/m].
"""

from __future__ import annotations

import weakref

import numpy as np
from scipy.sparse import csr_matrix
from skfem import Basis, BilinearForm, LinearForm

from granular_material.fem.layout import to_points, to_quadrature

__all__ = ["StiffnessPattern", "gauss_points_grad", "internal_force", "stiffness",
           "stiffness_pattern", "stress_form", "tangent_form"]


@BilinearForm
def tangent_form(u, v, w):
    """∫ ∇v : D : ∇u dV, D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) given as ``w.D`` (2,2,2,2,nelems,nqp)."""
    return np.einsum("ijkl...,kl...,ij...->...", w.D, u.grad, v.grad)


@LinearForm
def stress_form(v, w):
    """∫ ∇v : σ dV (the internal force), σ given as ``w.sigma`` (2, 2, nelems, nqp)."""
    return np.einsum("ij...,ij...->...", w.sigma, v.grad)


def _nqp(basis: Basis) -> int:
    return int(basis.X.shape[-1])


class StiffnessPattern:
    """What the tangent stiffness of one basis keeps from one assembly to the next (issue 62):
    the gradients of its local basis functions at every Gauss point, weighted by the point's
    volume, and the sparsity pattern of the global matrix with the place of every element
    entry in it. Only the values then change: K = Σ_e Bᵀ D B dV, summed into the pattern.

    The same matrix as :data:`tangent_form`'s assembly to round-off (the element sums are
    taken in another order) and with the same pattern, but that entries that sum to exactly
    zero are kept (scikit-fem drops them).
    """

    def __init__(self, basis: Basis) -> None:
        grads = [np.asarray(fields[0].grad) for fields in basis.basis]
        n_bfun, n_elem, n_qp = len(grads), basis.nelems, _nqp(basis)
        if any(len(f) != 1 for f in basis.basis) or any(
                g.shape != (2, 2, n_elem, n_qp) for g in grads):
            raise ValueError("not a 2D vector basis")
        # B[e, q, a, 2i + j] = ∂φ_a,i/∂x_j, and B·dV
        self.b = np.stack(grads).reshape(n_bfun, 4, n_elem, n_qp).transpose(2, 3, 0, 1).copy()
        self.b_dv = self.b * np.asarray(basis.dx)[:, :, None, None]
        self.b_t = np.ascontiguousarray(self.b.transpose(0, 1, 3, 2))
        dofs = np.asarray(basis.element_dofs)  # (n_bfun, n_elem)
        n = int(basis.N)
        rows = np.broadcast_to(dofs.T[:, :, None], (n_elem, n_bfun, n_bfun))
        cols = np.broadcast_to(dofs.T[:, None, :], (n_elem, n_bfun, n_bfun))
        keys = rows.astype(np.int64).ravel() * n + cols.ravel()
        unique, self.place = np.unique(keys, return_inverse=True)
        self.indices = (unique % n).astype(np.int32)
        self.indptr = np.searchsorted(unique // n, np.arange(n + 1)).astype(np.int32)
        self.shape = (n, n)
        self.n_qp = n_qp

    def matrix(self, tangent: np.ndarray) -> csr_matrix:
        """K [N/m per m of thickness] from D [Pa] (n, 2, 2, 2, 2), n = elements × points."""
        n_elem = self.b.shape[0]
        d = np.asarray(tangent, dtype=np.float64).reshape(n_elem, self.n_qp, 4, 4)
        k_e = np.matmul(self.b_dv, np.matmul(d, self.b_t)).sum(axis=1)  # (e, a, b)
        values = np.bincount(self.place, weights=k_e.ravel(), minlength=len(self.indices))
        return csr_matrix((values, self.indices.copy(), self.indptr.copy()), shape=self.shape)


#: the stiffness pattern of each basis assembled so far (forgotten with the basis)
_PATTERNS: weakref.WeakKeyDictionary[Basis, StiffnessPattern | None] = (
    weakref.WeakKeyDictionary())


def stiffness_pattern(basis: Basis) -> StiffnessPattern | None:
    """The :class:`StiffnessPattern` of ``basis``, made at its first assembly; None for a
    basis it does not serve (not a 2D vector basis): scikit-fem's form assembles that."""
    if basis not in _PATTERNS:
        try:
            _PATTERNS[basis] = StiffnessPattern(basis)
        except ValueError:
            _PATTERNS[basis] = None
    return _PATTERNS[basis]


def stiffness(basis: Basis, tangent: np.ndarray, kept: bool = True) -> csr_matrix:
    """Global tangent stiffness K [N/m per m of thickness] from D [Pa] (n, 2, 2, 2, 2); the
    basis's sparsity pattern and weighted gradients are kept between calls
    (:class:`StiffnessPattern`), or with ``kept`` False scikit-fem's form assembles it, bit
    for bit as before issue 62 (what a noisy material's runs use)."""
    pattern = stiffness_pattern(basis) if kept else None
    if pattern is None:
        return tangent_form.assemble(basis, D=to_quadrature(tangent, _nqp(basis)))
    return pattern.matrix(tangent)


def internal_force(basis: Basis, stress: np.ndarray) -> np.ndarray:
    """f_int = ∫ Bᵀσ dV [N per m of thickness], shape (ndofs,), from σ [Pa] (n, 2, 2)."""
    return stress_form.assemble(basis, sigma=to_quadrature(stress, _nqp(basis)))


def gauss_points_grad(basis: Basis, u: np.ndarray) -> np.ndarray:
    """∇u [-] of the nodal field ``u`` (ndofs,) at every Gauss point, shape (n, 2, 2)."""
    return to_points(basis.interpolate(u).grad)
