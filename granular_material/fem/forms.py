"""scikit-fem forms of the small-strain equilibrium problem, fed with per-point arrays.

Tangent and stress arrive from a material in the batch-first layout and are converted with
:mod:`granular_material.fem.layout` before they reach the forms. Thickness is 1 m (2D plane
strain): forces are per unit thickness [N/m].
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from skfem import Basis, BilinearForm, LinearForm

from granular_material.fem.layout import to_points, to_quadrature

__all__ = ["gauss_points_grad", "internal_force", "stiffness", "stress_form", "tangent_form"]


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


def stiffness(basis: Basis, tangent: np.ndarray) -> csr_matrix:
    """Global tangent stiffness K [N/m per m of thickness] from D [Pa] (n, 2, 2, 2, 2)."""
    return tangent_form.assemble(basis, D=to_quadrature(tangent, _nqp(basis)))


def internal_force(basis: Basis, stress: np.ndarray) -> np.ndarray:
    """f_int = ∫ Bᵀσ dV [N per m of thickness], shape (ndofs,), from σ [Pa] (n, 2, 2)."""
    return stress_form.assemble(basis, sigma=to_quadrature(stress, _nqp(basis)))


def gauss_points_grad(basis: Basis, u: np.ndarray) -> np.ndarray:
    """∇u [-] of the nodal field ``u`` (ndofs,) at every Gauss point, shape (n, 2, 2)."""
    return to_points(basis.interpolate(u).grad)
