"""The continuum start of a boundary-value problem: the loads at step 0 (the body's own weight,
its pressures) carried by a linear-elastic stand-in of its material, its stress then kept
inside a fraction of the material's strength and above a floor, and settled back towards
equilibrium.

Tension positive, Pa, batch-first (n, 2, 2), plane strain. Three stages, each a function:

1. **The elastic state** (:func:`elastic_stress`). One linear solve K u = f_ext on the free
   degrees of freedom, the problem's supports held at zero displacement, K of isotropic
   plane-strain elasticity with each point's own E and ν; σ = D:ε(u). It is in discrete
   equilibrium with the loads to round-off, whatever the surface's shape. With one material
   it does not depend on E (u is proportional to 1/E, σ is not), only on ν.
2. **The limits** (:func:`limit_stress`). At a free surface σ → 0, and near a steep face the
   elastic state may ask more friction than the material has. A point whose least principal
   compression is below its floor p_min is lifted to it by an isotropic pressure (the
   geostatic start's rule, :func:`~granular_material.fem.boundary_value.ground.lift_to_floor`),
   and then a point whose mobilised friction angle φ_m, sin φ_m = (σ1 − σ3)/(σ1 + σ3)
   (cohesionless), exceeds its cap φ_cap is brought to it: its mean stress
   (σ1 + σ3)/2 and principal directions kept, its deviator scaled down. The cap never lowers
   σ3 below where the floor put it (it raises it).
3. **Settling** (:func:`settle`). The limits unbalance the state. The initial-stiffness
   iteration of plasticity takes the residual back: the elastic body's correction for the
   residual is added (one factorised K, one back-substitution an iteration), then the
   limits again, until the residual stops falling. Where the slope can stand with the capped
   friction everywhere, what remains is the floor's own imbalance near the free surface (an
   isotropic pressure at a traction-free surface cannot be in equilibrium); where it
   cannot, the capped points keep a residual the first load step must carry.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse.linalg import splu
from skfem import Basis

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.ground import elastic_tangent, lift_to_floor
from granular_material.fem.forms import gauss_points_grad, internal_force, stiffness

__all__ = ["ContinuumStart", "cap_friction", "elastic_stress", "limit_stress",
           "mobilised_friction", "settle"]

#: settling iterations at most (each one back-substitution and one internal force)
MAX_SETTLE = 200


def mobilised_friction(stress: np.ndarray) -> np.ndarray:
    """φ_m [°] (n,) of every stress [Pa] (n, 2, 2), tension positive: sin φ_m =
    (σ1 − σ3)/(σ1 + σ3) of its principal compressions (90° where σ1 + σ3 <= 0, a point in
    tension or unstressed)."""
    compression = -np.linalg.eigvalsh(np.asarray(stress, dtype=np.float64))
    major, minor = compression[:, 0], compression[:, 1]
    total = major + minor
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(total > 0, (major - minor) / total, 1.0)
    return np.degrees(np.arcsin(np.clip(ratio, 0.0, 1.0)))


def cap_friction(stress: np.ndarray, cap: float | np.ndarray,
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``stress`` [Pa] (n, 2, 2) with every point whose mobilised friction angle exceeds its
    ``cap`` φ_cap [°] (one or one per point; NaN or inf: none) brought to it, its mean
    stress and principal directions kept and its deviator scaled by sin φ_cap / sin φ_m;
    and the indices of the points changed. A point whose mean stress is not compressive is
    left alone (the floor lifts it first)."""
    sigma = np.asarray(stress, dtype=np.float64)
    cap = np.broadcast_to(np.asarray(cap, dtype=np.float64), (sigma.shape[0],))
    mean = 0.5 * (sigma[:, 0, 0] + sigma[:, 1, 1])
    deviator = sigma - mean[:, None, None] * np.eye(2)
    radius = np.sqrt(0.25 * (sigma[:, 0, 0] - sigma[:, 1, 1]) ** 2 + sigma[:, 0, 1] ** 2)
    allowed = np.where(np.isfinite(cap), np.sin(np.radians(np.clip(cap, 0.0, 90.0))), np.inf)
    limit = allowed * np.maximum(-mean, 0.0)
    capped = np.flatnonzero((mean < 0) & (radius > limit))
    out = sigma.copy()
    scale = limit[capped] / radius[capped]
    out[capped] = mean[capped, None, None] * np.eye(2) + scale[:, None, None] * deviator[capped]
    return out, capped


def limit_stress(stress: np.ndarray, floor: float | np.ndarray, cap: float | np.ndarray,
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The floor then the cap (see the module docstring): ``stress`` [Pa] (n, 2, 2) lifted
    where its least principal compression is below ``floor`` [Pa] (−inf: none) and capped
    where its mobilised friction exceeds ``cap`` [°] (inf: none); the indices lifted and
    capped."""
    lifted_stress, lifted = lift_to_floor(stress, floor)
    out, capped = cap_friction(lifted_stress, cap)
    return out, lifted, capped


def _free(n: int, fixed: np.ndarray) -> np.ndarray:
    free = np.ones(n, dtype=bool)
    free[np.asarray(fixed, dtype=np.int64)] = False
    return np.flatnonzero(free)


def _per_point(name: str, value: float | np.ndarray, n: int, low: float, high: float,
               ) -> np.ndarray:
    array = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,))
    bad = ~(np.isfinite(array) & (array > low) & (array < high))
    if bad.any():
        raise ParameterError(name, f"must lie in ({low:g}, {high:g}) at every point, got "
                                   f"{array[bad][0]!r}")
    return array


class _Body:
    """The elastic stand-in: its tangent per point and its factorised stiffness on the free
    dofs."""

    def __init__(self, basis: Basis, fixed: np.ndarray, young: float | np.ndarray,
                 poisson: float | np.ndarray) -> None:
        n = basis.X.shape[-1] * basis.nelems
        e = _per_point("young", young, n, 0.0, math.inf)
        nu = _per_point("poisson", poisson, n, -1.0, 0.5)
        self.basis = basis
        self.tangent = elastic_tangent(nu) * e[:, None, None, None, None]
        self.index = _free(basis.N, fixed)
        k = stiffness(basis, self.tangent).tocsr()
        self.lu = splu(k[self.index][:, self.index].tocsc())

    def stress_of(self, force: np.ndarray) -> np.ndarray:
        """The stress [Pa] (n, 2, 2) of the body under the nodal ``force`` on its free dofs."""
        u = np.zeros(self.basis.N)
        u[self.index] = self.lu.solve(np.asarray(force, dtype=np.float64)[self.index])
        delta = np.einsum("nijkl,nkl->nij", self.tangent, gauss_points_grad(self.basis, u))
        return 0.5 * (delta + np.swapaxes(delta, 1, 2))

    def residual(self, stress: np.ndarray, force: np.ndarray) -> np.ndarray:
        """f_ext − f_int [N/m] of ``stress`` on the free dofs (zero on the fixed)."""
        r = np.asarray(force, dtype=np.float64) - internal_force(self.basis, stress)
        out = np.zeros_like(r)
        out[self.index] = r[self.index]
        return out


def elastic_stress(basis: Basis, force: np.ndarray, fixed: np.ndarray,
                   young: float | np.ndarray, poisson: float | np.ndarray) -> np.ndarray:
    """σ [Pa] (n, 2, 2) of the linear-elastic body (E [Pa] and ν [-] one or one per Gauss
    point) under the nodal ``force`` [N/m] (ndofs,), the dofs ``fixed`` held at zero: in
    discrete equilibrium with it."""
    return _Body(basis, fixed, young, poisson).stress_of(force)


@dataclass(frozen=True)
class ContinuumStart:
    """The start of :func:`settle`.

    Attributes:
        stress: the settled stress [Pa] (n, 2, 2), tension positive, within its floor and
            cap.
        elastic: the elastic state [Pa] (n, 2, 2), in equilibrium.
        lifted: the points of ``stress`` lifted to their floor (indices).
        capped: the points of ``stress`` brought to their friction cap (indices).
        residual_limited: ‖R‖/‖f_ext‖ of the elastic state after the limits, before settling.
        residual: ‖R‖/‖f_ext‖ of ``stress`` over the free dofs.
        iterations: settling iterations made.
    """

    stress: np.ndarray
    elastic: np.ndarray
    lifted: np.ndarray
    capped: np.ndarray
    residual_limited: float
    residual: float
    iterations: int


def settle(basis: Basis, force: np.ndarray, fixed: np.ndarray, young: float | np.ndarray,
           poisson: float | np.ndarray, floor: float | np.ndarray = -np.inf,
           cap: float | np.ndarray = np.inf, max_iterations: int = MAX_SETTLE,
           rtol: float = 1e-10) -> ContinuumStart:
    """The continuum start (see the module docstring): the elastic state of the body (E [Pa],
    ν [-]) under ``force`` [N/m], limited by ``floor`` [Pa] and ``cap`` [°] (each one or one
    per point) and settled by initial-stiffness iterations until ‖R‖/‖f_ext‖ <= ``rtol`` or
    it falls by less than 0.1 % in an iteration (at most ``max_iterations``); the state
    with the smallest residual is returned."""
    body = _Body(basis, fixed, young, poisson)
    elastic = body.stress_of(force)
    load = float(np.linalg.norm(np.asarray(force)[body.index])) or 1.0
    sigma, lifted, capped = limit_stress(elastic, floor, cap)
    r = body.residual(sigma, force)
    first = best = float(np.linalg.norm(r)) / load
    kept = (sigma, lifted, capped)
    iterations = 0
    while iterations < max_iterations and best > rtol:
        iterations += 1
        sigma, lifted, capped = limit_stress(sigma + body.stress_of(r), floor, cap)
        r = body.residual(sigma, force)
        now = float(np.linalg.norm(r)) / load
        if now < best:
            falling = now < 0.999 * best
            best, kept = now, (sigma, lifted, capped)
            if not falling:
                break
        else:
            break
    sigma, lifted, capped = kept
    return ContinuumStart(sigma, elastic, lifted, capped, first, best, iterations)
