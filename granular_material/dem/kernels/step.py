"""Kernels of one DEM step: contact forces once per pair, their gather and the integration,
the stress servo, the cell update.

A step is ``contact_forces`` → ``integrate`` → optionally ``servo`` →
``advance_cell_and_check``; on the CPU ``step_serial`` does the work of the first two in one
pass per RVE. Those three test the compile-time flags ``TANGENTIAL``, ``DAMPING`` and
``STRESS`` below through ``wp.static``, so that a variant built with other values
(:func:`~.kernels.step_kernels_for`) leaves those terms out of its code.

``step_serial``: on the CPU a warp kernel runs its threads one after the other, so one thread
per RVE walks its discs in index order and, for every pair a disc owns, adds the force to
both discs at once, with no record per slot and no second pass to gather them; a disc is
integrated as soon as its turn is over, as every pair that touches it is owned by a disc of
lower or equal index and has been added by then (partners of higher index are read before
they are integrated: every force is that of the state at the start of the step). A disc's
sums come out in the gather's order, its lower partners (added at their turns, in index
order) then its own: list order where lists are sorted by partner, as every build leaves
them, and then the results are ``integrate``'s bit for bit.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from granular_material.dem.kernels.common import (
    CONTROL_STRESS,
    STATUS_BLOWUP,
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
    servo_stiffness_term,
    slip_rate,
)
from granular_material.dem.kernels.lists import flag_rebuild, largest_displacement

__all__ = ["DAMPING", "STRESS", "TANGENTIAL", "advance_cell_and_check", "contact_forces",
           "integrate", "servo", "step_serial"]

#: compile-time features of ``contact_forces`` and ``integrate``, read through ``wp.static``:
#: the generic kernels see these values; :func:`~.kernels.step_kernels_for` builds variants of
#: the two kernels that see others (their own warp module each), for scenes that need less
TANGENTIAL = True  #: the tangential (Cundall–Strack) force, its history and the torques
DAMPING = True  #: YADE's local damping of forces and torques
STRESS = True  #: the Love and servo-stiffness sums, where ``with_stress`` asks at run time


@wp.func
def clear_pair(pair: AnyArray, slot: int, mirror: int):
    """Zero both records of a pair that does not touch; both are zero already where the
    pair's own record is (they are written together, and zeroed together at list builds
    and when a state is restored), so the scattered write is skipped then."""
    record = pair[slot]
    zero = record[0] - record[0]
    if record[0] != zero or record[1] != zero or record[2] != zero:
        pair[slot] = type(record)()
        pair[mirror] = type(record)()


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
    the branch vector d = x_c − x_a of touching pairs (the others' is stale: unused)."""
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
        if wp.dot(d, d) >= (ra + rc) * (ra + rc) * type(dt)(1.000001):
            contact_shear_force[slot] = zero  # clearly apart (decided without a root)
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
            clear_pair(pair, slot, mirror)
            continue
        n = d / dist
        kn, kt = pair_stiffness(law, ra, rc)
        v_rel = velocity[c] - velocity[i] + lg * d
        v_t = slip_rate(v_rel, n, dist, ra, rc, angular_velocity[i], angular_velocity[c],
                        spin)
        fn = kn * overlap
        half = type(dt)(0.5)
        if wp.static(TANGENTIAL):
            fs = coulomb_shear(contact_shear_force[slot], kt, v_t, dt, mu, fn)
            contact_shear_force[slot] = fs
            f_a = contact_force(fn, fs, n)
            pair[slot] = type(pair[slot])(f_a[0], f_a[1], (ra - half * overlap) * fs)
            pair[mirror] = type(pair[slot])(-f_a[0], -f_a[1], (rc - half * overlap) * fs)
        else:  # frictionless (μ = 0 caps fs at 0): v_t is unused, the compiler drops it
            contact_shear_force[slot] = zero
            f_a = -fn * n
            pair[slot] = type(pair[slot])(f_a[0], f_a[1], zero)
            pair[mirror] = type(pair[slot])(-f_a[0], -f_a[1], zero)
        if wp.static(STRESS):
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
        if wp.static(TANGENTIAL):
            tq = tq + record[2]
        if wp.static(STRESS):
            if with_stress != 0:
                d = pair_branch[slot]
                if f_i[0] != zero or f_i[1] != zero:  # touching: |f| >= fn > 0
                    j = b * n_disc + contact_partner[slot]
                    kn, _kt = pair_stiffness(law, radius[wp.min(i, j)], radius[wp.max(i, j)])
                    # Love's term takes the force on the pair's lower index
                    f_a = f_i
                    if j < i:
                        f_a = -f_i
                    s_sum = s_sum + love_term(f_a, d)
                    k_sum = k_sum + servo_stiffness_term(kn, d / wp.length(d), d)
    if wp.static(STRESS):
        if with_stress != 0:
            part_stress[i] = s_sum
            part_stiffness[i] = k_sum
    v = velocity[i]
    w = angular_velocity[i]
    if wp.static(DAMPING):  # (with damping 0 it multiplies by exactly 1)
        f = type(v)(local_damping(f[0], v[0], damping), local_damping(f[1], v[1], damping))
        tq = local_damping(tq, w, damping)
    v = v + dt * inv_mass[i] * f
    if wp.static(TANGENTIAL):  # (frictionless: no torque, the spin keeps its value)
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


def step_serial(
    n_disc: int, capacity: int, law: ContactLaw, damping: Any, with_stress: int,
    timestep: AnyArray, active: IntArray, friction: AnyArray, cell: AnyArray,
    velocity_gradient: AnyArray, radius: AnyArray, inv_mass: AnyArray,
    inv_inertia: AnyArray, contact_partner: IntArray, contact_count: IntArray,
    contact_shear_force: AnyArray, fractional_position: AnyArray, velocity: AnyArray,
    angular_velocity: AnyArray, verlet_displacement: AnyArray, disc_load: AnyArray,
    part_stress: AnyArray, part_stiffness: AnyArray, status: IntArray,
):
    """Per RVE: the Cundall–Strack force of every pair, added to both discs' ``disc_load``
    (force [N], torque [N·m]), each disc damped and leap-frogged when its turn is over;
    with ``with_stress`` also each disc's halves of the Love sum and of the servo's
    stiffness. The same physics as ``contact_forces`` then ``integrate``."""
    b = wp.tid()
    if active[b] == 0:
        return
    base = b * n_disc
    h = cell[b]
    h_inv = wp.inverse(h)
    lg = velocity_gradient[b]
    mu = friction[b]
    dt = timestep[b]
    zero = dt - dt
    half = type(dt)(0.5)
    # affine spin w = (L10 - L01)/2 of every disc
    spin = half * (lg[1, 0] - lg[0, 1])
    stress = with_stress != 0
    for j in range(n_disc):
        disc_load[base + j] = type(disc_load[base + j])()
        if wp.static(STRESS):
            if stress:
                part_stress[base + j] = type(h)()
                part_stiffness[base + j] = type(fractional_position[base + j])()
    for j in range(n_disc):
        i = base + j
        ra = radius[i]
        s_i = fractional_position[i]
        v = velocity[i]
        w = angular_velocity[i]
        load = disc_load[i]  # what the lower partners added
        f = type(v)(load[0], load[1])
        tq = load[2]
        s_sum = type(h)()
        k_sum = type(v)()
        if wp.static(STRESS):
            if stress:
                s_sum = part_stress[i]
                k_sum = part_stiffness[i]
        for k in range(contact_count[i]):
            slot = i * capacity + k
            c = base + contact_partner[slot]
            if c <= i:
                continue
            d = branch_vector(s_i, fractional_position[c], h)
            rc = radius[c]
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
            kn, kt = pair_stiffness(law, ra, rc)
            fn = kn * overlap
            f_a = -fn * n
            tq_a = zero
            tq_c = zero
            if wp.static(TANGENTIAL):
                v_rel = velocity[c] - v + lg * d
                v_t = slip_rate(v_rel, n, dist, ra, rc, w, angular_velocity[c], spin)
                fs = coulomb_shear(contact_shear_force[slot], kt, v_t, dt, mu, fn)
                contact_shear_force[slot] = fs
                f_a = contact_force(fn, fs, n)
                tq_a = (ra - half * overlap) * fs
                tq_c = (rc - half * overlap) * fs
            else:  # frictionless (μ = 0 caps fs at 0)
                contact_shear_force[slot] = zero
            f = f + f_a
            tq = tq + tq_a
            disc_load[c] = disc_load[c] + type(load)(-f_a[0], -f_a[1], tq_c)
            if wp.static(STRESS):
                if stress:
                    love = love_term(f_a, d)
                    stiff = servo_stiffness_term(kn, n, d)
                    s_sum = s_sum + love
                    k_sum = k_sum + stiff
                    part_stress[c] = part_stress[c] + love
                    part_stiffness[c] = part_stiffness[c] + stiff
        # every pair of disc i is in: integrate it (as ``integrate``)
        if wp.static(STRESS):
            if stress:
                part_stress[i] = s_sum
                part_stiffness[i] = k_sum
        if wp.static(DAMPING):  # (with damping 0 it multiplies by exactly 1)
            f = type(v)(local_damping(f[0], v[0], damping), local_damping(f[1], v[1], damping))
            tq = local_damping(tq, w, damping)
        v = v + dt * inv_mass[i] * f
        if wp.static(TANGENTIAL):  # (frictionless: no torque, the spin keeps its value)
            w = w + dt * inv_inertia[i] * tq
        dx = dt * v
        # finite iff x·0 is 0 (inf·0 and NaN·0 are NaN), without a call per component;
        # and |dx| > r/4 compared in squares, without a root
        finite = v[0] * zero + v[1] * zero + w * zero == zero
        if not finite or wp.dot(dx, dx) > type(dt)(0.0625) * ra * ra:
            wp.atomic_or(status, b, STATUS_BLOWUP)
            continue
        velocity[i] = v
        angular_velocity[i] = w
        verlet_displacement[i] = verlet_displacement[i] + dx
        s = s_i + h_inv * dx
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
