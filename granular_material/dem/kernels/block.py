"""The step of one RVE per thread block: many DEM steps in one launch (CUDA's block path).

``step_block`` is launched tiled, one block of ``BLOCK_THREADS`` threads per RVE (on the CPU
one thread, unless ``warp.config.enable_cpu_blocks``). The block steps its RVE up to its
``steps_left`` steps, each step the rules of the two-kernel step and the stages after it:

1. the discs' fractional positions, velocities and spins are loaded into shared memory
   (tiles of ``BLOCK_DISCS`` entries, read there by every pair that needs them);
2. each thread, for its discs ``j = lane, lane + T, …``, the force of every pair the disc
   owns, written to both slots' records as ``contact_forces`` does (same law functions,
   same arithmetic); a barrier;
3. each thread gathers its discs' records in list order, damps and leap-frogs them as
   ``integrate`` does, and adds their halves of the Love and servo-stiffness sums;
4. block reductions: the largest Verlet displacement (a maximum, exact) and, under the
   servo, the sums of the stress and stiffness (their order is the block's, not the disc
   order of ``servo``: equal to rounding); every thread then computes the same servo
   strain, the cell update ``H ← E·H`` and the test of the skin;
5. where the lists may have gone stale (or an error bit was set) the RVE stops there: its
   ``rebuild`` flag is set and the launch returns with ``steps_left`` counting what is
   left; the host rebuilds those RVEs' lists (the build kernels, unchanged) and launches
   again until no RVE has steps left (:func:`block_pending`).

So every per-step rule of the existing path holds, list rebuilds included: the steps of one
launch are bounded by the skin, as the existing path's test at the end of each step bounds
them. With one thread a block (the CPU) the sums come out in the existing path's order and
the results are its own bit for bit; with more threads only the servo's sums differ, in
rounding.

The pairs' records stay in global memory (``pair``, ``pair_branch``: 40 B a slot in float64,
up to 256 kB for 400 discs of 16 slots, beyond a multiprocessor's shared memory), served by
the L1 and L2 caches.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from granular_material.dem.kernels.common import (
    CONTROL_STRESS,
    STATUS_BLOWUP,
    STATUS_CELL_TOO_SMALL,
    STATUS_COINCIDENT,
    AnyArray,
    IntArray,
)
from granular_material.dem.kernels.laws import (
    ContactLaw,
    branch_vector,
    contact_force,
    coulomb_shear,
    local_damping,
    love_term,
    pair_stiffness,
    perpendicular_heights,
    servo_stiffness_term,
    slip_rate,
)
from granular_material.dem.kernels.lists import lists_stale
from granular_material.dem.kernels.step import clear_pair

__all__ = ["BLOCK_DISCS", "BLOCK_THREADS", "block_pending", "step_block"]

#: discs of an RVE that the block path holds in shared memory (the tiles' length, fixed at
#: compile time): 20 kB of positions, velocities and spins in float64
BLOCK_DISCS = 512
#: threads of a block (one block per RVE): about 3 discs a thread for 400 discs
BLOCK_THREADS = 128


def step_block(
    n_disc: int, capacity: int, law: ContactLaw, damping: Any, servo_on: int,
    thickness: Any, gain: Any, max_strain: Any, skin: Any, cutoff: Any,
    timestep: AnyArray, active: IntArray, friction: AnyArray, radius: AnyArray,
    inv_mass: AnyArray, inv_inertia: AnyArray, contact_partner: IntArray,
    contact_count: IntArray, contact_mirror_slot: IntArray, contact_shear_force: AnyArray,
    control: IntArray, target: AnyArray, velocity_gradient: AnyArray, step_map: AnyArray,
    cell: AnyArray, cell_at_list_build: AnyArray, force_rebuild: IntArray,
    fractional_position: AnyArray, velocity: AnyArray, angular_velocity: AnyArray,
    verlet_displacement: AnyArray, pair: AnyArray, pair_branch: AnyArray,
    steps_left: IntArray, rebuild: IntArray, status: IntArray,
):
    """Per RVE (a block): up to ``steps_left[b]`` steps, stopping after a step where the
    lists may have gone stale (``rebuild[b]`` set) or an error bit was set; the force law,
    integration, servo (``servo_on``) and cell update of the two-kernel step."""
    b, lane = wp.tid()
    if active[b] == 0:
        if lane == 0:
            steps_left[b] = 0
        return
    left = steps_left[b]
    if left <= 0:
        return
    threads = wp.block_dim()
    base = b * n_disc
    dt = timestep[b]
    zero = dt - dt
    half = type(dt)(0.5)
    one = type(dt)(1.0)
    mu = friction[b]
    h = cell[b]
    lg = velocity_gradient[b]
    e_map = step_map[b]
    h_build = cell_at_list_build[b]
    forced = force_rebuild[b]
    barrier = wp.tile_zeros(shape=1, dtype=int, storage="shared")
    done = int(0)  # noqa: UP018, RUF046 - a mutable loop variable in warp
    stale = int(0)  # noqa: UP018, RUF046
    failed = int(0)  # noqa: UP018, RUF046
    while done < left:
        barrier[0] = 0  # the previous step's writes are done before they are loaded
        s_all = wp.tile_load(fractional_position, shape=wp.static(BLOCK_DISCS), offset=base,
                             storage="shared")
        v_all = wp.tile_load(velocity, shape=wp.static(BLOCK_DISCS), offset=base,
                             storage="shared")
        w_all = wp.tile_load(angular_velocity, shape=wp.static(BLOCK_DISCS), offset=base,
                             storage="shared")
        bad = int(0)  # noqa: UP018, RUF046
        # -- the pairs each disc owns (contact_forces) --------------------------------------
        spin = half * (lg[1, 0] - lg[0, 1])
        for j in range(lane, n_disc, threads):
            i = base + j
            ra = radius[i]
            s_i = s_all[j]
            for k in range(contact_count[i]):
                slot = i * capacity + k
                cj = contact_partner[slot]
                if cj <= j:
                    continue
                d = branch_vector(s_i, s_all[cj], h)
                rc = radius[base + cj]
                mirror = base * capacity + wp.max(contact_mirror_slot[slot], 0)
                if wp.dot(d, d) >= (ra + rc) * (ra + rc) * type(dt)(1.000001):
                    contact_shear_force[slot] = zero
                    clear_pair(pair, slot, mirror)
                    continue
                dist = wp.length(d)
                overlap = ra + rc - dist
                if overlap <= zero:
                    contact_shear_force[slot] = zero
                    clear_pair(pair, slot, mirror)
                    continue
                if dist <= type(dt)(1.0e-12) * (ra + rc):
                    wp.atomic_or(status, b, STATUS_COINCIDENT)
                    bad = 1
                    clear_pair(pair, slot, mirror)
                    continue
                n = d / dist
                kn, kt = pair_stiffness(law, ra, rc)
                v_rel = v_all[cj] - v_all[j] + lg * d
                v_t = slip_rate(v_rel, n, dist, ra, rc, w_all[j], w_all[cj], spin)
                fn = kn * overlap
                fs = coulomb_shear(contact_shear_force[slot], kt, v_t, dt, mu, fn)
                contact_shear_force[slot] = fs
                f_a = contact_force(fn, fs, n)
                pair[slot] = type(pair[slot])(f_a[0], f_a[1], (ra - half * overlap) * fs)
                pair[mirror] = type(pair[slot])(-f_a[0], -f_a[1], (rc - half * overlap) * fs)
                if servo_on != 0:
                    pair_branch[slot] = d
                    pair_branch[mirror] = d
        barrier[0] = 0  # every record of the step is written
        # -- gather, damping, leap-frog (integrate) -----------------------------------------
        h_inv = wp.inverse(h)
        s_lane = type(h)()
        k_lane = type(s_all[0])()
        largest_sq = zero
        for j in range(lane, n_disc, threads):
            i = base + j
            ri = radius[i]
            f = type(s_all[0])()
            tq = zero
            s_sum = type(h)()
            k_sum = type(f)()
            for k in range(contact_count[i]):
                slot = i * capacity + k
                record = pair[slot]
                f_i = type(f)(record[0], record[1])
                f = f + f_i
                tq = tq + record[2]
                if servo_on != 0:
                    d = pair_branch[slot]
                    if f_i[0] != zero or f_i[1] != zero:  # touching: |f| >= fn > 0
                        c = base + contact_partner[slot]
                        kn, _kt = pair_stiffness(law, radius[wp.min(i, c)],
                                                 radius[wp.max(i, c)])
                        f_a = f_i
                        if c < i:
                            f_a = -f_i
                        s_sum = s_sum + love_term(f_a, d)
                        k_sum = k_sum + servo_stiffness_term(kn, d / wp.length(d), d)
            s_lane = s_lane + s_sum
            k_lane = k_lane + k_sum
            v = v_all[j]
            w = w_all[j]
            f = type(v)(local_damping(f[0], v[0], damping), local_damping(f[1], v[1], damping))
            tq = local_damping(tq, w, damping)
            v = v + dt * inv_mass[i] * f
            w = w + dt * inv_inertia[i] * tq
            dx = dt * v
            if not (wp.isfinite(v) and wp.isfinite(w)) or wp.length(dx) > type(dt)(0.25) * ri:
                wp.atomic_or(status, b, STATUS_BLOWUP)
                bad = 1
                largest_sq = wp.max(largest_sq, wp.length_sq(verlet_displacement[i]))
                continue
            velocity[i] = v
            angular_velocity[i] = w
            moved = verlet_displacement[i] + dx
            verlet_displacement[i] = moved
            largest_sq = wp.max(largest_sq, wp.length_sq(moved))
            s = s_all[j] + h_inv * dx
            fractional_position[i] = type(s)(s[0] - wp.floor(s[0]), s[1] - wp.floor(s[1]))
        # -- the block's sums: servo, cell, the skin (the same values in every thread) ------
        largest = wp.sqrt(wp.tile_max(wp.tile(largest_sq))[0])
        failed = wp.tile_max(wp.tile(bad))[0]
        if servo_on != 0:
            stress_sum = wp.tile_sum(wp.tile(s_lane, preserve_type=True))[0]
            stiffness_sum = wp.tile_sum(wp.tile(k_lane, preserve_type=True))[0]
            volume = wp.determinant(h) * thickness
            sigma = stress_sum / volume
            goal = target[b]
            de = type(goal)()
            for axis in range(2):
                if control[2 * b + axis] == CONTROL_STRESS:
                    modulus = wp.max(stiffness_sum[axis] / volume, type(dt)(1.0e-30))
                    increment = gain * (goal[axis] - sigma[axis, axis]) / modulus
                    de[axis] = wp.clamp(increment, -max_strain, max_strain)
                else:
                    de[axis] = goal[axis]
            lg = type(h)(de[0] / dt, zero, zero, de[1] / dt)
            e_map = type(h)(one + de[0], zero, zero, one + de[1])
        h = e_map * h
        done += 1
        heights = perpendicular_heights(h)
        if cutoff >= half * wp.min(heights[0], heights[1]):
            if lane == 0:
                wp.atomic_or(status, b, STATUS_CELL_TOO_SMALL)
            failed = 1
        if forced != 0 or lists_stale(h, h_build, largest, skin, cutoff):
            stale = 1
        if stale != 0 or failed != 0:
            break
    if lane == 0:
        cell[b] = h
        velocity_gradient[b] = lg
        step_map[b] = e_map
        rebuild[b] = stale
        steps_left[b] = left - done
        if failed != 0:
            steps_left[b] = 0  # an invalid state: the run stops and says so


def block_pending(n_rve: int, steps_left: IntArray, rebuild: IntArray, any_flag: IntArray):
    """One thread: ``any_flag[0]`` = 1 where some RVE still has steps left; the rebuild
    flags of RVEs that are done are cleared (their lists are tested again, as on the
    existing path, when the next run starts)."""
    flag = int(0)  # noqa: UP018, RUF046 - a mutable loop variable in warp
    for b in range(n_rve):
        if steps_left[b] > 0:
            flag = 1
        else:
            rebuild[b] = 0
    any_flag[0] = flag
