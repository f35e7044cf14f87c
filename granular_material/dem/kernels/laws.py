"""The contact physics of the disc DEM as small warp functions, generic in the float type.

Each law is a pure ``@wp.func`` used by the batched kernels of :mod:`~.kernels`: the
periodic pair geometry, the stiffness law, the Cundall–Strack force, YADE's local damping,
and the per-contact terms of Love's stress and the Kruyt–Rothenburg tangent.

A pair is always evaluated in one orientation, from disc a = min(i, j) to disc c = max(i, j):
``d = x_c − x_a`` (minimum image) and ``n = d/|d|``, ``t = perp(n)``; the force on a is
``f_a = −fn·n + fs·t`` (fn > 0 in compression).
"""

from __future__ import annotations

from typing import Any

import warp as wp

__all__ = [
    "LAW_CONSTANT",
    "LAW_FRICTMAT",
    "ContactLaw",
    "branch_vector",
    "contact_force",
    "coulomb_shear",
    "kruyt_rothenburg_term",
    "local_damping",
    "love_term",
    "min_image",
    "pair_stiffness",
    "perpendicular_heights",
    "servo_stiffness_term",
]

LAW_CONSTANT = 0  #: kn, kt constant [N/m] (Wu et al. 2025, Table 1)
LAW_FRICTMAT = 1  #: YADE FrictMat: kn = 2E·ra·rc/(ra + rc) [N/m], kt = ratio·kn


@wp.struct
class ContactLaw:
    """Stiffness law of every contact of a model (float64, cast to the kernel's float type).

    Attributes:
        law: LAW_CONSTANT or LAW_FRICTMAT.
        kn, kt: constant normal and tangential stiffness [N/m] (LAW_CONSTANT).
        young: Young's modulus E [Pa]; kt_over_kn: kt/kn [-] (LAW_FRICTMAT).
    """

    law: int
    kn: wp.float64
    kt: wp.float64
    young: wp.float64
    kt_over_kn: wp.float64


@wp.func
def min_image(ds: Any):
    """Fractional separation ``ds`` wrapped to [−½, ½)² (the nearest periodic image)."""
    return type(ds)(ds[0] - wp.round(ds[0]), ds[1] - wp.round(ds[1]))


@wp.func
def branch_vector(s_a: Any, s_c: Any, cell: Any):
    """Branch vector d = x_c − x_a [m] of the nearest images of fractional positions
    ``s_a``, ``s_c`` in the cell ``cell`` (columns = cell vectors [m])."""
    return cell * min_image(s_c - s_a)


@wp.func
def perpendicular_heights(cell: Any):
    """The cell's heights [m] perpendicular to its two cell vectors: (across s0, across s1)."""
    area = wp.determinant(cell)
    len0 = wp.sqrt(cell[0, 0] * cell[0, 0] + cell[1, 0] * cell[1, 0])
    len1 = wp.sqrt(cell[0, 1] * cell[0, 1] + cell[1, 1] * cell[1, 1])
    return area / len1, area / len0


@wp.func
def pair_stiffness(law: ContactLaw, ra: Any, rc: Any):
    """Normal and tangential stiffness (kn, kt) [N/m] of discs of radii ``ra``, ``rc`` [m]."""
    if law.law == LAW_FRICTMAT:
        kn = type(ra)(2.0) * type(ra)(law.young) * ra * rc / (ra + rc)
        return kn, type(ra)(law.kt_over_kn) * kn
    return type(ra)(law.kn), type(ra)(law.kt)


@wp.func
def coulomb_shear(shear: Any, kt: Any, slip_velocity: Any, dt: Any, mu: Any, fn: Any):
    """Cundall & Strack's tangential spring [N]: ``fs + kt·v_t·dt``, capped at μ·fn."""
    fs = shear + kt * slip_velocity * dt
    cap = mu * fn
    if wp.abs(fs) > cap:
        fs = wp.sign(fs) * cap
    return fs


@wp.func
def slip_rate(v_rel: Any, n: Any, dist: Any, ra: Any, rc: Any, w_a: Any, w_c: Any,
              spin: Any):
    """Tangential slip rate at a contact [m/s] (YADE's ScGeom with avoidGranularRatcheting,
    after McNamara et al.): the centres' relative velocity ``v_rel`` along t = perp(n),
    scaled by (ra + rc)/|d|, less the discs' spins ``w_a``, ``w_c`` and the affine ``spin``
    on full radii, so that a rigid rotation gives 0."""
    t = type(n)(-n[1], n[0])
    return (ra + rc) / dist * wp.dot(v_rel, t) - (w_a * ra + w_c * rc) - spin * (ra + rc)


@wp.func
def contact_force(fn: Any, fs: Any, n: Any):
    """Force on disc a [N]: ``−fn·n + fs·t`` with t = perp(n)."""
    return -fn * n + fs * type(n)(-n[1], n[0])


@wp.func
def love_term(force_a: Any, d: Any):
    """One partner's half of the contact's Love sum ``−f_(a→c) ⊗ d = f_a ⊗ d`` [N·m]."""
    return type(d[0])(0.5) * wp.outer(force_a, d)


@wp.func
def servo_stiffness_term(kn: Any, n: Any, d: Any):
    """One partner's half of ``kn (n_k d_k)²`` for k = x, y [N·m²]: the servo's stiffness."""
    nd_x = n[0] * d[0]
    nd_y = n[1] * d[1]
    return type(d)(type(kn)(0.5) * kn * (nd_x * nd_x), type(kn)(0.5) * kn * (nd_y * nd_y))


@wp.func
def kruyt_rothenburg_term(tangent: Any, kn: Any, kt: Any, n: Any, d: Any):
    """``tangent`` plus one partner's half of ``kn n_i d_j n_k d_l + kt t_i d_j t_k d_l``
    [N·m], stored as a 4 × 4 matrix with (i, j) → 2i + j."""
    t = type(n)(-n[1], n[0])
    half = type(kn)(0.5)
    out = tangent
    for p in range(2):
        for q in range(2):
            for r in range(2):
                for s in range(2):
                    out[2 * p + q, 2 * r + s] = out[2 * p + q, 2 * r + s] + half * (
                        kn * n[p] * d[q] * n[r] * d[s] + kt * t[p] * d[q] * t[r] * d[s]
                    )
    return out


@wp.func
def local_damping(force: Any, velocity: Any, damping: Any):
    """YADE's local non-viscous damping of one force component against its velocity."""
    one = type(force)(1.0)
    if force * velocity > type(force)(0.0):
        return force * (one - damping)
    if force * velocity < type(force)(0.0):
        return force * (one + damping)
    return force
