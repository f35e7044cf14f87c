"""Homogenised measures of RVE batches: Love stress, Kruyt–Rothenburg tangent, fabric, ...

All measures come back for every RVE of a batch from one pair of kernel launches.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import warp as wp

from granular_material.dem.model import Model, State

__all__ = ["Homogenized", "homogenize", "void_ratio"]


@dataclass(frozen=True)
class Homogenized:
    """Homogenised response of B RVEs (tension positive, SI).

    Attributes:
        stress: Love stress σ [Pa], shape (B, 2, 2), float64.
        tangent: Kruyt–Rothenburg tangent C [Pa], dσ_ij/d(∂u_k/∂x_l), shape (B, 2, 2, 2, 2).
        void_ratio: 2D void ratio e = (A − A_solid)/A_solid [-], shape (B,).
        coordination: Z = 2·N_c/N [-], shape (B,).
        fabric: φ = (1/N_c) Σ n⊗n [-], shape (B, 2, 2).
        unbalanced_force: mean |net disc force| / mean |contact force| [-], shape (B,).
        n_contacts: N_c, shape (B,). sliding_fraction: share of contacts at the Coulomb cap.
        volume: RVE volume V = det(H)·t [m³], shape (B,).
    """

    stress: np.ndarray
    tangent: np.ndarray
    void_ratio: np.ndarray
    coordination: np.ndarray
    fabric: np.ndarray
    unbalanced_force: np.ndarray
    n_contacts: np.ndarray
    sliding_fraction: np.ndarray
    volume: np.ndarray

    @classmethod
    def concatenate(cls, parts: list[Homogenized]) -> Homogenized:
        """Join the results of consecutive groups of RVEs along the batch axis."""
        if len(parts) == 1:
            return parts[0]
        return cls(**{f.name: np.concatenate([getattr(p, f.name) for p in parts])
                      for f in fields(cls)})

    @property
    def mean_stress(self) -> np.ndarray:
        """p = tr σ / 2 [Pa] (2D, tension positive), shape (B,)."""
        return 0.5 * np.trace(self.stress, axis1=1, axis2=2)


def void_ratio(radius: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """2D void ratio of discs ``radius`` (B, N) [m] in cells ``cell`` (B, 2, 2) [m]."""
    solid = np.pi * np.sum(np.asarray(radius) ** 2, axis=1)
    return np.linalg.det(cell) / solid - 1.0


def homogenize(model: Model, state: State) -> Homogenized:
    """Love stress and Kruyt–Rothenburg tangent of every RVE in ``state``.

    Notes:
        Love (1927) / Christoffersen et al. (1981), Wu et al. (2025) Eq. 5, tension positive:
        ``σ_ij = −(1/V) Σ_c f_i d_j`` with f the force of disc a on disc b and d = x_b − x_a.
        Kruyt & Rothenburg (1998), Wu et al. Eq. 6, uniform-strain estimate:
        ``C_ijkl = (1/V) Σ_c (kn n_i d_j n_k d_l + kt t_i d_j t_k d_l)``, t = perp(n), all
        contacts (sliding ones included, as Wu et al. and Guo & Zhao do).
    """
    ks = model.kernels
    dev = model.device
    b, n, k = model.n_rve, model.n_disc, model.capacity
    p_stress = wp.zeros(b * n, dtype=ks.mat22, device=dev)
    p_tangent = wp.zeros(b * n, dtype=ks.mat44, device=dev)
    p_fabric = wp.zeros(b * n, dtype=ks.mat22, device=dev)
    p_counts = wp.zeros(b * n, dtype=ks.vec2, device=dev)
    p_forces = wp.zeros(b * n, dtype=ks.vec2, device=dev)
    wp.launch(
        ks.contact_measures, dim=b * n, device=dev,
        inputs=[n, k, *model.law_args, model.friction, state.cell, state.frac, model.radius,
                state.nbr, state.nbr_count, state.shear, p_stress, p_tangent, p_fabric,
                p_counts, p_forces],
    )
    stress = wp.zeros(b, dtype=ks.mat22, device=dev)
    tangent = wp.zeros(b, dtype=ks.mat44, device=dev)
    fabric = wp.zeros(b, dtype=ks.mat22, device=dev)
    counts = wp.zeros(b, dtype=ks.vec2, device=dev)
    forces = wp.zeros(b, dtype=ks.vec2, device=dev)
    wp.launch(
        ks.reduce_measures, dim=b, device=dev,
        inputs=[n, p_stress, p_tangent, p_fabric, p_counts, p_forces, stress, tangent, fabric,
                counts, forces],
    )
    cell = state.cell.numpy().astype(np.float64)
    volume = np.linalg.det(cell) * model.meta.thickness
    counts_h = counts.numpy().astype(np.float64)
    forces_h = forces.numpy().astype(np.float64)
    n_c = counts_h[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        fab = np.where(n_c[:, None, None] > 0, fabric.numpy() / n_c[:, None, None], 0.0)
        sliding = np.where(n_c > 0, counts_h[:, 1] / n_c, 0.0)
        # mean net force per disc / mean force per contact
        unbalanced = np.where(
            forces_h[:, 1] > 0, (forces_h[:, 0] / n) / (forces_h[:, 1] / np.maximum(n_c, 1)),
            np.inf,
        )
    return Homogenized(
        stress=stress.numpy().astype(np.float64) / volume[:, None, None],
        tangent=tangent.numpy().astype(np.float64).reshape(b, 2, 2, 2, 2)
        / volume[:, None, None, None, None],
        void_ratio=void_ratio(model.radius_host, cell),
        coordination=2.0 * n_c / n,
        fabric=fab,
        unbalanced_force=unbalanced,
        n_contacts=n_c.round().astype(np.int64),
        sliding_fraction=sliding,
        volume=volume,
    )
