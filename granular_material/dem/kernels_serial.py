"""The step's forces and integration as one serial pass per RVE: the CPU's kernel.

On the CPU a warp kernel runs its threads one after the other, so one thread per RVE can
walk its discs in index order and, for every pair a disc owns (partner of higher index),
add the force to both discs at once, with no record per slot and no second pass to gather
them; a disc is integrated as soon as its turn is over, as every pair that touches it is
owned by a disc of lower or equal index and has been added by then (the partners of higher
index are read before they are integrated: every force is that of the state at the start
of the step, as in ``contact_forces`` → ``integrate``).

The sums come out in the same order as the gather's: a disc's lower partners (added at
their turns, in index order) and then its own (in list order), which is list order where
lists are sorted by partner, as every build leaves them. The kernel tests the compile-time
flags ``TANGENTIAL``, ``DAMPING`` and ``STRESS`` of :mod:`~.kernels_step` as
``contact_forces`` and ``integrate`` do; :func:`~.kernels.step_kernels_for` builds its
variants with theirs.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from granular_material.dem.kernel_common import (
    STATUS_BLOWUP,
    STATUS_COINCIDENT,
    AnyArray,
    IntArray,
)
from granular_material.dem.kernels_step import DAMPING, STRESS, TANGENTIAL
from granular_material.dem.laws import (
    ContactLaw,
    branch_vector,
    contact_force,
    coulomb_shear,
    local_damping,
    love_term,
    pair_stiffness,
    servo_stiffness_term,
)

__all__ = ["step_serial"]


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
                t = type(n)(-n[1], n[0])
                v_rel = velocity[c] - v + lg * d
                # slip rate as in contact_forces (YADE's ScGeom, avoidGranularRatcheting)
                v_t = (ra + rc) / dist * wp.dot(v_rel, t) \
                    - (w * ra + angular_velocity[c] * rc) - spin * (ra + rc)
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
