"""Kernels of the homogenised measures: per-disc halves of the contact sums, then per RVE."""

from __future__ import annotations

import warp as wp

from granular_material.dem.kernels.common import AnyArray, IntArray
from granular_material.dem.kernels.laws import (
    ContactLaw,
    branch_vector,
    contact_force,
    kruyt_rothenburg_term,
    love_term,
    pair_stiffness,
)

__all__ = ["contact_measures", "reduce_measures"]


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
