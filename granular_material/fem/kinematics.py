"""Kinematics of the FEM problems: small strain, or finite strain in the updated-Lagrangian
form of Guo & Zhao's FEM×DEM code.

Every problem is assembled on the reference mesh (scikit-fem's basis, coordinates X); a
formulation says what the material is driven with and what the forms integrate there.

``small-strain``
    The material gets ∇_X Δu, the displacement gradient of the load step on the reference
    mesh; the forms integrate σ and the material's tangent D on the reference mesh.

``updated-lagrangian`` (Guo & Zhao 2014; YADE's ``FEMxDEM/msFEM2D.py``)
    Equilibrium holds on the current configuration x = X + u: ∫ σ : ∇ₓv dv = f_ext, with the
    confining pressure acting on the current sides. The material is driven from its
    committed state by ∇Δu measured on the committed configuration x_n = X + u_n,
    ``G = ∇_X Δu · F_n⁻¹`` (rotation included; F_n = I + ∇_X u_n), so the RVE's deformation
    gradients F_{n+1}·F_n⁻¹ of the steps multiply to F exactly. The same integral is taken on
    the reference mesh as ∫ P : ∇_X v dV with the first Piola–Kirchhoff stress
    ``P = J σ F⁻ᵀ``, and its exact linearisation for a material tangent
    D_ijkm = ∂σ_ij/∂G_km is

        A_iJkM = J [D_ijkm F_n⁻¹_Mm F⁻¹_Jj + σ_ij F⁻¹_Jj F⁻¹_Mk − σ_ij F⁻¹_Jk F⁻¹_Mj]

    (the last two terms are the geometric, initial-stress stiffness; Guo & Zhao leave them
    out: ``geometric=False``). Arrays are batch-first, (n, 2, 2) and (n, 2, 2, 2, 2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "FORMULATIONS",
    "Kinematics",
    "first_piola",
    "logarithmic_strain",
    "reference_tangent",
]

#: the formulations a problem may be solved in (``NewtonSettings.formulation``)
FORMULATIONS = ("updated-lagrangian", "small-strain")

_EYE = np.eye(2)


def first_piola(sigma: np.ndarray, f: np.ndarray) -> np.ndarray:
    """P = J σ F⁻ᵀ [Pa] from the Cauchy stress σ [Pa] and F [-], shapes (n, 2, 2)."""
    f_inv = np.linalg.inv(f)
    j = np.linalg.det(f)
    return j[:, None, None] * np.einsum("nij,nJj->niJ", sigma, f_inv)


def reference_tangent(tangent: np.ndarray, sigma: np.ndarray, f: np.ndarray,
                      f_committed: np.ndarray, geometric: bool = True,
                      batched: bool = True) -> np.ndarray:
    """∂P_iJ/∂(∂u_k/∂X_M) [Pa], shape (n, 2, 2, 2, 2), of a material whose tangent
    ``tangent`` [Pa] is ∂σ_ij/∂G_km with G = ∇_X Δu · F_n⁻¹ (``f_committed`` = F_n) at the
    stress ``sigma`` [Pa] and deformation gradient ``f``; ``geometric`` adds the
    initial-stress terms (see the module docstring). ``batched`` False: the three-operand
    einsums of before issue 62, bit for bit (what a noisy material's runs use)."""
    f_inv = np.linalg.inv(f)
    fn_inv = np.linalg.inv(f_committed)
    j = np.linalg.det(f)[:, None, None, None, None]
    if not batched:
        out = np.einsum("nijkm,nMm,nJj->niJkM", tangent, fn_inv, f_inv)
        if geometric:
            out += np.einsum("nij,nJj,nMk->niJkM", sigma, f_inv, f_inv)
            out -= np.einsum("nij,nJk,nMj->niJkM", sigma, f_inv, f_inv)
        return j * out
    n = tangent.shape[0]
    # D_ijkm F_n⁻¹_Mm, then F⁻¹_Jj of it: two small batched products (the same sums as one
    # three-operand einsum, to round-off, several times faster: issue 62)
    out = np.matmul(tangent.reshape(n, 8, 2), np.swapaxes(fn_inv, 1, 2))  # (n, ijk, M)
    out = np.matmul(f_inv[:, None], out.reshape(n, 2, 2, 4)).reshape(n, 2, 2, 2, 2)
    if geometric:
        a = np.matmul(sigma, np.swapaxes(f_inv, 1, 2))  # σ_ij F⁻¹_Jj, (n, i, J)
        out += a[:, :, :, None, None] * np.swapaxes(f_inv, 1, 2)[:, None, None, :, :]
        out -= (a[:, :, None, None, :] * f_inv[:, None, :, :, None])
    return j * out


def logarithmic_strain(grad_u: np.ndarray) -> np.ndarray:
    """Hencky strain ε = ½ ln(F Fᵀ) [-] (Eulerian, tr ε = ln J) of ∇_X u, shape (n, 2, 2).

    In closed form for 2 × 2 (issue 62; a batched eigendecomposition took ten times as long):
    with b = F Fᵀ = m I + s, s its deviator, r = √(−det s) and λ = m ± r its eigenvalues,
    ln b = ln(det b)/2 · I + (ln λ₊ − ln λ₋)/(2r) · s. b − I is formed as H + Hᵀ + H Hᵀ
    (H = ∇_X u) and ln(det b)/2 (ln J, of J's magnitude where an element is inverted) by
    log1p, so that a small strain is not lost to the cancellation against I.
    """
    h = np.asarray(grad_u, dtype=np.float64)
    h00, h01, h10, h11 = h[:, 0, 0], h[:, 0, 1], h[:, 1, 0], h[:, 1, 1]
    b00 = 2.0 * h00 + h00 * h00 + h01 * h01  # b − I, entry by entry
    b11 = 2.0 * h11 + h10 * h10 + h11 * h11
    b01 = h01 + h10 + h00 * h10 + h01 * h11
    j_less_1 = h00 + h11 + (h00 * h11 - h01 * h10)  # J − 1, J = det F
    # ln |J| (ln det b / 2: b is positive definite even where an element is inverted)
    log_j = np.log(np.abs(1.0 + j_less_1), where=j_less_1 <= -0.5,
                   out=np.log1p(np.maximum(j_less_1, -0.5)))
    half = 0.5 * (b00 - b11)  # the deviator s = [[half, b01], [b01, −half]]
    m = 1.0 + 0.5 * (b00 + b11)
    r = np.hypot(half, b01)
    x = r / m  # in [0, 1): the eigenvalues m ± r are positive
    # β = (ln λ₊ − ln λ₋)/(4r): atanh(x)/(2r), → 1/(2m) as r → 0; where λ₋ ≪ λ₊ (x ≥ ½),
    # from λ₋ = J²/λ₊, which m − r would lose to cancellation
    near = x < 0.5
    beta = np.where(near, 0.5 / m, 0.5 * (np.log(m + r) - log_j) / np.where(near, 1.0, r))
    np.divide(0.5 * np.arctanh(np.minimum(x, 0.5)), r, out=beta, where=near & (x > 0))
    out = np.empty(h.shape, dtype=np.float64)
    out[:, 0, 0] = 0.5 * log_j + beta * half
    out[:, 1, 1] = 0.5 * log_j - beta * half
    out[:, 0, 1] = out[:, 1, 0] = beta * b01
    return out


@dataclass(frozen=True)
class Kinematics:
    """One formulation's maps between the reference mesh and the material.

    Attributes:
        formulation: one of :data:`FORMULATIONS`.
        geometric: updated-Lagrangian: include the initial-stress stiffness in the tangent
            the forms assemble (exact linearisation); Guo & Zhao's code leaves it out.
        batched: the tangent ∂P/∂∇u by batched products (issue 62); False: by the einsums
            of before, bit for bit (:func:`reference_tangent`).
    """

    formulation: str = "updated-lagrangian"
    geometric: bool = True
    batched: bool = True

    def __post_init__(self) -> None:
        if self.formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {', '.join(FORMULATIONS)}, "
                             f"got {self.formulation!r}")

    @property
    def finite(self) -> bool:
        """True for the finite-strain (updated-Lagrangian) formulation."""
        return self.formulation == "updated-lagrangian"

    def material_gradient(self, grad_committed: np.ndarray, grad_step: np.ndarray,
                          ) -> np.ndarray:
        """What drives the material: ∇Δu [-] of the step measured on the committed
        configuration (finite strain) or on the reference mesh (small strain), from
        ∇_X u_n (``grad_committed``) and ∇_X Δu (``grad_step``), shapes (n, 2, 2)."""
        if not self.finite:
            return grad_step
        return grad_step @ np.linalg.inv(_EYE + grad_committed)

    def assembled_stress(self, sigma: np.ndarray, grad_total: np.ndarray) -> np.ndarray:
        """The stress the forms integrate on the reference mesh [Pa]: σ, or P = J σ F⁻ᵀ with
        F = I + ∇_X u (``grad_total``)."""
        if not self.finite:
            return sigma
        return first_piola(sigma, _EYE + grad_total)

    def assembled_tangent(self, tangent: np.ndarray, sigma: np.ndarray,
                          grad_committed: np.ndarray, grad_total: np.ndarray) -> np.ndarray:
        """The tangent the forms integrate on the reference mesh [Pa]: D, or
        ∂P/∂(∇_X u) (:func:`reference_tangent`)."""
        if not self.finite:
            return tangent
        return reference_tangent(tangent, sigma, _EYE + grad_total, _EYE + grad_committed,
                                 self.geometric, self.batched)

    def strain(self, grad_total: np.ndarray) -> np.ndarray:
        """The strain reported [-]: sym ∇_X u (small strain) or the Hencky strain."""
        if not self.finite:
            return 0.5 * (grad_total + np.swapaxes(grad_total, 1, 2))
        return logarithmic_strain(grad_total)

    def current_volume(self, grad_total: np.ndarray) -> np.ndarray:
        """Current volume per unit reference volume, J = det F [-] (1 in small strain),
        shape (n,)."""
        if not self.finite:
            return np.ones(grad_total.shape[0])
        return np.linalg.det(_EYE + grad_total)
