"""Homogenised measures of RVE batches: Love stress, Kruyt–Rothenburg tangent, fabric, ...

All measures come back for every RVE of a batch from one pair of kernel launches.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import warp as wp

from granular_material.dem.kernels.sets import KernelSet, kernels_for, launch
from granular_material.dem.model import Model
from granular_material.dem.state import State

__all__ = ["Homogenized", "MeasureBuffers", "homogenize", "objective_tangent",
           "spin_tangent", "symmetric_part", "void_ratio"]


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

    def take(self, rves: np.ndarray) -> Homogenized:
        """The results of the RVEs ``rves`` (indices or a boolean mask over B)."""
        return Homogenized(**{f.name: np.asarray(getattr(self, f.name))[rves]
                              for f in fields(self)})

    def with_rves(self, rves: np.ndarray, other: Homogenized) -> Homogenized:
        """A copy whose RVEs ``rves`` (boolean mask over B) hold ``other``'s results (one
        per masked RVE, in order); the others keep these."""
        out = {}
        for f in fields(self):
            values = np.array(getattr(self, f.name), copy=True)
            values[rves] = getattr(other, f.name)
            out[f.name] = values
        return Homogenized(**out)

    @property
    def mean_stress(self) -> np.ndarray:
        """p = tr σ / 2 [Pa] (2D, tension positive), shape (B,)."""
        return 0.5 * np.trace(self.stress, axis1=1, axis2=2)


def void_ratio(radius: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """2D void ratio of discs ``radius`` (B, N) [m] in cells ``cell`` (B, 2, 2) [m]."""
    solid = np.pi * np.sum(np.asarray(radius) ** 2, axis=1)
    return np.linalg.det(cell) / solid - 1.0


def symmetric_part(tangent: np.ndarray) -> np.ndarray:
    """C_(ij)(kl): ``tangent`` (B, 2, 2, 2, 2) averaged over i↔j and k↔l (minor symmetries;
    of the Kruyt–Rothenburg tangent this is Guo & Zhao's
    Σ_c [kn (n⊗d)ˢ⊗(n⊗d)ˢ + kt (t⊗d)ˢ⊗(t⊗d)ˢ]/V, which has the major symmetry too)."""
    c = np.asarray(tangent, dtype=np.float64)
    return 0.25 * (c + c.swapaxes(1, 2) + c.swapaxes(3, 4) + c.swapaxes(1, 2).swapaxes(3, 4))


def spin_tangent(stress: np.ndarray) -> np.ndarray:
    """∂(Wσ − σW)_ij/∂(∂u_k/∂x_l) [Pa], W = skew ∇u, of symmetric stresses ``stress``
    (B, 2, 2): how a small rigid spin rotates σ; shape (B, 2, 2, 2, 2)."""
    s = np.asarray(stress, dtype=np.float64)
    eye = np.eye(2)
    return 0.5 * (np.einsum("ik,blj->bijkl", eye, s) - np.einsum("il,bkj->bijkl", eye, s)
                  - np.einsum("bik,jl->bijkl", s, eye) + np.einsum("bil,jk->bijkl", s, eye))


def objective_tangent(tangent: np.ndarray, stress: np.ndarray) -> np.ndarray:
    """The objective tangent [Pa], (B, 2, 2, 2, 2): the symmetric part of ``tangent``
    (:func:`symmetric_part`, applied to the strain ε = sym ∇u) plus the rotation of the
    symmetric ``stress`` by the spin (:func:`spin_tangent`). A spin W then gives
    Wσ − σW, as an objective RVE does, where the Kruyt–Rothenburg tangent sends it through
    its kt term (about 1000× too stiff). The lever arms' stretch and the volume change
    (terms of order σ·ε) are left out, as Kruyt–Rothenburg leaves them out."""
    return symmetric_part(tangent) + spin_tangent(stress)


class MeasureBuffers:
    """Device work arrays of :func:`homogenize` for one model's sizes, allocated once."""

    def __init__(self, model: Model) -> None:
        ft = model.float_type
        dev = model.device
        vec2 = wp.types.vector(2, ft)
        mat22 = wp.types.matrix((2, 2), ft)
        mat44 = wp.types.matrix((4, 4), ft)
        b, n = model.n_rve, model.n_disc
        self.shape = (model.n_rve, model.n_disc, model.dtype, model.device)
        self.part_stress = wp.zeros(b * n, dtype=mat22, device=dev)
        self.part_tangent = wp.zeros(b * n, dtype=mat44, device=dev)
        self.part_fabric = wp.zeros(b * n, dtype=mat22, device=dev)
        self.part_counts = wp.zeros(b * n, dtype=vec2, device=dev)
        self.part_forces = wp.zeros(b * n, dtype=vec2, device=dev)
        self.stress = wp.zeros(b, dtype=mat22, device=dev)
        self.tangent = wp.zeros(b, dtype=mat44, device=dev)
        self.fabric = wp.zeros(b, dtype=mat22, device=dev)
        self.counts = wp.zeros(b, dtype=vec2, device=dev)
        self.forces = wp.zeros(b, dtype=vec2, device=dev)


def homogenize(model: Model, state: State, buffers: MeasureBuffers | None = None,
               kernels: KernelSet | None = None) -> Homogenized:
    """Love stress and Kruyt–Rothenburg tangent of every RVE in ``state``.

    ``buffers`` (reused between calls) and ``kernels`` (the replica to launch) are made
    when not given.

    Notes:
        Love (1927) / Christoffersen et al. (1981), Wu et al. (2025) Eq. 5, tension positive:
        ``σ_ij = −(1/V) Σ_c f_i d_j`` with f the force of disc a on disc b and d = x_b − x_a.
        Kruyt & Rothenburg (1998), Wu et al. Eq. 6, uniform-strain estimate:
        ``C_ijkl = (1/V) Σ_c (kn n_i d_j n_k d_l + kt t_i d_j t_k d_l)``, t = perp(n), all
        contacts (sliding ones included, as Wu et al. and Guo & Zhao do).
    """
    ks = kernels or kernels_for(model.dtype)
    dev = model.device
    b, n, k = model.n_rve, model.n_disc, model.capacity
    buf = buffers if buffers is not None else MeasureBuffers(model)
    if buf.shape != (model.n_rve, model.n_disc, model.dtype, model.device):
        raise ValueError(f"measure buffers are for {buf.shape}, not this model")
    launch(ks.contact_measures, b * n, dev, n_disc=n, capacity=k, law=model.law,
           friction=model.constants.friction, cell=state.cell,
           fractional_position=state.fractional_position, radius=model.constants.radius,
           contact_partner=state.contact_partner, contact_count=state.contact_count,
           contact_mirror_slot=state.contact_mirror_slot,
           contact_shear_force=state.contact_shear_force, part_stress=buf.part_stress,
           part_tangent=buf.part_tangent, part_fabric=buf.part_fabric,
           part_counts=buf.part_counts, part_forces=buf.part_forces)
    launch(ks.reduce_measures, b, dev, n_disc=n, part_stress=buf.part_stress,
           part_tangent=buf.part_tangent, part_fabric=buf.part_fabric,
           part_counts=buf.part_counts, part_forces=buf.part_forces, stress=buf.stress,
           tangent=buf.tangent, fabric=buf.fabric, counts=buf.counts, forces=buf.forces)
    cell = state.cell.numpy().astype(np.float64)
    volume = np.linalg.det(cell) * model.meta.thickness
    counts_h = buf.counts.numpy().astype(np.float64)
    forces_h = buf.forces.numpy().astype(np.float64)
    n_c = counts_h[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        fab = np.where(n_c[:, None, None] > 0, buf.fabric.numpy() / n_c[:, None, None], 0.0)
        sliding = np.where(n_c > 0, counts_h[:, 1] / n_c, 0.0)
        # mean net force per disc / mean force per contact
        unbalanced = np.where(
            forces_h[:, 1] > 0, (forces_h[:, 0] / n) / (forces_h[:, 1] / np.maximum(n_c, 1)),
            np.inf,
        )
    return Homogenized(
        stress=buf.stress.numpy().astype(np.float64) / volume[:, None, None],
        tangent=buf.tangent.numpy().astype(np.float64).reshape(b, 2, 2, 2, 2)
        / volume[:, None, None, None, None],
        void_ratio=void_ratio(model.radius, cell),
        coordination=2.0 * n_c / n,
        fabric=fab,
        unbalanced_force=unbalanced,
        n_contacts=n_c.round().astype(np.int64),
        sliding_fraction=sliding,
        volume=volume,
    )
