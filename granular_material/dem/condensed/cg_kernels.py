"""The warp kernels of the condensed tangent's batched block-Jacobi CG (issue 26), on any
device: one block of work per system s = 3·rve + column (``wp.launch_tiled``: on CUDA a
thread block whose threads share the RVE's discs, the dot products reduced over the block;
on the CPU a single lane), over the block-sparse layout of
:class:`~granular_material.dem.condensed.cg_solve.DeviceSystem` (3 × 3 blocks over u_x, u_y,
w = r·θ), and the products K_Gu X reduced on the device as well. float64 only; launched by
:func:`~granular_material.dem.condensed.cg_solve.solve_on_device`."""

from __future__ import annotations

import warp as wp

__all__ = [
    "MODULE",
    "cg_direction",
    "cg_iterate",
    "cg_start",
    "kernel_modules",
    "load_products",
    "mat33",
    "vec3",
]

MODULE = "granular_material_dem_condensed_cg"  #: the warp module of the kernels below

vec3 = wp.vec3d
mat33 = wp.mat33d


@wp.func
def _bsr_row(block_start: wp.array(dtype=wp.int32), row_end: wp.array(dtype=wp.int32),
             block_disc: wp.array(dtype=wp.int32),
             block_value: wp.array(dtype=mat33), v: wp.array(dtype=vec3), offset: int,
             k: int) -> vec3:
    """Row k of the block matrix times the column of ``v`` that starts at ``offset``."""
    acc = vec3()
    for e in range(block_start[k], row_end[k]):
        acc += block_value[e] * v[offset + block_disc[e]]
    return acc


@wp.kernel(enable_backward=False, module=MODULE)
def cg_start(disc_start: wp.array(dtype=wp.int32), n_total: int,
             inverse_diagonal: wp.array(dtype=mat33), rhs: wp.array(dtype=vec3),
             x: wp.array(dtype=vec3), r: wp.array(dtype=vec3), z: wp.array(dtype=vec3),
             p: wp.array(dtype=vec3), rhs_norm2: wp.array(dtype=wp.float64),
             rz: wp.array(dtype=wp.float64), residual: wp.array(dtype=wp.float64),
             iterations: wp.array(dtype=wp.int32), active: wp.array(dtype=wp.int32)):
    """x = 0, r = b, z = p = M⁻¹r and the norms, one block per system s = 3·rve + column."""
    s, lane = wp.tid()
    width = wp.block_dim()
    rve = s // 3
    offset = (s - 3 * rve) * n_total
    acc_bb = wp.float64(0.0)
    acc_rz = wp.float64(0.0)
    k = disc_start[rve] + lane
    while k < disc_start[rve + 1]:
        i = offset + k
        rv = rhs[i]
        zv = inverse_diagonal[k] * rv
        x[i] = vec3()
        r[i] = rv
        z[i] = zv
        p[i] = zv
        acc_bb += wp.dot(rv, rv)
        acc_rz += wp.dot(rv, zv)
        k += width
    bb = wp.tile_extract(wp.tile_sum(wp.tile(acc_bb)), 0)
    rz0 = wp.tile_extract(wp.tile_sum(wp.tile(acc_rz)), 0)
    if lane == 0:
        rhs_norm2[s] = bb
        rz[s] = rz0
        iterations[s] = 0
        if bb > wp.float64(0.0):
            residual[s] = wp.float64(1.0)
            active[s] = 1
        else:
            residual[s] = wp.float64(0.0)
            active[s] = 0


@wp.kernel(enable_backward=False, module=MODULE)
def cg_iterate(disc_start: wp.array(dtype=wp.int32), n_total: int,
               block_start: wp.array(dtype=wp.int32), row_end: wp.array(dtype=wp.int32),
               block_disc: wp.array(dtype=wp.int32),
               block_value: wp.array(dtype=mat33), inverse_diagonal: wp.array(dtype=mat33),
               tolerance2: wp.float64, x: wp.array(dtype=vec3), r: wp.array(dtype=vec3),
               z: wp.array(dtype=vec3), p: wp.array(dtype=vec3), q: wp.array(dtype=vec3),
               rhs_norm2: wp.array(dtype=wp.float64), rz: wp.array(dtype=wp.float64),
               beta: wp.array(dtype=wp.float64), residual: wp.array(dtype=wp.float64),
               iterations: wp.array(dtype=wp.int32), active: wp.array(dtype=wp.int32),
               failed: wp.array(dtype=wp.int32)):
    """One CG iteration of every active system (q = A p, α, x, r, z = M⁻¹r, β): a system
    whose residual reaches the tolerance, or that breaks down, becomes inactive."""
    s, lane = wp.tid()
    if active[s] == 0:  # the same for every thread of the block
        return
    width = wp.block_dim()
    rve = s // 3
    offset = (s - 3 * rve) * n_total
    first = disc_start[rve]
    last = disc_start[rve + 1]
    rz_old = rz[s]
    acc_pq = wp.float64(0.0)
    k = first + lane
    while k < last:
        qv = _bsr_row(block_start, row_end, block_disc, block_value, p, offset, k)
        q[offset + k] = qv
        acc_pq += wp.dot(p[offset + k], qv)
        k += width
    pq = wp.tile_extract(wp.tile_sum(wp.tile(acc_pq)), 0)
    alpha = rz_old / pq
    acc_rz = wp.float64(0.0)
    acc_rr = wp.float64(0.0)
    k = first + lane
    while k < last:
        i = offset + k
        x[i] = x[i] + alpha * p[i]
        rv = r[i] - alpha * q[i]
        zv = inverse_diagonal[k] * rv
        r[i] = rv
        z[i] = zv
        acc_rz += wp.dot(rv, zv)
        acc_rr += wp.dot(rv, rv)
        k += width
    rz_new = wp.tile_extract(wp.tile_sum(wp.tile(acc_rz)), 0)
    rr = wp.tile_extract(wp.tile_sum(wp.tile(acc_rr)), 0)
    if lane == 0:
        iterations[s] = iterations[s] + 1
        residual[s] = wp.sqrt(rr / rhs_norm2[s])
        beta[s] = rz_new / rz_old
        rz[s] = rz_new
        if not (pq > wp.float64(0.0)) or not wp.isfinite(rr):
            failed[s] = 1
            active[s] = 0
        elif rr <= tolerance2 * rhs_norm2[s]:
            active[s] = 0


@wp.kernel(enable_backward=False, module=MODULE)
def cg_direction(disc_rve: wp.array(dtype=wp.int32), n_total: int,
                 active: wp.array(dtype=wp.int32), beta: wp.array(dtype=wp.float64),
                 z: wp.array(dtype=vec3), p: wp.array(dtype=vec3)):
    """p = z + β p of every active system, one thread per (column, disc)."""
    i = wp.tid()
    column = i // n_total
    s = 3 * disc_rve[i - column * n_total] + column
    if active[s] != 0:
        p[i] = z[i] + beta[s] * p[i]


@wp.kernel(enable_backward=False, module=MODULE)
def load_products(disc_start: wp.array(dtype=wp.int32), n_total: int,
                  load: wp.array(dtype=vec3), x: wp.array(dtype=vec3),
                  product: wp.array(dtype=wp.float64)):
    """product[12·rve + 3·g + c] = (row g of K_Gu) · (solution column c), one block each."""
    t, lane = wp.tid()
    width = wp.block_dim()
    rve = t // 12
    g = (t - 12 * rve) // 3
    c = t - 12 * rve - 3 * g
    acc = wp.float64(0.0)
    k = disc_start[rve] + lane
    while k < disc_start[rve + 1]:
        acc += wp.dot(load[g * n_total + k], x[c * n_total + k])
        k += width
    total = wp.tile_extract(wp.tile_sum(wp.tile(acc)), 0)
    if lane == 0:
        product[t] = total


def kernel_modules() -> dict[str, wp.Module]:
    """The warp module of this file by name (for an ahead-of-time compile)."""
    return {MODULE: cg_iterate.module}
