"""The Mohr–Coulomb return mapping in principal stresses: pure functions on batches.

Principal stresses come sorted, σ1 ≥ σ2 ≥ σ3 [Pa], tension positive, shape (m, 3): the
in-plane pair and σzz of a plane-strain point. The yield function of the plane of the major
stress i and the minor j is

    f_ij = (σ_i − σ_j) + (σ_i + σ_j) sin φ − 2 c cos φ,

the plastic potential g_ij the same with the dilation angle ψ (non-associated for ψ < φ).
The return is implicit (backward Euler) with isotropic elasticity, so it keeps the principal
directions; it lands on one of four regions (:data:`REGIONS`): the smooth face f_13, the edge
σ1 = σ2 (planes 13 and 23, the "right" corner of de Souza Neto, Perić & Owen, Computational
Methods for Plasticity, 2008, §8.2), the edge σ2 = σ3 (planes 13 and 12, the "left" corner)
or the apex σ1 = σ2 = σ3 = c cot φ. With c = 0 the apex is the origin: the point is
stress-free there and has no strength. With φ = 0 (Tresca, f_ij = σ_i − σ_j − 2c) the
surface is a prism along the hydrostatic axis with no apex: every return lands on the face or
an edge (no division by sin φ or tan φ is made on the way).

Hardening variable: the plastic shear strain γp, whose increment is 2 Σ Δγ^i over the
active planes' multipliers (de Souza Neto et al., §8.2, take 2 cos φ Σ Δγ^i; the factor
cos φ is left out so that γp is a strain whatever φ is). On the face it is the principal
plastic shear Δε1p − Δε3p = ((σ1tr − σ1) − (σ3tr − σ3)) / (2G), so there
dεvp/dγp = sin ψ (tension positive); the sum is symmetric in the two planes of an edge, so
the return is a smooth function of the trial where two trial principal stresses are equal.
The apex (no unique multipliers) takes the principal plastic shear, (σ1tr − σ3tr) / (2G).
Softening: φ falls linearly in γp from φ to φcs and ψ from ψ to 0 over
``softening_strain``, constant after.

For a given γp each region's return is linear in the multipliers (closed form). With
softening the one unknown left is γp itself: a scalar Newton on
r(γp) = γp − γp_n − Δγp(γp) = 0, safeguarded by bisection in the bracket
[γp_n, max(softening_strain, γp_n + Δγp of the fully softened angles)] and differentiated
analytically, so the algorithmic Jacobian ∂σ/∂σtr (m, 3, 3) is exact (dγp/dσtr
included). Where softening is so brittle that ∂Δγp/∂γp > 1 (a snap-back of the point
itself: a tiny ``softening_strain`` at high pressure) the return may have several
solutions or none in the region the trial points to; such a point is reported as not
converged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "APEX",
    "EDGE_MAJOR",
    "EDGE_MINOR",
    "ELASTIC",
    "FACE",
    "REGIONS",
    "SYM4",
    "ReturnResult",
    "Strength",
    "in_plane_principal",
    "principal_return",
    "spectral_derivative",
    "yield_function",
]

ELASTIC, FACE, EDGE_MAJOR, EDGE_MINOR, APEX = 0, 1, 2, 3, 4
#: the return regions by code: elastic, face f13, edge σ1 = σ2, edge σ2 = σ3, apex
REGIONS = {ELASTIC: "elastic", FACE: "face", EDGE_MAJOR: "edge σ1=σ2",
           EDGE_MINOR: "edge σ2=σ3", APEX: "apex"}
# the active planes of each region as (major, minor) indices into σ1 ≥ σ2 ≥ σ3
_PLANES = {FACE: ((0, 2),), EDGE_MAJOR: ((0, 2), (1, 2)), EDGE_MINOR: ((0, 2), (0, 1))}
_EYE3 = np.eye(3)
_EYE2 = np.eye(2)
#: the symmetric fourth-order identity ½ (δ_ik δ_jl + δ_il δ_jk) as a 4 × 4 matrix (ij, kl)
SYM4 = 0.5 * (np.einsum("ik,jl->ijkl", _EYE2, _EYE2)
              + np.einsum("il,jk->ijkl", _EYE2, _EYE2)).reshape(4, 4)


@dataclass(frozen=True)
class Strength:
    """The constants of a return: elasticity and strength, angles in radians.

    Attributes:
        shear: shear modulus G [Pa].
        lame: Lamé's λ [Pa].
        phi: peak friction angle φ [rad].
        psi: peak dilation angle ψ [rad].
        cohesion: c [Pa].
        phi_cs: friction angle after softening [rad] (= phi: no softening).
        softening_strain: γp over which φ and ψ soften [-] (0: no softening).
    """

    shear: float
    lame: float
    phi: float
    psi: float
    cohesion: float
    phi_cs: float
    softening_strain: float

    @property
    def softening(self) -> bool:
        """Whether φ or ψ change with γp."""
        return self.softening_strain > 0 and (self.phi_cs != self.phi or self.psi != 0)

    def angles(self, gamma: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(φ, ψ, dφ/dγp, dψ/dγp) [rad] at the plastic shear strains ``gamma`` (m,)."""
        gamma = np.asarray(gamma, dtype=np.float64)
        if not self.softening:
            full = np.ones_like(gamma)
            return self.phi * full, self.psi * full, 0 * full, 0 * full
        x = np.clip(gamma / self.softening_strain, 0.0, 1.0)
        rate = np.where(gamma < self.softening_strain, 1.0 / self.softening_strain, 0.0)
        phi = self.phi + (self.phi_cs - self.phi) * x
        psi = self.psi * (1.0 - x)
        return phi, psi, (self.phi_cs - self.phi) * rate, -self.psi * rate


@dataclass(frozen=True)
class ReturnResult:
    """The outcome of :func:`principal_return` for m points (sorted principal order).

    Attributes:
        stress: returned principal stresses [Pa] (m, 3).
        gamma: plastic shear strain γp after the step [-] (m,).
        jacobian: ∂σ/∂σtr [-] (m, 3, 3), exact.
        region: the return region (:data:`REGIONS`) (m,), int8.
        converged: False where the local Newton did not converge (m,).
        iterations: local Newton iterations spent, all points together.
    """

    stress: np.ndarray
    gamma: np.ndarray
    jacobian: np.ndarray
    region: np.ndarray
    converged: np.ndarray
    iterations: int


def yield_function(principal: np.ndarray, phi: np.ndarray | float, cohesion: float
                   ) -> np.ndarray:
    """f = (σ1 − σ3) + (σ1 + σ3) sin φ − 2 c cos φ [Pa] of sorted principal stresses
    ``principal`` (m, 3) [Pa], φ [rad]; > 0 outside the surface."""
    s1, s3 = principal[:, 0], principal[:, 2]
    return (s1 - s3) + (s1 + s3) * np.sin(phi) - 2.0 * cohesion * np.cos(phi)


@dataclass
class _Planes:
    """One closed-form return onto given planes at a given γp, and its derivatives."""

    stress: np.ndarray  # (m, 3)
    multipliers: np.ndarray  # Δγ of each plane (m, k)
    h: np.ndarray  # Δγp (m,)
    stress_theta: np.ndarray  # ∂σ/∂γp (m, 3)
    h_theta: np.ndarray  # ∂Δγp/∂γp (m,)
    j0: np.ndarray  # ∂σ/∂σtr at fixed γp (m, 3, 3)
    h_sigma: np.ndarray  # ∂Δγp/∂σtr at fixed γp (m, 3)


_FIELDS = ("stress", "multipliers", "h", "stress_theta", "h_theta", "j0", "h_sigma")


def _solve_planes(trial: np.ndarray, theta: np.ndarray, region: int, st: Strength) -> _Planes:
    planes = _PLANES[region]
    m, k = trial.shape[0], len(planes)
    phi, psi, dphi, dpsi = st.angles(theta)
    s, co, t, cp = np.sin(phi), np.cos(phi), np.sin(psi), np.cos(psi)
    f, df, n, dn = (np.zeros((m, 3, k)) for _ in range(4))
    for q, (i, j) in enumerate(planes):
        f[:, i, q], f[:, j, q] = 1 + s, -(1 - s)
        df[:, i, q] = df[:, j, q] = co * dphi
        n[:, i, q], n[:, j, q] = 1 + t, -(1 - t)
        dn[:, i, q] = dn[:, j, q] = cp * dpsi
    elastic = st.lame * np.ones((3, 3)) + 2 * st.shear * _EYE3
    a = np.einsum("ab,mbq->maq", elastic, n)
    da = np.einsum("ab,mbq->maq", elastic, dn)
    mat = np.einsum("maq,mar->mqr", f, a)
    rhs = np.einsum("maq,ma->mq", f, trial) - 2 * st.cohesion * co[:, None]
    drhs = np.einsum("maq,ma->mq", df, trial) + (2 * st.cohesion * s * dphi)[:, None]
    inv = np.linalg.inv(mat)
    mult = np.einsum("mqr,mr->mq", inv, rhs)
    dmat = np.einsum("maq,mar->mqr", df, a) + np.einsum("maq,mar->mqr", f, da)
    dmult = np.einsum("mqr,mr->mq", inv, drhs - np.einsum("mqr,mr->mq", dmat, mult))
    stress = trial - np.einsum("maq,mq->ma", a, mult)
    stress_theta = -np.einsum("maq,mq->ma", da, mult) - np.einsum("maq,mq->ma", a, dmult)
    dmult_dtrial = np.einsum("mqr,mbr->mqb", inv, f)  # M⁻¹ Fᵀ
    proj = np.einsum("maq,mqb->mab", a, dmult_dtrial)  # A M⁻¹ Fᵀ
    return _Planes(stress, mult, 2 * mult.sum(axis=1), stress_theta, 2 * dmult.sum(axis=1),
                   _EYE3 - proj, 2 * dmult_dtrial.sum(axis=1))


def _return_onto(trial: np.ndarray, gamma_n: np.ndarray, region: int, st: Strength,
                 max_iterations: int) -> tuple[_Planes, np.ndarray, np.ndarray, int]:
    """The return onto ``region``'s planes with γp solved for: (solution, γp, converged,
    iterations)."""
    if not st.softening:  # Δγp does not depend on γp: no iteration
        sol = _solve_planes(trial, gamma_n, region, st)
        return sol, gamma_n + sol.h, np.ones(len(gamma_n), dtype=bool), 0
    # a bracket: r(γp_n) = −Δγp ≤ 0, and past the softening strain Δγp is constant, h_cs,
    # so r ≥ 0 at max(softening_strain, γp_n + h_cs)
    top = np.maximum(gamma_n, st.softening_strain)
    theta, lo = gamma_n.copy(), gamma_n.copy()
    hi = np.maximum(top, gamma_n + _solve_planes(trial, top, region, st).h)
    done = np.zeros(len(gamma_n), dtype=bool)
    sol = _solve_planes(trial, theta, region, st)
    iterations = 0
    for it in range(max_iterations):
        todo = np.flatnonzero(~done)
        if not todo.size:
            break
        part = sol if it == 0 else _solve_planes(trial[todo], theta[todo], region, st)
        if it:
            for name in _FIELDS:
                getattr(sol, name)[todo] = getattr(part, name)
        th = theta[todo]
        r = th - gamma_n[todo] - part.h
        ok = np.abs(r) <= 1e-15 + 1e-13 * np.abs(th)
        done[todo[ok]] = True
        lo[todo] = np.where(r < 0, th, lo[todo])
        hi[todo] = np.where(r > 0, th, hi[todo])
        slope = 1.0 - part.h_theta
        with np.errstate(divide="ignore", invalid="ignore"):
            step = th - r / slope
        inside = (slope > 0) & (step >= lo[todo]) & (step <= hi[todo])
        theta[todo] = np.where(ok, th, np.where(inside, step, 0.5 * (lo[todo] + hi[todo])))
        iterations += int((~ok).sum())
    return sol, theta, done, iterations


def _ordered(stress: np.ndarray, tol: np.ndarray) -> np.ndarray:
    return (stress[:, 0] >= stress[:, 1] - tol) & (stress[:, 1] >= stress[:, 2] - tol)


def _apex(trial: np.ndarray, gamma_n: np.ndarray, st: Strength
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The apex σ = c cot φ(γp) with γp = γp_n + (σ1tr − σ3tr)/(2G): (stress, γp, J)."""
    theta = gamma_n + (trial[:, 0] - trial[:, 2]) / (2 * st.shear)
    phi, _, dphi, _ = st.angles(theta)
    p = st.cohesion / np.tan(phi)
    dp = -st.cohesion / np.sin(phi) ** 2 * dphi
    dtheta = np.array([1.0, 0.0, -1.0]) / (2 * st.shear)
    jac = dp[:, None, None] * np.ones((1, 3, 1)) * dtheta[None, None, :]
    return np.repeat(p[:, None], 3, axis=1), theta, jac


def principal_return(trial: np.ndarray, gamma_n: np.ndarray, st: Strength,
                     max_iterations: int = 60) -> ReturnResult:
    """Return the sorted trial principal stresses ``trial`` (m, 3) [Pa] (σ1 ≥ σ2 ≥ σ3) with
    committed plastic shear strains ``gamma_n`` (m,) onto the Mohr–Coulomb surface.

    Regions are tried in turn: the face; where its result breaks σ1 ≥ σ2 ≥ σ3, the edge of
    the pair that crossed (σ2 > σ1: edge σ1 = σ2; else edge σ2 = σ3); where the edge's
    multipliers turn negative or σ1 < σ3, the apex. Tresca (φ = 0 throughout) has no apex:
    there the edge's return is always admissible (its multipliers are ≥ 0 whenever the face's
    return crossed that edge), so it is taken whatever rounding says.
    """
    trial = np.asarray(trial, dtype=np.float64)
    gamma_n = np.asarray(gamma_n, dtype=np.float64)
    m = trial.shape[0]
    stress, gamma = trial.copy(), gamma_n.copy()
    jac = np.broadcast_to(_EYE3, (m, 3, 3)).copy()
    region = np.zeros(m, dtype=np.int8)
    converged = np.ones(m, dtype=bool)
    scale = np.abs(trial).max(axis=1) + st.cohesion + 1e-300
    tol = 1e-12 * scale
    phi_n = st.angles(gamma_n)[0]
    tresca = st.phi == 0 and (st.phi_cs == 0 or not st.softening)
    todo = np.flatnonzero(yield_function(trial, phi_n, st.cohesion) > tol)
    iterations = 0

    def accept(idx: np.ndarray, sol: _Planes, theta: np.ndarray, code: int) -> None:
        slope = 1.0 - sol.h_theta
        dtheta = sol.h_sigma / slope[:, None]
        stress[idx], gamma[idx], region[idx] = sol.stress, theta, code
        jac[idx] = sol.j0 + sol.stress_theta[:, :, None] * dtheta[:, None, :]

    if todo.size:
        sol, theta, ok, its = _return_onto(trial[todo], gamma_n[todo], FACE, st, max_iterations)
        iterations += its
        good = ok & _ordered(sol.stress, tol[todo])
        accept(todo[good], _take(sol, good), theta[good], FACE)
        converged[todo[~ok]] = False
        bad = ~good & ok
        crossed_major = sol.stress[:, 1] > sol.stress[:, 0] + tol[todo]
        todo_edges = [(todo[bad & crossed_major], EDGE_MAJOR),
                      (todo[bad & ~crossed_major], EDGE_MINOR)]
        apex: list[np.ndarray] = []
        for idx, code in todo_edges:
            if not idx.size:
                continue
            sol, theta, ok, its = _return_onto(trial[idx], gamma_n[idx], code, st,
                                               max_iterations)
            iterations += its
            good = ok if tresca else (
                ok & (sol.multipliers >= -1e-12 * np.abs(sol.multipliers).max(
                    axis=1, keepdims=True)).all(axis=1)
                & (sol.stress[:, 0] >= sol.stress[:, 2] - tol[idx]))
            accept(idx[good], _take(sol, good), theta[good], code)
            converged[idx[~ok]] = False
            apex.append(idx[~good & ok])
        idx = np.concatenate(apex) if apex else np.zeros(0, dtype=np.int64)
        if idx.size:
            stress[idx], gamma[idx], jac[idx] = _apex(trial[idx], gamma_n[idx], st)
            region[idx] = APEX
    return ReturnResult(stress, gamma, jac, region, converged, iterations)


def _take(sol: _Planes, mask: np.ndarray) -> _Planes:
    return _Planes(*(getattr(sol, name)[mask] for name in _FIELDS))


def in_plane_principal(stress: np.ndarray, zz: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(principal (n, 3) = (a, b, zz) with a ≥ b the in-plane eigenvalues, the
    eigenprojections M_a and M_b (n, 2, 2)) of symmetric in-plane stresses."""
    xx, yy = stress[:, 0, 0], stress[:, 1, 1]
    xy = 0.5 * (stress[:, 0, 1] + stress[:, 1, 0])
    mean, radius = 0.5 * (xx + yy), np.hypot(0.5 * (xx - yy), xy)
    angle = 0.5 * np.arctan2(2 * xy, xx - yy)
    c, s = np.cos(angle), np.sin(angle)
    m_a = np.stack([np.stack([c * c, c * s], -1), np.stack([c * s, s * s], -1)], -2)
    return np.stack([mean + radius, mean - radius, zz], axis=1), m_a, _EYE2 - m_a


def spectral_derivative(jac: np.ndarray, principal: np.ndarray, returned: np.ndarray,
                        m_a: np.ndarray, m_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The derivative of σ = s_a M_a + s_b M_b (the in-plane stress rebuilt from returned
    principal values ``returned`` (n, 3) on the trial's eigenprojections) with respect to
    the in-plane trial stress and σzz,tr: (∂σ_ij/∂σtr_pq as (n, 4, 4) (ij, pq),
    ∂σ_ij/∂σzz,tr as (n, 4)).

    ``jac`` (n, 3, 3) is ∂(s_a, s_b, s_zz)/∂(t_a, t_b, t_zz), ``principal`` (n, 3) the trial
    values (t_a ≥ t_b, t_zz). The eigenvector term is (s_a − s_b)/(t_a − t_b)
    (I_s − M_a⊗M_a − M_b⊗M_b), whose factor tends to ∂s_a/∂t_a − ∂s_a/∂t_b as the in-plane
    eigenvalues meet (the return is symmetric in them).
    """
    n = jac.shape[0]
    gap = principal[:, 0] - principal[:, 1]
    close = np.abs(gap) <= 1e-10 * (np.abs(principal).max(axis=1) + 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        omega = np.where(close, jac[:, 0, 0] - jac[:, 0, 1],
                         (returned[:, 0] - returned[:, 1]) / gap)
    proj = np.stack([m_a, m_b], axis=1).reshape(n, 2, 4)  # (n, A, ij)
    proj_t = np.swapaxes(proj, 1, 2)
    spectral = proj_t @ jac[:, :2, :2] @ proj + omega[:, None, None] * (SYM4 - proj_t @ proj)
    return spectral, (jac[:, None, :2, 2] @ proj)[:, 0, :]
