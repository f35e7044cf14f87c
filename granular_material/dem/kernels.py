"""warp kernels of the batched periodic disc DEM, built once per float type.

Every particle array is flat, index ``i = b·N + j`` for disc j of RVE b; per-RVE arrays have
length B. Positions are fractional, ``s = H⁻¹x`` in [0, 1)², so particles follow the cell's
homogeneous deformation (YADE's homoDeform); velocities are the fluctuation about the affine
field ``L·x``, and spins the fluctuation about the cell's spin ``(L₁₀ − L₀₁)/2``, so that a
rigid rotation of the cell is a rigid rotation of the packing (objectivity). Each particle
thread evaluates every pair in its own neighbour list (no atomics
on forces, deterministic); a pair is always computed in the orientation (min id → max id), so
both partners see bit-identical forces and tangential history.

Contact law (Cundall & Strack 1979, as YADE's Law2_ScGeom_FrictPhys_CundallStrack): normal
force ``kn·δ``; tangential spring ``fs += kt·(v_rel·t)·dt`` kept as a scalar along the
current tangent t = perp(n) (which rotates with the contact), capped at ``tan φ · kn·δ``.
"""


from dataclasses import dataclass
from functools import cache
from typing import Any

import warp as wp

__all__ = [
    "STATUS_BLOWUP",
    "STATUS_CELL_TOO_SMALL",
    "STATUS_COINCIDENT",
    "STATUS_OVERFLOW",
    "KernelSet",
    "kernels_for",
]

STATUS_BLOWUP = 1  #: a velocity became non-finite or a disc moved > r/4 in one step
STATUS_OVERFLOW = 2  #: a neighbour list exceeded its capacity
STATUS_CELL_TOO_SMALL = 4  #: contact cut-off above half a perpendicular cell height
STATUS_COINCIDENT = 8  #: two disc centres coincide

LAW_CONSTANT = 0
LAW_FRICTMAT = 1


@dataclass(frozen=True)
class KernelSet:
    """The kernels and vector types for one float type (wp.float64 or wp.float32)."""

    float_type: Any
    vec2: Any
    mat22: Any
    mat44: Any
    check_rebuild: Any
    clear_bins: Any
    fill_bins: Any
    build_neighbors: Any
    commit_neighbors: Any
    compute_forces: Any
    servo: Any
    integrate: Any
    advance_cell: Any
    contact_measures: Any
    reduce_measures: Any


@cache
def kernels_for(float_type: Any, replica: int = 0) -> KernelSet:
    """Build (once) and return the kernel set for ``float_type``.

    Each ``replica`` is a separate warp module. On x86-64 a CPU module keeps a static
    pointer to the running launch's tile storage, so two threads must never run kernels of
    the same module at once: every CPU shard steps with its own replica.
    """
    ft = float_type
    module = f"granular_material_dem_{wp.types.type_repr(ft)}_r{replica}"
    vec2 = wp.types.vector(2, ft)
    mat22 = wp.types.matrix((2, 2), ft)
    mat44 = wp.types.matrix((4, 4), ft)

    @wp.func
    def min_image(ds: vec2) -> vec2:
        return vec2(ds[0] - wp.round(ds[0]), ds[1] - wp.round(ds[1]))

    @wp.func
    def branch(i: int, j: int, h: mat22, frac: wp.array(dtype=vec2)) -> vec2:
        """Minimum-image branch vector from disc min(i, j) to disc max(i, j) [m]."""
        return h * min_image(frac[wp.max(i, j)] - frac[wp.min(i, j)])

    @wp.func
    def pair_stiffness(
        law: int, ra: ft, rb: ft, kn_c: ft, kt_c: ft, young: ft, kt_ratio: ft
    ) -> vec2:
        if law == LAW_FRICTMAT:
            kn = ft(2.0) * young * ra * rb / (ra + rb)
            return vec2(kn, kt_ratio * kn)
        return vec2(kn_c, kt_c)

    @wp.kernel(module=module)
    def check_rebuild(
        n_disc: int,
        skin: ft,
        cutoff: ft,
        active: wp.array(dtype=wp.int32),
        cell: wp.array(dtype=mat22),
        cell_ref: wp.array(dtype=mat22),
        disp: wp.array(dtype=vec2),
        force_rebuild: wp.array(dtype=wp.int32),
        rebuild: wp.array(dtype=wp.int32),
        status: wp.array(dtype=wp.int32),
    ):
        b = wp.tid()
        rebuild[b] = 0
        if active[b] == 0:
            return
        h = cell[b]
        area = wp.determinant(h)
        len0 = wp.sqrt(h[0, 0] * h[0, 0] + h[1, 0] * h[1, 0])
        len1 = wp.sqrt(h[0, 1] * h[0, 1] + h[1, 1] * h[1, 1])
        height = wp.min(area / len1, area / len0)
        if cutoff >= ft(0.5) * height:
            wp.atomic_or(status, b, STATUS_CELL_TOO_SMALL)
        max_disp = ft(0.0)
        for j in range(n_disc):
            max_disp = wp.max(max_disp, wp.length(disp[b * n_disc + j]))
        rel = h * wp.inverse(cell_ref[b])
        strain = wp.sqrt(
            (rel[0, 0] - ft(1.0)) * (rel[0, 0] - ft(1.0))
            + rel[0, 1] * rel[0, 1]
            + rel[1, 0] * rel[1, 0]
            + (rel[1, 1] - ft(1.0)) * (rel[1, 1] - ft(1.0))
        )
        if force_rebuild[b] != 0 or ft(2.0) * max_disp + strain * cutoff > skin:
            rebuild[b] = 1
            cell_ref[b] = h
            force_rebuild[b] = 0

    @wp.func
    def bins_per_axis(h: mat22, cutoff: ft, max_bins: int) -> wp.vec2i:
        """Bins along s0 and s1: each at least ``cutoff`` across, measured perpendicular."""
        area = wp.determinant(h)
        len0 = wp.sqrt(h[0, 0] * h[0, 0] + h[1, 0] * h[1, 0])
        len1 = wp.sqrt(h[0, 1] * h[0, 1] + h[1, 1] * h[1, 1])
        n0 = wp.min(int(wp.floor(area / len1 / cutoff)), max_bins)
        n1 = wp.min(int(wp.floor(area / len0 / cutoff)), max_bins)
        return wp.vec2i(wp.max(n0, 1), wp.max(n1, 1))

    @wp.func
    def bin_of(s: vec2, nb: wp.vec2i) -> wp.vec2i:
        return wp.vec2i(wp.min(int(s[0] * ft(nb[0])), nb[0] - 1),
                        wp.min(int(s[1] * ft(nb[1])), nb[1] - 1))

    @wp.kernel(module=module)
    def clear_bins(
        max_bins: int,
        rebuild: wp.array(dtype=wp.int32),
        bin_count: wp.array(dtype=wp.int32),
    ):
        k = wp.tid()
        if rebuild[k // (max_bins * max_bins)] != 0:
            bin_count[k] = 0

    @wp.kernel(module=module)
    def fill_bins(
        n_disc: int,
        max_bins: int,
        bin_capacity: int,
        cutoff: ft,
        rebuild: wp.array(dtype=wp.int32),
        cell: wp.array(dtype=mat22),
        frac: wp.array(dtype=vec2),
        bin_count: wp.array(dtype=wp.int32),
        bin_items: wp.array(dtype=wp.int32),
        status: wp.array(dtype=wp.int32),
    ):
        i = wp.tid()
        b = i // n_disc
        if rebuild[b] == 0:
            return
        nb = bins_per_axis(cell[b], cutoff, max_bins)
        if nb[0] < 3 or nb[1] < 3:
            return  # small cell: the build scans all discs of the RVE
        ij = bin_of(frac[i], nb)
        key = (b * max_bins + ij[1]) * max_bins + ij[0]
        slot = wp.atomic_add(bin_count, key, 1)
        if slot < bin_capacity:
            bin_items[key * bin_capacity + slot] = i - b * n_disc
        else:
            wp.atomic_or(status, b, STATUS_OVERFLOW)

    @wp.func
    def consider_pair(
        i: int, jj: int, base: int, h: mat22, skin: ft, capacity: int, count: int,
        frac: wp.array(dtype=vec2), radius: wp.array(dtype=ft),
        nbr: wp.array(dtype=wp.int32), shear: wp.array(dtype=ft), old_count: int,
        nbr_new: wp.array(dtype=wp.int32), shear_new: wp.array(dtype=ft),
    ) -> int:
        """Insert partner jj (kept sorted by jj, history carried over); returns the count."""
        j = base + jj
        if j == i:
            return count
        d = branch(i, j, h, frac)
        reach = radius[i] + radius[j] + skin
        if wp.dot(d, d) >= reach * reach:
            return count
        if count < capacity:
            history = ft(0.0)
            for k in range(old_count):
                if nbr[i * capacity + k] == jj:
                    history = shear[i * capacity + k]
            pos = count
            while pos > 0 and nbr_new[i * capacity + pos - 1] > jj:
                nbr_new[i * capacity + pos] = nbr_new[i * capacity + pos - 1]
                shear_new[i * capacity + pos] = shear_new[i * capacity + pos - 1]
                pos -= 1
            nbr_new[i * capacity + pos] = jj
            shear_new[i * capacity + pos] = history
        return count + 1

    @wp.kernel(module=module)
    def build_neighbors(
        n_disc: int,
        capacity: int,
        max_bins: int,
        bin_capacity: int,
        skin: ft,
        cutoff: ft,
        rebuild: wp.array(dtype=wp.int32),
        cell: wp.array(dtype=mat22),
        frac: wp.array(dtype=vec2),
        radius: wp.array(dtype=ft),
        bin_count: wp.array(dtype=wp.int32),
        bin_items: wp.array(dtype=wp.int32),
        nbr: wp.array(dtype=wp.int32),
        nbr_count: wp.array(dtype=wp.int32),
        shear: wp.array(dtype=ft),
        nbr_new: wp.array(dtype=wp.int32),
        nbr_count_new: wp.array(dtype=wp.int32),
        shear_new: wp.array(dtype=ft),
        status: wp.array(dtype=wp.int32),
    ):
        i = wp.tid()
        b = i // n_disc
        if rebuild[b] == 0:
            return
        base = b * n_disc
        h = cell[b]
        old_count = nbr_count[i]
        count = int(0)  # noqa: UP018, RUF046 - a mutable loop variable in warp
        nb = bins_per_axis(h, cutoff, max_bins)
        if nb[0] < 3 or nb[1] < 3:
            for jj in range(n_disc):
                count = consider_pair(i, jj, base, h, skin, capacity, count, frac, radius,
                                      nbr, shear, old_count, nbr_new, shear_new)
        else:
            # the 3 x 3 bins around i's (distinct, as there are >= 3 bins per axis)
            ij = bin_of(frac[i], nb)
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    bx = (ij[0] + dx + nb[0]) % nb[0]
                    by = (ij[1] + dy + nb[1]) % nb[1]
                    key = (b * max_bins + by) * max_bins + bx
                    for q in range(wp.min(bin_count[key], bin_capacity)):
                        jj = bin_items[key * bin_capacity + q]
                        count = consider_pair(i, jj, base, h, skin, capacity, count, frac,
                                              radius, nbr, shear, old_count, nbr_new,
                                              shear_new)
        if count > capacity:
            wp.atomic_or(status, b, STATUS_OVERFLOW)
            count = capacity
        nbr_count_new[i] = count

    @wp.kernel(module=module)
    def commit_neighbors(
        n_disc: int,
        capacity: int,
        rebuild: wp.array(dtype=wp.int32),
        nbr_new: wp.array(dtype=wp.int32),
        nbr_count_new: wp.array(dtype=wp.int32),
        shear_new: wp.array(dtype=ft),
        nbr: wp.array(dtype=wp.int32),
        nbr_count: wp.array(dtype=wp.int32),
        shear: wp.array(dtype=ft),
        disp: wp.array(dtype=vec2),
    ):
        i = wp.tid()
        if rebuild[i // n_disc] == 0:
            return
        count = nbr_count_new[i]
        nbr_count[i] = count
        for k in range(count):
            nbr[i * capacity + k] = nbr_new[i * capacity + k]
            shear[i * capacity + k] = shear_new[i * capacity + k]
        disp[i] = vec2(ft(0.0), ft(0.0))

    @wp.kernel(module=module)
    def compute_forces(
        n_disc: int,
        capacity: int,
        timestep: wp.array(dtype=ft),
        law: int,
        kn_c: ft,
        kt_c: ft,
        young: ft,
        kt_ratio: ft,
        active: wp.array(dtype=wp.int32),
        friction: wp.array(dtype=ft),
        cell: wp.array(dtype=mat22),
        vel_grad: wp.array(dtype=mat22),
        frac: wp.array(dtype=vec2),
        vel: wp.array(dtype=vec2),
        ang_vel: wp.array(dtype=ft),
        radius: wp.array(dtype=ft),
        nbr: wp.array(dtype=wp.int32),
        nbr_count: wp.array(dtype=wp.int32),
        shear: wp.array(dtype=ft),
        force: wp.array(dtype=vec2),
        torque: wp.array(dtype=ft),
        part_stress: wp.array(dtype=mat22),
        part_stiff: wp.array(dtype=vec2),
        status: wp.array(dtype=wp.int32),
    ):
        i = wp.tid()
        b = i // n_disc
        zero = vec2(ft(0.0), ft(0.0))
        f_sum = zero
        t_sum = ft(0.0)
        s_sum = mat22(ft(0.0), ft(0.0), ft(0.0), ft(0.0))
        k_sum = zero
        if active[b] != 0:
            base = b * n_disc
            h = cell[b]
            lg = vel_grad[b]
            mu = friction[b]
            dt = timestep[b]
            for k in range(nbr_count[i]):
                slot = i * capacity + k
                j = base + nbr[slot]
                a = wp.min(i, j)
                c = wp.max(i, j)
                d = branch(i, j, h, frac)
                dist = wp.length(d)
                ra = radius[a]
                rc = radius[c]
                overlap = ra + rc - dist
                if overlap <= ft(0.0):
                    shear[slot] = ft(0.0)
                    continue
                if dist <= ft(1.0e-12) * (ra + rc):
                    wp.atomic_or(status, b, STATUS_COINCIDENT)
                    continue
                n = d / dist
                t = vec2(-n[1], n[0])
                stiff = pair_stiffness(law, ra, rc, kn_c, kt_c, young, kt_ratio)
                # affine field: velocity L·x and spin w = (L10 - L01)/2 of every disc
                v_rel = vel[c] - vel[a] + lg * d
                spin = ft(0.5) * (lg[1, 0] - lg[0, 1])
                v_t = wp.dot(v_rel, t) - (ang_vel[a] * ra + ang_vel[c] * rc) - spin * (ra + rc)
                fs = shear[slot] + stiff[1] * v_t * dt
                fn = stiff[0] * overlap
                cap = mu * fn
                if wp.abs(fs) > cap:
                    fs = wp.sign(fs) * cap
                shear[slot] = fs
                f_a = -fn * n + fs * t
                if i == a:
                    f_sum = f_sum + f_a
                    t_sum = t_sum + (ra - ft(0.5) * overlap) * fs
                else:
                    f_sum = f_sum - f_a
                    t_sum = t_sum + (rc - ft(0.5) * overlap) * fs
                # half of the pair's Love term -f_(a->c) (x) d = f_a (x) d, per partner
                s_sum = s_sum + ft(0.5) * wp.outer(f_a, d)
                nd_x = n[0] * d[0]
                nd_y = n[1] * d[1]
                k_sum = k_sum + ft(0.5) * stiff[0] * vec2(nd_x * nd_x, nd_y * nd_y)
        force[i] = f_sum
        torque[i] = t_sum
        part_stress[i] = s_sum
        part_stiff[i] = k_sum

    @wp.kernel(module=module)
    def servo(
        n_disc: int,
        timestep: wp.array(dtype=ft),
        thickness: ft,
        gain: ft,
        max_strain: ft,
        active: wp.array(dtype=wp.int32),
        cell: wp.array(dtype=mat22),
        part_stress: wp.array(dtype=mat22),
        part_stiff: wp.array(dtype=vec2),
        control: wp.array(dtype=wp.int32),
        target: wp.array(dtype=vec2),
        vel_grad: wp.array(dtype=mat22),
        step_map: wp.array(dtype=mat22),
    ):
        b = wp.tid()
        if active[b] == 0:
            return
        dt = timestep[b]
        volume = wp.determinant(cell[b]) * thickness
        s_sum = mat22(ft(0.0), ft(0.0), ft(0.0), ft(0.0))
        k_sum = vec2(ft(0.0), ft(0.0))
        for j in range(n_disc):
            s_sum = s_sum + part_stress[b * n_disc + j]
            k_sum = k_sum + part_stiff[b * n_disc + j]
        sigma = s_sum / volume
        goal = target[b]
        de = vec2(ft(0.0), ft(0.0))
        for k in range(2):
            if control[2 * b + k] == 1:
                modulus = wp.max(k_sum[k] / volume, ft(1.0e-30))
                step = gain * (goal[k] - sigma[k, k]) / modulus
                de[k] = wp.clamp(step, -max_strain, max_strain)
            else:
                de[k] = goal[k]
        lg = mat22(de[0] / dt, ft(0.0), ft(0.0), de[1] / dt)
        vel_grad[b] = lg
        step_map[b] = mat22(ft(1.0) + de[0], ft(0.0), ft(0.0), ft(1.0) + de[1])

    @wp.func
    def damp(f: ft, v: ft, damping: ft) -> ft:
        if f * v > ft(0.0):
            return f * (ft(1.0) - damping)
        if f * v < ft(0.0):
            return f * (ft(1.0) + damping)
        return f

    @wp.kernel(module=module)
    def integrate(
        n_disc: int,
        timestep: wp.array(dtype=ft),
        damping: ft,
        active: wp.array(dtype=wp.int32),
        cell: wp.array(dtype=mat22),
        radius: wp.array(dtype=ft),
        inv_mass: wp.array(dtype=ft),
        inv_inertia: wp.array(dtype=ft),
        force: wp.array(dtype=vec2),
        torque: wp.array(dtype=ft),
        frac: wp.array(dtype=vec2),
        vel: wp.array(dtype=vec2),
        ang_vel: wp.array(dtype=ft),
        disp: wp.array(dtype=vec2),
        status: wp.array(dtype=wp.int32),
    ):
        i = wp.tid()
        b = i // n_disc
        if active[b] == 0:
            return
        dt = timestep[b]
        v = vel[i]
        f = force[i]
        f = vec2(damp(f[0], v[0], damping), damp(f[1], v[1], damping))
        w = ang_vel[i]
        tq = damp(torque[i], w, damping)
        v = v + dt * inv_mass[i] * f
        w = w + dt * inv_inertia[i] * tq
        dx = dt * v
        if not (wp.isfinite(v) and wp.isfinite(w)) or wp.length(dx) > ft(0.25) * radius[i]:
            wp.atomic_or(status, b, STATUS_BLOWUP)
            return
        vel[i] = v
        ang_vel[i] = w
        disp[i] = disp[i] + dx
        s = frac[i] + wp.inverse(cell[b]) * dx
        frac[i] = vec2(s[0] - wp.floor(s[0]), s[1] - wp.floor(s[1]))

    @wp.kernel(module=module)
    def advance_cell(
        active: wp.array(dtype=wp.int32),
        step_map: wp.array(dtype=mat22),
        cell: wp.array(dtype=mat22),
    ):
        b = wp.tid()
        if active[b] != 0:
            cell[b] = step_map[b] * cell[b]

    @wp.kernel(module=module)
    def contact_measures(
        n_disc: int,
        capacity: int,
        law: int,
        kn_c: ft,
        kt_c: ft,
        young: ft,
        kt_ratio: ft,
        friction: wp.array(dtype=ft),
        cell: wp.array(dtype=mat22),
        frac: wp.array(dtype=vec2),
        radius: wp.array(dtype=ft),
        nbr: wp.array(dtype=wp.int32),
        nbr_count: wp.array(dtype=wp.int32),
        shear: wp.array(dtype=ft),
        part_stress: wp.array(dtype=mat22),
        part_tangent: wp.array(dtype=mat44),
        part_fabric: wp.array(dtype=mat22),
        part_counts: wp.array(dtype=vec2),
        part_forces: wp.array(dtype=vec2),
    ):
        """Per-disc halves of the contact sums of Love stress, KR tangent and fabric."""
        i = wp.tid()
        b = i // n_disc
        base = b * n_disc
        h = cell[b]
        mu = friction[b]
        s_sum = mat22(ft(0.0), ft(0.0), ft(0.0), ft(0.0))
        fab = mat22(ft(0.0), ft(0.0), ft(0.0), ft(0.0))
        tan = mat44()
        n_contacts = ft(0.0)
        n_sliding = ft(0.0)
        f_net = vec2(ft(0.0), ft(0.0))
        f_abs = ft(0.0)
        for k in range(nbr_count[i]):
            slot = i * capacity + k
            j = base + nbr[slot]
            a = wp.min(i, j)
            c = wp.max(i, j)
            d = branch(i, j, h, frac)
            dist = wp.length(d)
            ra = radius[a]
            rc = radius[c]
            overlap = ra + rc - dist
            if overlap <= ft(0.0) or dist <= ft(0.0):
                continue
            n = d / dist
            t = vec2(-n[1], n[0])
            stiff = pair_stiffness(law, ra, rc, kn_c, kt_c, young, kt_ratio)
            fn = stiff[0] * overlap
            fs = shear[slot]
            f_a = -fn * n + fs * t
            if i == a:
                f_net = f_net + f_a
            else:
                f_net = f_net - f_a
            s_sum = s_sum + ft(0.5) * wp.outer(f_a, d)
            fab = fab + ft(0.5) * wp.outer(n, n)
            n_contacts = n_contacts + ft(0.5)
            if wp.abs(fs) >= mu * fn * ft(1.0 - 1.0e-9):
                n_sliding = n_sliding + ft(0.5)
            f_abs = f_abs + ft(0.5) * wp.length(f_a)
            # C_ijkl = kn n_i d_j n_k d_l + kt t_i d_j t_k d_l, index (i,j) -> 2i+j
            for p in range(2):
                for q in range(2):
                    for r in range(2):
                        for s in range(2):
                            tan[2 * p + q, 2 * r + s] = tan[2 * p + q, 2 * r + s] + ft(0.5) * (
                                stiff[0] * n[p] * d[q] * n[r] * d[s]
                                + stiff[1] * t[p] * d[q] * t[r] * d[s]
                            )
        part_stress[i] = s_sum
        part_tangent[i] = tan
        part_fabric[i] = fab
        part_counts[i] = vec2(n_contacts, n_sliding)
        part_forces[i] = vec2(wp.length(f_net), f_abs)

    @wp.kernel(module=module)
    def reduce_measures(
        n_disc: int,
        part_stress: wp.array(dtype=mat22),
        part_tangent: wp.array(dtype=mat44),
        part_fabric: wp.array(dtype=mat22),
        part_counts: wp.array(dtype=vec2),
        part_forces: wp.array(dtype=vec2),
        stress: wp.array(dtype=mat22),
        tangent: wp.array(dtype=mat44),
        fabric: wp.array(dtype=mat22),
        counts: wp.array(dtype=vec2),
        forces: wp.array(dtype=vec2),
    ):
        b = wp.tid()
        s_sum = mat22(ft(0.0), ft(0.0), ft(0.0), ft(0.0))
        f_sum = mat22(ft(0.0), ft(0.0), ft(0.0), ft(0.0))
        t_sum = mat44()
        c_sum = vec2(ft(0.0), ft(0.0))
        g_sum = vec2(ft(0.0), ft(0.0))
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

    return KernelSet(
        float_type=ft, vec2=vec2, mat22=mat22, mat44=mat44,
        check_rebuild=check_rebuild, clear_bins=clear_bins, fill_bins=fill_bins,
        build_neighbors=build_neighbors,
        commit_neighbors=commit_neighbors, compute_forces=compute_forces, servo=servo,
        integrate=integrate, advance_cell=advance_cell, contact_measures=contact_measures,
        reduce_measures=reduce_measures,
    )
