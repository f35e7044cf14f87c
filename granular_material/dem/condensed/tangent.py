"""The condensed (non-affine) tangent of RVEs at equilibrium (Miehe & Dettmar, CMAME 2004).

Per RVE, the stiffness of its contact network is assembled over the discs' fluctuating
translations u_j [m] and rotations (as arc lengths w_j = r_j·θ_j [m], so that every unknown
is a length) and the four macro components G_kl = ∂u_k/∂x_l of the displacement gradient;
the fluctuations are then condensed out::

    C = (K_GG − K_Gu K_uu⁻¹ K_uG) / V        [Pa],  C_ijkl = ∂σ_ij/∂G_kl

K_GG/V is the affine term (Kruyt–Rothenburg's, see below); the second term is what the
particles' rearrangement takes away.

Contact kinematics are the engine's, linearised (``kernels_step.contact_forces``): for a
pair a < c with branch vector d = x_c − x_a (minimum image), n = d/|d|, t = perp(n) and
s = (r_a + r_c)/|d|,

- normal opening δn = n·(u_c − u_a + G·d),
- tangential slip δt = s·t·(u_c − u_a + G·d) − w_a − w_c − (r_a + r_c)·ω(G), with ω(G) =
  (G_10 − G_01)/2 the macro spin (disc rotations are measured from the cell's spin, as in
  the engine); a rigid rotation G = W therefore gives δn = δt = 0 exactly.

The contact's stiffness: kn on δn; kt on δt for a sticking contact; for a sliding one
(|fs| at μ·fn, the engine's test) the tangential spring does not resist further slip,
``sliding="free"`` (kt → 0), or, ``sliding="coulomb"``, the force stays on the cone,
Δfs = μ·sign(fs)·Δfn (non-symmetric), or, ``sliding="stick"``, it keeps kt: the stiffness
the network has once every slip stops or reverses, an upper bound of its incremental
stiffness in every direction (sliding and opening only take stiffness away; contacts that
form are not seen by any tangent at the state). Initial-stress (geometric) terms of order
fn/|d| are left out, as Kruyt–Rothenburg leaves them out.

Why an upper bound matters: modified Newton with a held symmetric tangent K contracts
where 0 < J ≤ K (J the response's own stiffness, the error shrinks by I − K⁻¹J), and
overshoots, cycles or diverges where J > 2K. With ``"free"`` a contact at its cap has
kt = 0 however the next increment moves it; where it moves back, it sticks and answers
with kt, so K underestimates J in those directions. Measured in docs/physics-tangents.md ("Sliding
contacts in the condensed tangent").

Properties, by construction: with ``sliding="free"`` (or ``"stick"``) C has major symmetry
(C_ijkl = C_klij; it is the Hessian of the network's energy over V), a spin costs nothing
(C_ijkl W_kl = 0: minor symmetry in kl) and so, by major symmetry, C is minor symmetric in
ij too; its affine term is the Kruyt–Rothenburg tangent symmetrised over (ij) and (kl),
with kt·s² in place of kt (s − 1 = overlap/|d|, about 1e-3) and, with ``"free"``, no kt at
sliding contacts.
With ``sliding="coulomb"`` C keeps the minor symmetry in kl but loses the major one.

What it predicts is the RVE's quasi-static response: central differences of the DEM (±1e-5,
applied slowly and held until at rest) within 0.5–1.6 % on 24-disc packings at 100 kPa
(tests); unseen deviatoric increments of 1e-4 on 100-disc ones within 1–4 % at p0 and
1–38 % after a 1 % shear (``benchmarks/condensed_tangent.py``: finite increments mobilise
sliding at contacts near their cap, which no tangent at the state sees). The FEM drives an
RVE at 1e-5 strain a step, 10 steps for 1e-4: too fast for the discs to relax, so that
response is stiffer than the quasi-static one (8 % at p0, up to 2× after shear).

Singular modes: rigid translation is removed by fixing the translation of one disc (any
disc of the network gives the same C, the fluctuations being periodic). Rattlers (no
touching partner) and discs with a single contact are left out, repeatedly (a disc that
loses its partner that way may drop to one contact too): a disc with one contact has three
unknowns against that contact's two relative displacements, so it follows its partner and
the contact carries no incremental force; leaving them out is exact, not an approximation.
What floppy modes remain (a disc all of whose contacts slide can spin freely; a bipartite
lattice can gear) are regularised by ``regularization`` times the mean diagonal stiffness
on every unknown: the loads K_uG lie in the range of K_uu (both are Bᵀ·k·… of the same
contacts), so a floppy mode takes no load and the regularisation only shifts C in
proportion to it (measured on 100-disc packings: 2e-9 to 1.3e-8 of max|C| at the default
1e-9). Finding and removing each mechanism exactly would cost a rank-revealing
factorisation; the diagonal shift costs nothing.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from granular_material.dem.rve.file import RVEData, _touching_pairs

__all__ = [
    "SLIDING_MODES",
    "SYMMETRIC_SLIDING",
    "CondensedTangent",
    "ContactNetwork",
    "condensed_tangent",
    "contact_network",
]

#: how the tangential spring of a contact at its Coulomb cap responds: "free" (it does not
#: resist further slip, kt → 0), "coulomb" (the force stays on the cone) or "stick" (it
#: keeps kt, as every contact does when the slip stops or reverses)
SLIDING_MODES = ("free", "coulomb", "stick")
#: the modes whose K_uu is symmetric positive definite (the CG paths take only these)
SYMMETRIC_SLIDING = ("free", "stick")
#: relative tolerance of the engine's sliding test |fs| >= μ fn (1 − tol) (kernels_measures)
SLIDING_TOLERANCE = 1e-9
#: macro spin ω(G) = (G_10 − G_01)/2 as coefficients over G_kl, index 2k + l
_SPIN = np.array([0.0, -0.5, 0.5, 0.0])


@dataclass(frozen=True)
class ContactNetwork:
    """The touching pairs of one RVE, as the engine sees them (SI).

    Attributes:
        a, c: disc indices of each contact, a < c, shape (M,).
        branch: d = x_c − x_a [m] (minimum image), (M, 2).
        radius_a, radius_c: radii [m], (M,).
        kn, kt: contact stiffnesses [N/m], (M,).
        normal_force: fn = kn·overlap [N] (> 0 in compression), (M,).
        shear_force: the tangential spring force fs [N] (the owner's), (M,).
        sliding: whether |fs| is at the Coulomb cap μ·fn, (M,), bool.
        friction: μ = tan φ [-]. volume: RVE volume det(H)·t [m³]. n_disc: N.
    """

    a: np.ndarray
    c: np.ndarray
    branch: np.ndarray
    radius_a: np.ndarray
    radius_c: np.ndarray
    kn: np.ndarray
    kt: np.ndarray
    normal_force: np.ndarray
    shear_force: np.ndarray
    sliding: np.ndarray
    friction: float
    volume: float
    n_disc: int


@dataclass(frozen=True)
class CondensedTangent:
    """Condensed tangents of B RVEs and what went into them.

    Attributes:
        tangent: C [Pa], dσ_ij/dG_kl, shape (B, 2, 2, 2, 2).
        affine: the affine term K_GG/V [Pa], same shape.
        n_contacts: touching pairs per RVE, (B,). n_sliding: of them at the Coulomb cap.
        n_left_out: rattlers and discs of fewer than two contacts left out, (B,).
        n_unknowns: translations and rotations solved for, (B,).
        seconds: wall time of assembly, factorisation and solve per RVE [s], (B,).
    """

    tangent: np.ndarray
    affine: np.ndarray
    n_contacts: np.ndarray
    n_sliding: np.ndarray
    n_left_out: np.ndarray
    n_unknowns: np.ndarray
    seconds: np.ndarray


def _stiffness(data: RVEData, ra: np.ndarray, rc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(kn, kt) [N/m] of pairs of radii ``ra``, ``rc`` [m] under the RVE's law (laws.py)."""
    law = data.meta.stiffness
    if law["law"] == "frictmat":
        kn = 2.0 * float(law["young"]) * ra * rc / (ra + rc)
        return kn, float(law["kt_over_kn"]) * kn
    return np.full(ra.shape, float(law["kn"])), np.full(ra.shape, float(law["kt"]))


def _fractional(data: RVEData, rve: int) -> np.ndarray:
    """Fractional positions s = H⁻¹x in [0, 1) of RVE ``rve``, (N, 2): the engine's own
    when the data carries them."""
    if "fractional_position" in data.extra:
        return np.asarray(data.extra["fractional_position"][rve], dtype=np.float64)
    frac = np.linalg.solve(data.cell[rve], data.position[rve].T).T
    return frac - np.floor(frac)


def contact_network(data: RVEData, rve: int = 0,
                    cap_tolerance: float = SLIDING_TOLERANCE) -> ContactNetwork:
    """The touching pairs of RVE ``rve`` of ``data`` with their forces: from the engine's
    contact lists and tangential springs when ``data`` carries them (a state written by the
    engine), else from the geometry with no tangential force. A contact slides where
    |fs| >= μ·fn·(1 − ``cap_tolerance``) (the engine's test by default)."""
    cell = np.asarray(data.cell[rve], dtype=np.float64)
    radius = np.asarray(data.radius[rve], dtype=np.float64)
    frac = _fractional(data, rve)
    if "contact_partner" in data.extra:
        partner = np.asarray(data.extra["contact_partner"][rve], dtype=np.int64)
        count = np.asarray(data.extra["contact_count"][rve], dtype=np.int64)
        shear_slots = np.asarray(data.extra["contact_shear_force"][rve], dtype=np.float64)
        used = np.arange(partner.shape[1])[None, :] < count[:, None]
        owner = np.arange(len(radius))[:, None]
        mask = used & (partner > owner)  # each pair once, from its lower index
        a, k = np.nonzero(mask)
        c = partner[a, k]
        shear = shear_slots[a, k]
    else:
        a, c, _dist2, _reach = _touching_pairs(frac, cell, radius)
        shear = np.zeros(len(a))
    ds = frac[c] - frac[a]
    ds -= np.round(ds)
    d = ds @ cell.T
    dist = np.linalg.norm(d, axis=1)
    ra, rc = radius[a], radius[c]
    touching = (ra + rc - dist > 0) & (dist > 0)
    a, c, d, dist, ra, rc, shear = (x[touching] for x in (a, c, d, dist, ra, rc, shear))
    kn, kt = _stiffness(data, ra, rc)
    fn = kn * (ra + rc - dist)
    mu = math.tan(data.meta.friction_angle)
    sliding = np.abs(shear) >= mu * fn * (1.0 - cap_tolerance)
    return ContactNetwork(
        a=a, c=c, branch=d, radius_a=ra, radius_c=rc, kn=kn, kt=kt, normal_force=fn,
        shear_force=shear, sliding=sliding, friction=mu,
        volume=float(np.linalg.det(cell)) * data.meta.thickness, n_disc=len(radius),
    )


def _kept_discs(net: ContactNetwork) -> tuple[np.ndarray, np.ndarray]:
    """Discs of at least two contacts after repeatedly leaving out those of fewer, and the
    contacts between kept discs (boolean masks (N,), (M,))."""
    kept = np.ones(net.n_disc, dtype=bool)
    alive = np.ones(len(net.a), dtype=bool)
    while True:
        degree = np.bincount(net.a[alive], minlength=net.n_disc) \
            + np.bincount(net.c[alive], minlength=net.n_disc)
        drop = kept & (degree < 2)
        if not drop.any():
            return kept, alive
        kept &= ~drop
        alive &= kept[net.a] & kept[net.c]


def _contact_matrices(net: ContactNetwork, sliding: str) -> tuple[np.ndarray, np.ndarray]:
    """Per contact: B (M, 2, 10), rows (δn, δt) over (u_a, w_a, u_c, w_c, G_00, G_01, G_10,
    G_11), and the 2 × 2 stiffness k (M, 2, 2) [N/m] mapping (δn, δt) to the generalised
    forces (−Δfn, Δfs)."""
    m = len(net.a)
    d = net.branch
    dist = np.linalg.norm(d, axis=1)
    n = d / dist[:, None]
    t = np.stack([-n[:, 1], n[:, 0]], axis=1)
    reach = net.radius_a + net.radius_c
    s = reach / dist
    b = np.zeros((m, 2, 10))
    b[:, 0, 0:2], b[:, 0, 3:5] = -n, n
    b[:, 1, 0:2], b[:, 1, 3:5] = -s[:, None] * t, s[:, None] * t
    b[:, 1, 2] = b[:, 1, 5] = -1.0
    b[:, 0, 6:] = np.einsum("mk,ml->mkl", n, d).reshape(m, 4)
    b[:, 1, 6:] = (s[:, None, None] * np.einsum("mk,ml->mkl", t, d)).reshape(m, 4) \
        - reach[:, None] * _SPIN[None, :]
    k = np.zeros((m, 2, 2))
    k[:, 0, 0] = net.kn
    k[:, 1, 1] = net.kt if sliding == "stick" else np.where(net.sliding, 0.0, net.kt)
    if sliding == "coulomb":
        k[:, 1, 0] = np.where(net.sliding, -net.friction * np.sign(net.shear_force) * net.kn,
                              0.0)
    return b, k


@dataclass(frozen=True)
class _ReducedSystem:
    """One RVE's linear system over its unknowns (see :func:`_reduced_system`)."""

    k_uu: sp.csc_matrix | None  #: K_uu, regularised [N/m], (n_free, n_free); None if empty
    k_ug: np.ndarray  #: K_uG [N/m·m], (n_free, 4)
    k_gu: np.ndarray  #: K_Gu, (4, n_free)
    affine: np.ndarray  #: K_GG of the contacts between kept discs [N·m], (4, 4)
    affine_all: np.ndarray  #: K_GG of every contact [N·m], (4, 4)
    free: np.ndarray  #: which of the 3N unknowns (u_x, u_y, w of each disc) are solved, bool
    kept: np.ndarray  #: the discs of at least two contacts, (N,), bool
    left_out: int  #: discs left out


def _reduced_system(net: ContactNetwork, sliding: str,
                    regularization: float) -> _ReducedSystem:
    """K_uu (regularised), K_uG, K_Gu and the affine terms of one RVE: the kept discs'
    translations and rotations, less one disc's translation (module docstring)."""
    kept, alive = _kept_discs(net)
    b, k = _contact_matrices(net, sliding)
    local = np.matmul(b.transpose(0, 2, 1), np.matmul(k, b))  # Bᵀ k B, (M, 10, 10)
    # the affine term of every contact; the contacts of discs left out relax fully
    affine_all = local[:, 6:, 6:].sum(axis=0)
    local = local[alive]
    affine = local[:, 6:, 6:].sum(axis=0)
    # unknowns: the kept discs' translations and rotations, less one disc's translation
    free = np.repeat(kept, 3)
    if kept.any():
        first = int(np.argmax(kept))
        free[3 * first: 3 * first + 2] = False
    n_free = int(free.sum())
    left_out = int((~kept).sum())
    if n_free == 0:
        return _ReducedSystem(None, np.zeros((0, 4)), np.zeros((4, 0)), affine, affine_all,
                              free, kept, left_out)
    number = np.where(free, np.cumsum(free) - 1, -1)  # reduced index of each unknown, or −1
    a, c = net.a[alive], net.c[alive]
    dofs = number[np.concatenate([3 * a[:, None] + np.arange(3),
                                  3 * c[:, None] + np.arange(3)], axis=1)]  # (M, 6)
    k_disc = local[:, :6, :6]
    rows = np.broadcast_to(dofs[:, :, None], k_disc.shape)
    cols = np.broadcast_to(dofs[:, None, :], k_disc.shape)
    used = (rows >= 0) & (cols >= 0)
    on_diagonal = used & (rows == cols)
    scale = float(k_disc[on_diagonal].sum()) / n_free  # mean diagonal stiffness [N/m]
    diagonal = np.arange(n_free)
    entries = np.concatenate([k_disc[used], np.full(n_free, regularization * scale)])
    k_uu = sp.csc_matrix((entries, (np.concatenate([rows[used], diagonal]),
                                    np.concatenate([cols[used], diagonal]))),
                         shape=(n_free, n_free))
    # K_uG and K_Gu, dense (n_free, 4) and (4, n_free)
    slot = dofs.ravel() + 1  # 0: no unknown (a fixed translation), dropped below

    def gather(values: np.ndarray) -> np.ndarray:
        return np.bincount(slot, weights=values.ravel(), minlength=n_free + 1)[1:]

    k_ug = np.stack([gather(local[:, :6, 6 + g]) for g in range(4)], axis=1)
    k_gu = np.stack([gather(local[:, 6 + g, :6]) for g in range(4)], axis=0)
    return _ReducedSystem(k_uu, k_ug, k_gu, affine, affine_all, free, kept, left_out)


def _condense_one(net: ContactNetwork, sliding: str,
                  regularization: float) -> tuple[np.ndarray, np.ndarray, int, int]:
    """(C, affine) [Pa] as 4 × 4 (index 2i + j) of one RVE, discs left out, unknowns."""
    system = _reduced_system(net, sliding, regularization)
    affine, affine_all, left_out = system.affine, system.affine_all, system.left_out
    if system.k_uu is None:
        return affine / net.volume, affine_all / net.volume, left_out, 0
    k_uu, k_ug, k_gu = system.k_uu, system.k_ug, system.k_gu
    n_free = k_uu.shape[0]
    if sliding in SYMMETRIC_SLIDING:  # symmetric positive definite: diagonal pivots are stable
        lu = spla.splu(k_uu, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
    else:
        lu = spla.splu(k_uu, permc_spec="MMD_AT_PLUS_A")
    x = lu.solve(k_ug)
    condensed = affine - k_gu @ x
    return condensed / net.volume, affine_all / net.volume, left_out, n_free


def _selected(n_rve: int, rves: np.ndarray | None, regularization: float) -> np.ndarray:
    """The RVE indices to condense (all ``n_rve`` for None), once ``regularization`` is
    checked."""
    if not (math.isfinite(regularization) and regularization > 0):
        raise ValueError(f"regularization must be a number > 0, got {regularization!r}")
    return np.arange(n_rve) if rves is None else np.asarray(rves, dtype=int)


def _check_sliding(sliding: str, allowed: tuple[str, ...] = SLIDING_MODES) -> None:
    """Raise ValueError unless ``sliding`` is one of ``allowed``."""
    if sliding not in allowed:
        raise ValueError(f"sliding must be one of {', '.join(allowed)}, got {sliding!r}")


def _counters(count: int) -> tuple[np.ndarray, ...]:
    """Per-RVE tallies of a condensation: contacts, sliding, left out, unknowns (int), and
    seconds (float), each shape (count,)."""
    return (*(np.zeros(count, dtype=np.int64) for _ in range(4)), np.zeros(count))


def condensed_tangent(data: RVEData, sliding: str = "free", regularization: float = 1e-9,
                      rves: np.ndarray | None = None,
                      cap_tolerance: float = SLIDING_TOLERANCE) -> CondensedTangent:
    """The condensed tangent C [Pa] (B, 2, 2, 2, 2), C_ijkl = ∂σ_ij/∂(∂u_k/∂x_l), of every
    RVE of ``data`` (or of the indices ``rves``) in its current configuration (see the
    module docstring). ``sliding``: "free" (a sliding contact has kt = 0, symmetric),
    "coulomb" (Δfs = μ·sign(fs)·Δfn) or "stick" (every touching contact keeps kt: the
    network's elastic stiffness, symmetric; see the module docstring). ``cap_tolerance``: a
    contact within this share of its Coulomb cap counts as sliding (default: the engine's
    own test, at the cap). A scipy sparse LU per RVE, on the CPU."""
    _check_sliding(sliding)
    index = _selected(data.n_rve, rves, regularization)
    count = len(index)
    tangent, affine = np.zeros((count, 4, 4)), np.zeros((count, 4, 4))
    n_contacts, n_sliding, n_left_out, n_unknowns, seconds = _counters(count)
    for slot, rve in enumerate(index):
        start = time.perf_counter()
        net = contact_network(data, int(rve), cap_tolerance)
        tangent[slot], affine[slot], n_left_out[slot], n_unknowns[slot] = _condense_one(
            net, sliding, regularization)
        seconds[slot] = time.perf_counter() - start
        n_contacts[slot], n_sliding[slot] = len(net.a), int(net.sliding.sum())
    return CondensedTangent(
        tangent=tangent.reshape(count, 2, 2, 2, 2), affine=affine.reshape(count, 2, 2, 2, 2),
        n_contacts=n_contacts, n_sliding=n_sliding, n_left_out=n_left_out,
        n_unknowns=n_unknowns, seconds=seconds,
    )
