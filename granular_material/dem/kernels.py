"""warp kernels of the batched periodic disc DEM, generic in the float type.

Every particle array is flat, index ``i = b·N + j`` for disc j of RVE b; per-RVE arrays have
length B; per-slot arrays have length B·N·K (slot ``i·K + k`` is disc i's k-th neighbour).
Positions are fractional, ``s = H⁻¹x`` in [0, 1)², so particles follow the cell's homogeneous
deformation (YADE's homoDeform); velocities are the fluctuation about the affine field
``L·x``, and spins the fluctuation about the cell's spin ``(L₁₀ − L₀₁)/2``, so that a rigid
rotation of the cell is a rigid rotation of the packing (objectivity).

Each contact is computed once per step: the lists are full (j is in i's list iff i is in
j's, at slot ``contact_mirror_slot``), but only the lower index of a pair (its *owner*)
evaluates the force law and keeps the tangential history, writing the pair's force to both
of its slots; every disc then sums its own slots in list order (no atomics on forces,
deterministic, and the same sums in the same order as when each disc evaluated all of its
pairs).

A step is ``contact_forces`` → ``integrate`` (gather, damping, leap-frog) → optionally
``servo`` → ``advance_cell_and_check`` (cell update, and whether the next step must rebuild
the lists); a rebuild is ``begin_build`` → ``fill_bins`` → ``build_lists`` → ``commit_lists``.
Kernels are plain functions here; :func:`kernels_for` makes one warp module of them per
replica (see there), and warp specialises them to the float type of their arrays at launch.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

import warp as wp

from granular_material.dem.laws import (
    ContactLaw,
    branch_vector,
    contact_force,
    coulomb_shear,
    kruyt_rothenburg_term,
    local_damping,
    love_term,
    pair_stiffness,
    perpendicular_heights,
    servo_stiffness_term,
)

__all__ = [
    "CONTROL_STRAIN",
    "CONTROL_STRESS",
    "STATUS_BLOWUP",
    "STATUS_CELL_TOO_SMALL",
    "STATUS_COINCIDENT",
    "STATUS_OVERFLOW",
    "KernelSet",
    "kernels_for",
    "launch",
]

STATUS_BLOWUP = 1  #: a velocity became non-finite or a disc moved > r/4 in one step
STATUS_OVERFLOW = 2  #: a neighbour list exceeded its capacity
STATUS_CELL_TOO_SMALL = 4  #: contact cut-off above half a perpendicular cell height
STATUS_COINCIDENT = 8  #: two disc centres coincide

CONTROL_STRAIN = 0  #: a diagonal component driven at a prescribed strain per step
CONTROL_STRESS = 1  #: a diagonal component servo-controlled to a target stress

IntArray = wp.array(dtype=wp.int32)
AnyArray = wp.array(dtype=Any)


# -- neighbour lists ---------------------------------------------------------------------
@wp.func
def lists_stale(cell: Any, cell_at_build: Any, max_displacement: Any, skin: Any,
                cutoff: Any) -> bool:
    """Whether a disc's displacement since the build, or the cell's deformation, could close
    the Verlet skin [m] (Notes of :class:`~granular_material.dem.solver.Solver`)."""
    one = type(skin)(1.0)
    rel = cell * wp.inverse(cell_at_build)
    strain = wp.sqrt(
        (rel[0, 0] - one) * (rel[0, 0] - one) + rel[0, 1] * rel[0, 1]
        + rel[1, 0] * rel[1, 0] + (rel[1, 1] - one) * (rel[1, 1] - one)
    )
    return type(skin)(2.0) * max_displacement + strain * cutoff > skin


@wp.func
def flag_rebuild(b: int, cell: Any, max_displacement: Any, skin: Any, cutoff: Any,
                 cell_at_list_build: AnyArray, force_rebuild: IntArray, rebuild: IntArray,
                 status: IntArray):
    heights = perpendicular_heights(cell)
    if cutoff >= type(skin)(0.5) * wp.min(heights[0], heights[1]):
        wp.atomic_or(status, b, STATUS_CELL_TOO_SMALL)
    if force_rebuild[b] != 0 or lists_stale(cell, cell_at_list_build[b], max_displacement,
                                            skin, cutoff):
        rebuild[b] = 1


@wp.func
def largest_displacement(b: int, n_disc: int, verlet_displacement: AnyArray):
    """max |verlet_displacement| [m] over the discs of RVE b."""
    largest = wp.length(verlet_displacement[b * n_disc])
    for j in range(1, n_disc):
        largest = wp.max(largest, wp.length(verlet_displacement[b * n_disc + j]))
    return largest


def check_lists(
    n_disc: int, skin: Any, cutoff: Any, active: IntArray, cell: AnyArray,
    cell_at_list_build: AnyArray, verlet_displacement: AnyArray, force_rebuild: IntArray,
    rebuild: IntArray, status: IntArray,
):
    """Per RVE, before the first step of a run: must the lists be rebuilt?"""
    b = wp.tid()
    rebuild[b] = 0
    if active[b] == 0:
        return
    flag_rebuild(b, cell[b], largest_displacement(b, n_disc, verlet_displacement), skin,
                 cutoff, cell_at_list_build, force_rebuild, rebuild, status)


def any_rebuild(n_rve: int, rebuild: IntArray, any_flag: IntArray):
    """One thread: ``any_flag[0]`` = 1 if any RVE rebuilds next step (the condition of the
    captured rebuild on the CPU)."""
    flag = int(0)  # noqa: UP018, RUF046 - a mutable loop variable in warp
    for b in range(n_rve):
        flag = flag | rebuild[b]
    any_flag[0] = flag


@wp.func
def bins_per_axis(cell: Any, cutoff: Any, max_bins: int) -> wp.vec2i:
    """Bins along s0 and s1: each at least ``cutoff`` across, measured perpendicular."""
    heights = perpendicular_heights(cell)
    n0 = wp.min(int(wp.floor(heights[0] / cutoff)), max_bins)
    n1 = wp.min(int(wp.floor(heights[1] / cutoff)), max_bins)
    return wp.vec2i(wp.max(n0, 1), wp.max(n1, 1))


@wp.func
def bin_of(s: Any, nb: wp.vec2i) -> wp.vec2i:
    return wp.vec2i(wp.min(int(s[0] * type(s[0])(nb[0])), nb[0] - 1),
                    wp.min(int(s[1] * type(s[1])(nb[1])), nb[1] - 1))


def begin_build(
    max_bins: int, rebuild: IntArray, cell: AnyArray, cell_at_list_build: AnyArray,
    force_rebuild: IntArray, bin_count: IntArray,
):
    """Per RVE that rebuilds: empty its bins, remember the cell, clear the forced flag."""
    b = wp.tid()
    if rebuild[b] == 0:
        return
    for k in range(max_bins * max_bins):
        bin_count[b * max_bins * max_bins + k] = 0
    cell_at_list_build[b] = cell[b]
    force_rebuild[b] = 0


def fill_bins(
    n_disc: int, max_bins: int, bin_capacity: int, cutoff: Any, rebuild: IntArray,
    cell: AnyArray, fractional_position: AnyArray, bin_count: IntArray, bin_items: IntArray,
    status: IntArray,
):
    """Per disc of a rebuilding RVE: enter it in its bin."""
    i = wp.tid()
    b = i // n_disc
    if rebuild[b] == 0:
        return
    nb = bins_per_axis(cell[b], cutoff, max_bins)
    if nb[0] < 3 or nb[1] < 3:
        return  # small cell: the build scans all discs of the RVE
    ij = bin_of(fractional_position[i], nb)
    key = (b * max_bins + ij[1]) * max_bins + ij[0]
    slot = wp.atomic_add(bin_count, key, 1)
    if slot < bin_capacity:
        bin_items[key * bin_capacity + slot] = i - b * n_disc
    else:
        wp.atomic_or(status, b, STATUS_OVERFLOW)


@wp.func
def find_partner(partners: IntArray, count: int, first_slot: int, partner: int) -> int:
    """Flat slot of ``partner`` in the list starting at ``first_slot``, or −1."""
    found = int(-1)  # noqa: UP018, RUF046 - a mutable loop variable in warp
    for k in range(count):
        if partners[first_slot + k] == partner:
            found = first_slot + k
    return found


@wp.func
def insert_candidate(
    i: int, jj: int, base: int, cell: Any, skin: Any, capacity: int, count: int,
    fractional_position: AnyArray, radius: AnyArray, contact_partner: IntArray,
    contact_count: IntArray, contact_shear_force: AnyArray, partner_new: IntArray,
    shear_new: AnyArray,
) -> int:
    """Insert partner jj of disc i (kept sorted by jj) if within reach; returns the count.

    The tangential history comes from the pair owner's (the lower index's) old list.
    """
    j = base + jj
    if j == i:
        return count
    a = wp.min(i, j)
    c = wp.max(i, j)
    d = branch_vector(fractional_position[a], fractional_position[c], cell)
    reach = radius[i] + radius[j] + skin
    if wp.dot(d, d) >= reach * reach:
        return count
    if count < capacity:
        history = skin - skin
        old = find_partner(contact_partner, contact_count[a], a * capacity, c - base)
        if old >= 0:
            history = contact_shear_force[old]
        pos = count
        while pos > 0 and partner_new[i * capacity + pos - 1] > jj:
            partner_new[i * capacity + pos] = partner_new[i * capacity + pos - 1]
            shear_new[i * capacity + pos] = shear_new[i * capacity + pos - 1]
            pos -= 1
        partner_new[i * capacity + pos] = jj
        shear_new[i * capacity + pos] = history
    return count + 1


def build_lists(
    n_disc: int, capacity: int, max_bins: int, bin_capacity: int, skin: Any, cutoff: Any,
    rebuild: IntArray, cell: AnyArray, fractional_position: AnyArray, radius: AnyArray,
    bin_count: IntArray, bin_items: IntArray, contact_partner: IntArray,
    contact_count: IntArray, contact_shear_force: AnyArray, partner_new: IntArray,
    count_new: IntArray, shear_new: AnyArray, status: IntArray,
):
    """Per disc of a rebuilding RVE: its new list, from the 3 × 3 bins around it."""
    i = wp.tid()
    b = i // n_disc
    if rebuild[b] == 0:
        return
    base = b * n_disc
    h = cell[b]
    count = int(0)  # noqa: UP018, RUF046 - a mutable loop variable in warp
    nb = bins_per_axis(h, cutoff, max_bins)
    if nb[0] < 3 or nb[1] < 3:
        for jj in range(n_disc):
            count = insert_candidate(i, jj, base, h, skin, capacity, count,
                                     fractional_position, radius, contact_partner,
                                     contact_count, contact_shear_force, partner_new,
                                     shear_new)
    else:
        # the 3 x 3 bins around i's (distinct, as there are >= 3 bins per axis)
        ij = bin_of(fractional_position[i], nb)
        for dy in range(-1, 2):
            for dx in range(-1, 2):
                bx = (ij[0] + dx + nb[0]) % nb[0]
                by = (ij[1] + dy + nb[1]) % nb[1]
                key = (b * max_bins + by) * max_bins + bx
                for q in range(wp.min(bin_count[key], bin_capacity)):
                    count = insert_candidate(i, bin_items[key * bin_capacity + q], base, h,
                                             skin, capacity, count, fractional_position,
                                             radius, contact_partner, contact_count,
                                             contact_shear_force, partner_new, shear_new)
    if count > capacity:
        wp.atomic_or(status, b, STATUS_OVERFLOW)
        count = capacity
    count_new[i] = count


@wp.func
def link_mirrors(i: int, base: int, capacity: int, partners: IntArray, counts: IntArray,
                 mirror_slot: IntArray):
    """``mirror_slot`` of each of disc i's slots: the slot of the partner's list that holds
    i, counted from the RVE's first slot (−1 if the lists are not symmetric, which only an
    overflow makes them)."""
    for k in range(counts[i]):
        slot = i * capacity + k
        j = base + partners[slot]
        found = find_partner(partners, counts[j], j * capacity, i - base)
        if found >= 0:
            found = found - base * capacity
        mirror_slot[slot] = found


def commit_lists(
    n_disc: int, capacity: int, rebuild: IntArray, partner_new: IntArray,
    count_new: IntArray, shear_new: AnyArray, contact_partner: IntArray,
    contact_count: IntArray, contact_shear_force: AnyArray, contact_mirror_slot: IntArray,
    verlet_displacement: AnyArray,
):
    """Per disc of a rebuilding RVE: the new list becomes current; owners linked."""
    i = wp.tid()
    b = i // n_disc
    if rebuild[b] == 0:
        return
    count = count_new[i]
    contact_count[i] = count
    for k in range(count):
        contact_partner[i * capacity + k] = partner_new[i * capacity + k]
        contact_shear_force[i * capacity + k] = shear_new[i * capacity + k]
    # the partners' new lists are complete (build_lists ran before): link from them
    link_mirrors(i, b * n_disc, capacity, partner_new, count_new, contact_mirror_slot)
    verlet_displacement[i] = type(verlet_displacement[i])()


def link_lists(n_disc: int, capacity: int, contact_partner: IntArray,
               contact_count: IntArray, contact_mirror_slot: IntArray):
    """Per disc: ``contact_mirror_slot`` of lists uploaded from a file."""
    i = wp.tid()
    link_mirrors(i, (i // n_disc) * n_disc, capacity, contact_partner, contact_count,
               contact_mirror_slot)


# -- one step ----------------------------------------------------------------------------
def contact_forces(
    n_disc: int, capacity: int, law: ContactLaw, timestep: AnyArray, active: IntArray,
    friction: AnyArray, cell: AnyArray, velocity_gradient: AnyArray,
    fractional_position: AnyArray, velocity: AnyArray, angular_velocity: AnyArray,
    radius: AnyArray, contact_partner: IntArray, contact_count: IntArray,
    contact_mirror_slot: IntArray, contact_shear_force: AnyArray, with_stress: int,
    pair: AnyArray, pair_branch: AnyArray, status: IntArray,
):
    """Per disc: the Cundall–Strack force of every pair it owns (partner of higher index),
    written as ``pair = (f, τ)`` to both slots of the pair: the force [N] on that slot's
    disc and its torque [N·m] (zero where the discs do not touch); with ``with_stress`` also
    the branch vector d = x_c − x_a of touching pairs (zero for the others)."""
    i = wp.tid()
    b = i // n_disc
    if active[b] == 0:
        return
    base = b * n_disc
    h = cell[b]
    lg = velocity_gradient[b]
    mu = friction[b]
    dt = timestep[b]
    zero = dt - dt
    # affine spin w = (L10 - L01)/2 of every disc
    spin = type(dt)(0.5) * (lg[1, 0] - lg[0, 1])
    ra = radius[i]
    for k in range(contact_count[i]):
        slot = i * capacity + k
        c = base + contact_partner[slot]
        if c <= i:
            continue
        d = branch_vector(fractional_position[i], fractional_position[c], h)
        rc = radius[c]
        mirror = base * capacity + wp.max(contact_mirror_slot[slot], 0)
        pair[slot] = type(pair[slot])()
        pair[mirror] = type(pair[slot])()
        if with_stress != 0:
            pair_branch[slot] = type(d)()
            pair_branch[mirror] = type(d)()
        if wp.dot(d, d) >= (ra + rc) * (ra + rc) * type(dt)(1.000001):
            contact_shear_force[slot] = zero  # clearly apart (decided without a root)
            continue
        dist = wp.length(d)
        overlap = ra + rc - dist
        if overlap <= zero:
            contact_shear_force[slot] = zero
            continue
        if dist <= type(dt)(1.0e-12) * (ra + rc):
            wp.atomic_or(status, b, STATUS_COINCIDENT)
            continue
        n = d / dist
        t = type(n)(-n[1], n[0])
        kn, kt = pair_stiffness(law, ra, rc)
        v_rel = velocity[c] - velocity[i] + lg * d
        v_t = wp.dot(v_rel, t) - (angular_velocity[i] * ra + angular_velocity[c] * rc) \
            - spin * (ra + rc)
        fn = kn * overlap
        fs = coulomb_shear(contact_shear_force[slot], kt, v_t, dt, mu, fn)
        contact_shear_force[slot] = fs
        f_a = contact_force(fn, fs, n)
        half = type(dt)(0.5)
        pair[slot] = type(pair[slot])(f_a[0], f_a[1], (ra - half * overlap) * fs)
        pair[mirror] = type(pair[slot])(-f_a[0], -f_a[1], (rc - half * overlap) * fs)
        if with_stress != 0:
            pair_branch[slot] = d
            pair_branch[mirror] = d


def integrate(
    n_disc: int, capacity: int, law: ContactLaw, damping: Any, with_stress: int,
    timestep: AnyArray, active: IntArray, cell: AnyArray, radius: AnyArray,
    inv_mass: AnyArray, inv_inertia: AnyArray, contact_partner: IntArray,
    contact_count: IntArray, pair: AnyArray, pair_branch: AnyArray,
    fractional_position: AnyArray, velocity: AnyArray, angular_velocity: AnyArray,
    verlet_displacement: AnyArray, part_stress: AnyArray, part_stiffness: AnyArray,
    status: IntArray,
):
    """Per disc: gather its contact forces in list order, damp, leap-frog; with
    ``with_stress`` also its halves of the Love sum and of the servo's stiffness."""
    i = wp.tid()
    b = i // n_disc
    if active[b] == 0:
        return
    dt = timestep[b]
    zero = dt - dt
    ri = radius[i]
    f = type(velocity[i])()
    tq = zero
    s_sum = type(cell[b])()
    k_sum = type(velocity[i])()
    # a separated pair's record is zero, so it adds exact zeros: the sums are those of the
    # touching pairs, in list order
    for k in range(contact_count[i]):
        slot = i * capacity + k
        record = pair[slot]
        f_i = type(f)(record[0], record[1])
        f = f + f_i
        tq = tq + record[2]
        if with_stress != 0:
            d = pair_branch[slot]
            if d[0] != zero or d[1] != zero:
                j = b * n_disc + contact_partner[slot]
                kn, _kt = pair_stiffness(law, radius[wp.min(i, j)], radius[wp.max(i, j)])
                # Love's term takes the force on the pair's lower index
                f_a = f_i
                if j < i:
                    f_a = -f_i
                s_sum = s_sum + love_term(f_a, d)
                k_sum = k_sum + servo_stiffness_term(kn, d / wp.length(d), d)
    if with_stress != 0:
        part_stress[i] = s_sum
        part_stiffness[i] = k_sum
    v = velocity[i]
    f = type(v)(local_damping(f[0], v[0], damping), local_damping(f[1], v[1], damping))
    w = angular_velocity[i]
    tq = local_damping(tq, w, damping)
    v = v + dt * inv_mass[i] * f
    w = w + dt * inv_inertia[i] * tq
    dx = dt * v
    if not (wp.isfinite(v) and wp.isfinite(w)) or wp.length(dx) > type(dt)(0.25) * ri:
        wp.atomic_or(status, b, STATUS_BLOWUP)
        return
    velocity[i] = v
    angular_velocity[i] = w
    verlet_displacement[i] = verlet_displacement[i] + dx
    s = fractional_position[i] + wp.inverse(cell[b]) * dx
    fractional_position[i] = type(s)(s[0] - wp.floor(s[0]), s[1] - wp.floor(s[1]))


def servo(
    n_disc: int, thickness: Any, gain: Any, max_strain: Any, timestep: AnyArray,
    active: IntArray, cell: AnyArray, part_stress: AnyArray, part_stiffness: AnyArray,
    control: IntArray, target: AnyArray, velocity_gradient: AnyArray, step_map: AnyArray,
):
    """Per RVE: the strain increment of xx and yy for the next step, stress- or
    strain-controlled (``control``), as the velocity gradient and the cell's step map."""
    b = wp.tid()
    if active[b] == 0:
        return
    dt = timestep[b]
    zero = dt - dt
    one = type(dt)(1.0)
    volume = wp.determinant(cell[b]) * thickness
    s_sum = type(cell[b])()
    k_sum = type(target[b])()
    for j in range(n_disc):
        s_sum = s_sum + part_stress[b * n_disc + j]
        k_sum = k_sum + part_stiffness[b * n_disc + j]
    sigma = s_sum / volume
    goal = target[b]
    de = type(goal)()
    for k in range(2):
        if control[2 * b + k] == CONTROL_STRESS:
            modulus = wp.max(k_sum[k] / volume, type(dt)(1.0e-30))
            step = gain * (goal[k] - sigma[k, k]) / modulus
            de[k] = wp.clamp(step, -max_strain, max_strain)
        else:
            de[k] = goal[k]
    velocity_gradient[b] = type(cell[b])(de[0] / dt, zero, zero, de[1] / dt)
    step_map[b] = type(cell[b])(one + de[0], zero, zero, one + de[1])


def advance_cell_and_check(
    n_disc: int, skin: Any, cutoff: Any, active: IntArray, step_map: AnyArray,
    cell: AnyArray, cell_at_list_build: AnyArray, verlet_displacement: AnyArray,
    force_rebuild: IntArray, rebuild: IntArray, status: IntArray,
):
    """Per RVE, the end of a step: ``H ← E·H``, then whether the next step must rebuild."""
    b = wp.tid()
    rebuild[b] = 0
    if active[b] == 0:
        return
    h = step_map[b] * cell[b]
    cell[b] = h
    flag_rebuild(b, h, largest_displacement(b, n_disc, verlet_displacement), skin, cutoff,
                 cell_at_list_build, force_rebuild, rebuild, status)


# -- measures ----------------------------------------------------------------------------
def contact_measures(
    n_disc: int, capacity: int, law: ContactLaw, friction: AnyArray, cell: AnyArray,
    fractional_position: AnyArray, radius: AnyArray, contact_partner: IntArray,
    contact_count: IntArray, contact_mirror_slot: IntArray, contact_shear_force: AnyArray,
    part_stress: AnyArray, part_tangent: AnyArray, part_fabric: AnyArray,
    part_counts: AnyArray, part_forces: AnyArray,
):
    """Per disc: its halves of the contact sums of Love stress, KR tangent and fabric."""
    i = wp.tid()
    b = i // n_disc
    base = b * n_disc
    h = cell[b]
    mu = friction[b]
    zero = mu - mu
    half = type(mu)(0.5)
    s_sum = type(h)()
    fab = type(h)()
    tan = type(part_tangent[i])()
    n_contacts = zero
    n_sliding = zero
    f_net = type(fractional_position[i])()
    f_abs = zero
    for k in range(contact_count[i]):
        slot = i * capacity + k
        j = base + contact_partner[slot]
        owner = slot
        if j < i:
            owner = base * capacity + contact_mirror_slot[slot]
            if contact_mirror_slot[slot] < 0:
                continue
        a = wp.min(i, j)
        c = wp.max(i, j)
        d = branch_vector(fractional_position[a], fractional_position[c], h)
        dist = wp.length(d)
        ra = radius[a]
        rc = radius[c]
        overlap = ra + rc - dist
        if overlap <= zero or dist <= zero:
            continue
        n = d / dist
        kn, kt = pair_stiffness(law, ra, rc)
        fn = kn * overlap
        fs = contact_shear_force[owner]
        f_a = contact_force(fn, fs, n)
        if i == a:
            f_net = f_net + f_a
        else:
            f_net = f_net - f_a
        s_sum = s_sum + love_term(f_a, d)
        fab = fab + half * wp.outer(n, n)
        n_contacts = n_contacts + half
        if wp.abs(fs) >= mu * fn * type(mu)(1.0 - 1.0e-9):
            n_sliding = n_sliding + half
        f_abs = f_abs + half * wp.length(f_a)
        tan = kruyt_rothenburg_term(tan, kn, kt, n, d)
    part_stress[i] = s_sum
    part_tangent[i] = tan
    part_fabric[i] = fab
    part_counts[i] = type(f_net)(n_contacts, n_sliding)
    part_forces[i] = type(f_net)(wp.length(f_net), f_abs)


def reduce_measures(
    n_disc: int, part_stress: AnyArray, part_tangent: AnyArray, part_fabric: AnyArray,
    part_counts: AnyArray, part_forces: AnyArray, stress: AnyArray, tangent: AnyArray,
    fabric: AnyArray, counts: AnyArray, forces: AnyArray,
):
    """Per RVE: the sums of the per-disc halves, in disc order."""
    b = wp.tid()
    s_sum = type(stress[b])()
    f_sum = type(fabric[b])()
    t_sum = type(tangent[b])()
    c_sum = type(counts[b])()
    g_sum = type(forces[b])()
    for j in range(n_disc):
        i = b * n_disc + j
        s_sum = s_sum + part_stress[i]
        t_sum = t_sum + part_tangent[i]
        f_sum = f_sum + part_fabric[i]
        c_sum = c_sum + part_counts[i]
        g_sum = g_sum + part_forces[i]
    stress[b] = s_sum
    tangent[b] = t_sum
    fabric[b] = f_sum
    counts[b] = c_sum
    forces[b] = g_sum


_KERNELS = (
    check_lists, any_rebuild, begin_build, fill_bins, build_lists, commit_lists, link_lists,
    contact_forces, integrate, servo, advance_cell_and_check, contact_measures,
    reduce_measures,
)


@dataclass(frozen=True)
class KernelSet:
    """The kernels of one warp module (one replica); attributes named as the functions."""

    check_lists: wp.Kernel
    any_rebuild: wp.Kernel
    begin_build: wp.Kernel
    fill_bins: wp.Kernel
    build_lists: wp.Kernel
    commit_lists: wp.Kernel
    link_lists: wp.Kernel
    contact_forces: wp.Kernel
    integrate: wp.Kernel
    servo: wp.Kernel
    advance_cell_and_check: wp.Kernel
    contact_measures: wp.Kernel
    reduce_measures: wp.Kernel


#: what each generic argument of the kernels holds: a scalar, vec2, vec3, mat22 or mat44 of the
#: float type (scalar arguments are passed in the float type; arrays hold these dtypes)
_ROLES = {
    "scalar": ("skin", "cutoff", "damping", "thickness", "gain", "max_strain", "timestep",
               "friction", "radius", "inv_mass", "inv_inertia", "angular_velocity",
               "contact_shear_force", "shear_new"),
    "vec2": ("fractional_position", "velocity", "verlet_displacement", "pair_branch",
             "part_stiffness", "target", "part_counts", "part_forces",
             "counts", "forces"),
    "mat22": ("cell", "cell_at_list_build", "velocity_gradient", "step_map", "part_stress",
              "part_fabric", "stress", "fabric"),
    "vec3": ("pair",),
    "mat44": ("part_tangent", "tangent"),
}


def _concrete_types(kernel: wp.Kernel, ft: Any) -> dict[str, Any]:
    """The concrete type of every generic argument of ``kernel`` for float type ``ft``."""
    dtypes = {"scalar": ft, "vec2": wp.types.vector(2, ft), "vec3": wp.types.vector(3, ft),
              "mat22": wp.types.matrix((2, 2), ft), "mat44": wp.types.matrix((4, 4), ft)}
    role_of = {name: role for role, names in _ROLES.items() for name in names}
    types = {}
    for arg in kernel.adj.args:
        is_array = wp.types.is_array(arg.type)
        if (arg.type.dtype if is_array else arg.type) is not Any:
            continue
        dtype = dtypes[role_of[arg.label]]
        types[arg.label] = wp.array(dtype=dtype) if is_array else dtype
    return types


@cache
def kernels_for(dtype: str = "float64", replica: int = 0) -> KernelSet:
    """The kernels for ``dtype`` ("float64" or "float32") as warp module ``replica``, each
    specialised to the float type before the module is first built (so it builds once).

    On x86-64 a CPU module keeps a static pointer to the running launch's tile storage, so
    two threads must never run kernels of the same module at once: every CPU shard steps
    with its own replica.
    """
    ft = {"float64": wp.float64, "float32": wp.float32}[dtype]
    module = f"granular_material_dem_{dtype}_r{replica}"
    kernels = {}
    for function in _KERNELS:
        kernel = wp.kernel(function, module=module, enable_backward=False)
        types = _concrete_types(kernel, ft)
        if types:
            wp.overload(kernel, types)
        kernels[function.__name__] = kernel
    return KernelSet(**kernels)


def launch(kernel: wp.Kernel, dim: int, device: str, record: bool = False,
           **arguments: Any) -> wp.Launch | None:
    """Launch ``kernel`` with its arguments by name (all of them, no others); with
    ``record`` return the recorded launch instead, to be replayed by ``.launch()``."""
    names = [arg.label for arg in kernel.adj.args]
    if set(names) != set(arguments):
        missing = sorted(set(names) - set(arguments))
        unknown = sorted(set(arguments) - set(names))
        raise TypeError(f"{kernel.key}: missing arguments {missing}, unknown {unknown}")
    return wp.launch(kernel, dim=dim, inputs=[arguments[n] for n in names], device=device,
                     record_cmd=record)
