"""Kernels of the Verlet neighbour lists: is a rebuild due, bins, the build and its commit.

A rebuild is ``begin_build`` → ``fill_bins`` → ``build_lists`` → ``commit_lists`` for the
RVEs whose ``rebuild`` flag is set; ``check_lists`` (before a run) and the end of every step
(:func:`~granular_material.dem.kernels.step.advance_cell_and_check`) set the flags.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from granular_material.dem.kernels.common import (
    STATUS_CELL_TOO_SMALL,
    STATUS_OVERFLOW,
    AnyArray,
    IntArray,
)
from granular_material.dem.kernels.laws import branch_vector, perpendicular_heights

__all__ = [
    "any_rebuild",
    "begin_build",
    "build_lists",
    "check_lists",
    "commit_lists",
    "fill_bins",
    "flag_rebuild",
    "largest_displacement",
    "link_lists",
]


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
    """max |verlet_displacement| [m] over the discs of RVE b: one root, of the largest
    square (the same value as the largest root, as sqrt is monotonic and wp.length of a
    vec2 is the root of wp.length_sq's very expression)."""
    largest = wp.length_sq(verlet_displacement[b * n_disc])
    for j in range(1, n_disc):
        largest = wp.max(largest, wp.length_sq(verlet_displacement[b * n_disc + j]))
    return wp.sqrt(largest)


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
    verlet_displacement: AnyArray, pair: AnyArray,
):
    """Per disc of a rebuilding RVE: the new list becomes current, partners linked, the
    slots' force records zeroed (a slot may now hold another pair; ``pair`` is empty
    where the step keeps no records)."""
    i = wp.tid()
    b = i // n_disc
    if rebuild[b] == 0:
        return
    count = count_new[i]
    contact_count[i] = count
    records = pair.shape[0] != 0
    for k in range(count):
        contact_partner[i * capacity + k] = partner_new[i * capacity + k]
        contact_shear_force[i * capacity + k] = shear_new[i * capacity + k]
        if records:
            pair[i * capacity + k] = type(pair[i * capacity + k])()
    # the partners' new lists are complete (build_lists ran before): link from them
    link_mirrors(i, b * n_disc, capacity, partner_new, count_new, contact_mirror_slot)
    verlet_displacement[i] = type(verlet_displacement[i])()


def link_lists(n_disc: int, capacity: int, contact_partner: IntArray,
               contact_count: IntArray, contact_mirror_slot: IntArray):
    """Per disc: ``contact_mirror_slot`` of lists uploaded from a file."""
    i = wp.tid()
    link_mirrors(i, (i // n_disc) * n_disc, capacity, contact_partner, contact_count,
               contact_mirror_slot)
