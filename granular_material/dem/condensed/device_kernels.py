"""The warp kernels that assemble the condensed tangent's systems on a batch's own device
(issue 26), from the engine's arrays (fractional positions, cell, radii, neighbour slots,
tangential springs and their mirror slots), in launch order:

- ``slot_contacts`` (one thread a slot): which slots touch, the pair's branch and
  stiffnesses, and whether it slides (the engine's test on the spring its owner keeps);
- ``drop_weak_discs`` (one thread a disc, repeated until nothing changes): the discs of
  fewer than two contacts among the kept ones are left out, as ``condensed._kept_discs``,
  and ``first_kept_disc`` (one thread an RVE) finds the disc whose translation is fixed;
- ``assemble_rows`` (one thread a disc): its row of 3 × 3 blocks, the diagonal and one per
  contact with a kept disc, packed into the disc's ``capacity + 1`` places (the CG reads a
  row up to its ``row_end``), its K_uG columns and K_Gu rows;
- ``rve_sums`` (one thread an RVE): the regularisation's scale, K_GG and the counters;
- ``regularize`` (one thread a disc): the regularisation and the inverse diagonal blocks.

Every disc keeps its three unknowns: a disc left out and each RVE's fixed translation (its
first kept disc's) are identity rows with no load, whose solution is zero, the same as
leaving them out. The contact kinematics are ``condensed._contact_matrices``' (``sliding=
"free"`` or ``"stick"``), written per slot from the slot owner's side (δn and δt are the
same from either side of a pair). float64 only; launched by
:func:`~granular_material.dem.condensed.device.condensed_tangent_on_device`."""

from __future__ import annotations

import warp as wp

from granular_material.dem.kernels.laws import ContactLaw, branch_vector, pair_stiffness

__all__ = [
    "MODULE",
    "Network",
    "assemble_rows",
    "drop_weak_discs",
    "first_kept_disc",
    "kernel_modules",
    "regularize",
    "rve_sums",
    "slot_contacts",
]

MODULE = "granular_material_dem_condensed_device"  #: the warp module of the kernels below

vec2 = wp.vec2d
vec3 = wp.vec3d
vec4 = wp.vec4d
mat22 = wp.mat22d
mat33 = wp.mat33d
mat44 = wp.mat44d


@wp.struct
class Network:
    """What the assembly reads of a shard's contacts, per slot (B·N·K) or disc (B·N)."""

    partner: wp.array(dtype=wp.int32)  # the partner's index within its RVE, per slot
    count: wp.array(dtype=wp.int32)  # used slots, per disc
    radius: wp.array(dtype=wp.float64)  # [m], per disc
    touching: wp.array(dtype=wp.int32)  # 1 where the slot's pair overlaps
    sliding: wp.array(dtype=wp.int32)  # 1 where it slides (the engine's test)
    branch: wp.array(dtype=vec2)  # x_partner − x_owner, minimum image [m]
    kn: wp.array(dtype=wp.float64)  # [N/m]
    kt: wp.array(dtype=wp.float64)  # [N/m], 0 where the pair slides
    kept: wp.array(dtype=wp.int32)  # 1 for a disc of at least two contacts (after dropping)


@wp.kernel(enable_backward=False, module=MODULE)
def slot_contacts(n_disc: int, capacity: int, selected: wp.array(dtype=wp.int32),
                  fractional: wp.array(dtype=vec2), cell: wp.array(dtype=mat22),
                  radius: wp.array(dtype=wp.float64), partner: wp.array(dtype=wp.int32),
                  count: wp.array(dtype=wp.int32), shear: wp.array(dtype=wp.float64),
                  mirror: wp.array(dtype=wp.int32), law: ContactLaw, mu: wp.float64,
                  cap_tolerance: wp.float64, free_slip: wp.int32,
                  touching: wp.array(dtype=wp.int32), sliding: wp.array(dtype=wp.int32),
                  branch: wp.array(dtype=vec2), kn: wp.array(dtype=wp.float64),
                  kt: wp.array(dtype=wp.float64)):
    """Per slot: does its pair touch (overlap > 0), its branch d = x_partner − x_owner
    (minimum image) [m], kn and kt [N/m] (kt = 0 where the pair slides and ``free_slip``
    is 1: ``sliding="free"``; kt kept with 0: ``"stick"``)."""
    slot = wp.tid()
    disc = slot // capacity
    rve = disc // n_disc
    touching[slot] = 0
    sliding[slot] = 0
    if selected[rve] == 0 or slot - disc * capacity >= count[disc]:
        return
    local = partner[slot]
    other = rve * n_disc + local
    d = branch_vector(fractional[disc], fractional[other], cell[rve])
    dist = wp.length(d)
    ra = radius[disc]
    rc = radius[other]
    overlap = ra + rc - dist
    if not (overlap > wp.float64(0.0) and dist > wp.float64(0.0)):
        return
    k_n, k_t = pair_stiffness(law, ra, rc)
    # the pair's spring as its owner (the lower index) keeps it
    fs = shear[slot]
    if local < disc - rve * n_disc and mirror[slot] >= 0:
        fs = shear[rve * n_disc * capacity + mirror[slot]]
    slides = wp.abs(fs) >= mu * k_n * overlap * (wp.float64(1.0) - cap_tolerance)
    touching[slot] = 1
    branch[slot] = d
    kn[slot] = k_n
    kt[slot] = k_t
    if slides:
        sliding[slot] = 1
        if free_slip == 1:
            kt[slot] = wp.float64(0.0)


@wp.kernel(enable_backward=False, module=MODULE)
def drop_weak_discs(n_disc: int, capacity: int, partner: wp.array(dtype=wp.int32),
                    count: wp.array(dtype=wp.int32), touching: wp.array(dtype=wp.int32),
                    kept: wp.array(dtype=wp.int32), kept_next: wp.array(dtype=wp.int32),
                    changed: wp.array(dtype=wp.int32)):
    """One pass of leaving out the discs of fewer than two contacts among the kept discs."""
    disc = wp.tid()
    kept_next[disc] = 0
    if kept[disc] == 0:
        return
    first = (disc // n_disc) * n_disc
    degree = int(0)  # noqa: UP018, RUF046 - a mutable loop variable in warp
    for j in range(count[disc]):
        slot = disc * capacity + j
        if touching[slot] != 0 and kept[first + partner[slot]] != 0:
            degree += 1
    if degree >= 2:
        kept_next[disc] = 1
    else:
        changed[0] = 1


@wp.func
def _contact_rows(d: vec2, ra_rc: wp.float64, dist: wp.float64):
    """(n, s·t, G-part of δn, G-part of δt) of a pair with branch d, radii sum ra_rc."""
    n = d / dist
    t = vec2(-n[1], n[0])
    s = ra_rc / dist
    g_n = vec4(n[0] * d[0], n[0] * d[1], n[1] * d[0], n[1] * d[1])
    # δt: s·t⊗d less (r_a + r_c)·ω(G), ω = (G_10 − G_01)/2
    g_t = vec4(s * t[0] * d[0], s * t[0] * d[1] + wp.float64(0.5) * ra_rc,
               s * t[1] * d[0] - wp.float64(0.5) * ra_rc, s * t[1] * d[1])
    return n, s * t, g_n, g_t


@wp.kernel(enable_backward=False, module=MODULE)
def assemble_rows(n_disc: int, capacity: int, net: Network,
                  first_kept: wp.array(dtype=wp.int32), row_end: wp.array(dtype=wp.int32),
                  block_disc: wp.array(dtype=wp.int32), block_value: wp.array(dtype=mat33),
                  rhs: wp.array(dtype=vec3), load: wp.array(dtype=vec3),
                  diagonal_stiffness: wp.array(dtype=vec3)):
    """Disc k's row of blocks (the diagonal first, then one per contact with a kept disc,
    up to ``row_end[k]`` in its ``capacity + 1`` places), its K_uG columns (G_00, sym G_01,
    G_11) and its K_Gu rows, unregularised; identity rows where an unknown is not solved (a
    disc left out, the RVE's fixed translation)."""
    disc = wp.tid()
    n_total = first_kept.shape[0] * n_disc
    rve = disc // n_disc
    base = disc * (capacity + 1)
    identity = mat33(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    block_disc[base] = disc
    row_end[disc] = base + 1
    if net.kept[disc] == 0:
        block_value[base] = identity
        for c in range(3):
            rhs[c * n_total + disc] = vec3()
        for g in range(4):
            load[g * n_total + disc] = vec3()
        diagonal_stiffness[disc] = vec3()
        return
    fixed_rve_disc = rve * n_disc + first_kept[rve]
    own_free = vec3(1.0, 1.0, 1.0)
    if disc == fixed_rve_disc:
        own_free = vec3(0.0, 0.0, 1.0)
    diag = mat33()
    col0 = vec3()
    col1 = vec3()
    col2 = vec3()
    row0 = vec3()
    row1 = vec3()
    row2 = vec3()
    row3 = vec3()
    used = int(0)  # noqa: UP018, RUF046 - a mutable loop variable in warp
    for j in range(net.count[disc]):
        slot = disc * capacity + j
        other = rve * n_disc + net.partner[slot]
        if net.touching[slot] != 0 and net.kept[other] != 0:
            d = net.branch[slot]
            dist = wp.length(d)
            n, st, g_n, g_t = _contact_rows(d, net.radius[disc] + net.radius[other], dist)
            k_n = net.kn[slot]
            k_t = net.kt[slot]
            # this disc's rows of B (δn, δt over u_x, u_y, w) and the partner's
            a_n = vec3(-n[0], -n[1], 0.0)
            a_t = vec3(-st[0], -st[1], -1.0)
            c_n = vec3(n[0], n[1], 0.0)
            c_t = vec3(st[0], st[1], -1.0)
            diag += k_n * wp.outer(a_n, a_n) + k_t * wp.outer(a_t, a_t)
            off = k_n * wp.outer(a_n, c_n) + k_t * wp.outer(a_t, c_t)
            other_free = vec3(1.0, 1.0, 1.0)
            if other == fixed_rve_disc:
                other_free = vec3(0.0, 0.0, 1.0)
            used += 1
            block_value[base + used] = wp.diag(own_free) * off * wp.diag(other_free)
            block_disc[base + used] = other
            col0 += k_n * g_n[0] * a_n + k_t * g_t[0] * a_t
            col1 += wp.float64(0.5) * (k_n * (g_n[1] + g_n[2]) * a_n
                                       + k_t * (g_t[1] + g_t[2]) * a_t)
            col2 += k_n * g_n[3] * a_n + k_t * g_t[3] * a_t
            row0 += k_n * g_n[0] * a_n + k_t * g_t[0] * a_t
            row1 += k_n * g_n[1] * a_n + k_t * g_t[1] * a_t
            row2 += k_n * g_n[2] * a_n + k_t * g_t[2] * a_t
            row3 += k_n * g_n[3] * a_n + k_t * g_t[3] * a_t
    row_end[disc] = base + 1 + used
    mask = wp.diag(own_free)
    diag = mask * diag * mask
    diagonal_stiffness[disc] = vec3(diag[0, 0], diag[1, 1], diag[2, 2])
    block_value[base] = diag + wp.diag(vec3(1.0, 1.0, 1.0) - own_free)
    rhs[disc] = wp.cw_mul(own_free, col0)
    rhs[n_total + disc] = wp.cw_mul(own_free, col1)
    rhs[2 * n_total + disc] = wp.cw_mul(own_free, col2)
    load[disc] = wp.cw_mul(own_free, row0)
    load[n_total + disc] = wp.cw_mul(own_free, row1)
    load[2 * n_total + disc] = wp.cw_mul(own_free, row2)
    load[3 * n_total + disc] = wp.cw_mul(own_free, row3)


@wp.kernel(enable_backward=False, module=MODULE)
def first_kept_disc(n_disc: int, kept: wp.array(dtype=wp.int32),
                    first_kept: wp.array(dtype=wp.int32)):
    """Each RVE's first kept disc (within the RVE), 0 where none is kept."""
    rve = wp.tid()
    first_kept[rve] = 0
    for i in range(n_disc):
        if kept[rve * n_disc + i] != 0:
            first_kept[rve] = i
            return


@wp.kernel(enable_backward=False, module=MODULE)
def rve_sums(n_disc: int, capacity: int, net: Network,
             diagonal_stiffness: wp.array(dtype=vec3), scale: wp.array(dtype=wp.float64),
             affine: wp.array(dtype=mat44), affine_all: wp.array(dtype=mat44),
             counters: wp.array(dtype=wp.int32)):
    """Per RVE: the mean diagonal stiffness of its solved unknowns [N/m], K_GG of the
    contacts between kept discs and of every contact [N·m] (each pair from its owner's
    slot), and (contacts, sliding, left out, unknowns)."""
    rve = wp.tid()
    first = rve * n_disc
    total = wp.float64(0.0)
    n_kept = int(0)  # noqa: UP018, RUF046 - a mutable loop variable in warp
    n_contacts = int(0)  # noqa: UP018, RUF046 - a mutable loop variable in warp
    n_sliding = int(0)  # noqa: UP018, RUF046 - a mutable loop variable in warp
    k_gg = mat44()
    k_gg_all = mat44()
    for i in range(n_disc):
        disc = first + i
        if net.kept[disc] != 0:
            n_kept += 1
            v = diagonal_stiffness[disc]
            total += v[0] + v[1] + v[2]
        for j in range(net.count[disc]):
            slot = disc * capacity + j
            local = net.partner[slot]
            if net.touching[slot] != 0 and local > i:
                other = first + local
                n_contacts += 1
                n_sliding += net.sliding[slot]
                d = net.branch[slot]
                _n, _st, g_n, g_t = _contact_rows(d, net.radius[disc] + net.radius[other],
                                                  wp.length(d))
                term = net.kn[slot] * wp.outer(g_n, g_n) + net.kt[slot] * wp.outer(g_t, g_t)
                k_gg_all += term
                if net.kept[disc] != 0 and net.kept[other] != 0:
                    k_gg += term
    n_free = int(0)  # noqa: UP018, RUF046 - a mutable loop variable in warp
    if n_kept > 0:
        n_free = 3 * n_kept - 2
    scale[rve] = total / wp.float64(wp.max(n_free, 1))
    affine[rve] = k_gg
    affine_all[rve] = k_gg_all
    counters[4 * rve] = n_contacts
    counters[4 * rve + 1] = n_sliding
    counters[4 * rve + 2] = n_disc - n_kept
    counters[4 * rve + 3] = n_free


@wp.kernel(enable_backward=False, module=MODULE)
def regularize(n_disc: int, capacity: int, regularization: wp.float64,
               first_kept: wp.array(dtype=wp.int32), kept: wp.array(dtype=wp.int32),
               scale: wp.array(dtype=wp.float64), block_value: wp.array(dtype=mat33),
               inverse_diagonal: wp.array(dtype=mat33)):
    """``regularization`` × the RVE's mean diagonal stiffness on every solved unknown of
    disc k, and the inverse of its diagonal block."""
    disc = wp.tid()
    rve = disc // n_disc
    base = disc * (capacity + 1)
    block = block_value[base]
    if kept[disc] != 0:
        shift = regularization * scale[rve]
        if disc == rve * n_disc + first_kept[rve]:
            block += wp.diag(vec3(0.0, 0.0, shift))
        else:
            block += wp.diag(vec3(shift, shift, shift))
        block_value[base] = block
    inverse_diagonal[disc] = wp.inverse(block)


def kernel_modules() -> dict[str, wp.Module]:
    """The warp module of this file by name (for an ahead-of-time compile)."""
    return {MODULE: slot_contacts.module}
