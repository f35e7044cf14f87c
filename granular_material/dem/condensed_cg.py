"""The condensed tangent's linear solves as a batched preconditioned conjugate gradient on
warp, on any device (issue 26): on CUDA the fluctuations' solves stay on the device.

Per RVE the system is the one :func:`granular_material.dem.condensed.condensed_tangent`
factorises (``condensed._reduced_system``: the same contact network, the same discs left
out, the same regularisation of every solved unknown by ``regularization`` times the mean
diagonal stiffness), with ``sliding="free"`` or ``"stick"`` (K_uu symmetric positive
definite; the non-symmetric ``"coulomb"`` variant needs the direct solver). It is laid out
per kept disc as a block-sparse (BSR, 3 × 3 blocks over u_x, u_y, w = r·θ) matrix in flat
arrays over the batch; the fixed translation of the network's first disc is an identity row
and column (those two unknowns start at zero and never move, the same solution as leaving
them out).

Right-hand sides: the columns G_00 and G_11 of K_uG and the symmetric part of G_01 and G_10
(a spin loads nothing, K_uG·W = 0: both share that solution), three systems per RVE. Each
(RVE, column) is one block of work (``wp.launch_tiled``: on CUDA a thread block per system
whose threads share the discs, with the dot products reduced over the block; on the CPU a
single lane) running a block-Jacobi-preconditioned CG (the inverse of each disc's 3 × 3
diagonal block); a system stops at its own relative residual ‖r‖₂/‖b‖₂ ≤ ``tolerance``
(the recursively updated residual), the others go on. The host only checks every
``check_every`` iterations whether any system is still active. Then

    C = (K_GG − K_Gu X) / V        [Pa]

with the products K_Gu X reduced on the device as well.

Here the assembly (the contact network, the per-contact stiffness blocks) is the scipy
path's, on the host, from an :class:`RVEData` (``DEMBatch.to_data``); only the solves and
the products K_Gu X run on the device. A float64 batch can assemble the same systems on its
own device instead (:mod:`granular_material.dem.condensed_device`, through
:func:`solve_on_device`), which the DEM material does on CUDA.
float64 only: a relative residual of 1e-10 is below float32's resolution.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import warp as wp

from granular_material.dem.condensed import (
    SLIDING_TOLERANCE,
    SYMMETRIC_SLIDING,
    CondensedTangent,
    _check_sliding,
    _counters,
    _reduced_system,
    _selected,
    contact_network,
)
from granular_material.dem.rve_file import RVEData

__all__ = [
    "CGFallbackWarning",
    "CGNotConvergedError",
    "CondensedTangentCG",
    "condensed_tangent_cg",
    "kernel_modules",
]

MODULE = "granular_material_dem_condensed_cg"  #: the warp module of the kernels below
N_SOLVE = 3  #: solution columns per RVE: G_00, sym(G_01), G_11
#: which solution column each macro component G_kl (index 2k + l) takes
_COLUMN_OF = np.array([0, 1, 1, 2])
BLOCK_DIM = 128  #: threads per system on CUDA (the CPU runs one)
_CPU_LOCK = threading.Lock()  # a CPU tile module must not run on two threads at once

vec3 = wp.vec3d
mat33 = wp.mat33d


class CGNotConvergedError(RuntimeError):
    """Some RVEs' CG did not reach the tolerance within the iteration cap (or broke down)."""


class CGFallbackWarning(RuntimeWarning):
    """Some RVEs' CG did not converge and their tangents were taken from the host's LU."""


@dataclass(frozen=True)
class CondensedTangentCG(CondensedTangent):
    """:class:`CondensedTangent` of the CG path, with its convergence.

    Attributes:
        iterations: CG iterations of each RVE's three systems (G_00, sym G_01, G_11),
            (B, 3).
        residual: their final relative residuals ‖r‖/‖b‖ (0 where b = 0), (B, 3).
        converged: whether all three reached the tolerance, (B,); where not (returned only
            with ``raise_unconverged=False``) the RVE's tangent is the CG's last iterate's.
        assembly_seconds: the batch's assembly on the host [s].
        solve_seconds: the batch's solve on the device, transfers included [s].
    """

    iterations: np.ndarray
    residual: np.ndarray
    converged: np.ndarray
    assembly_seconds: float = 0.0
    solve_seconds: float = 0.0


# -- kernels ------------------------------------------------------------------------------------
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


# -- host side ----------------------------------------------------------------------------------
@dataclass
class _Blocks:
    """One RVE's system per kept disc: BSR of K_uu (identity at the fixed translation), the
    inverse diagonal blocks, the solve's right-hand sides and K_Gu's rows."""

    start: np.ndarray  # (nk + 1,)
    disc: np.ndarray  # (nnzb,)
    value: np.ndarray  # (nnzb, 3, 3)
    inverse_diagonal: np.ndarray  # (nk, 3, 3)
    rhs: np.ndarray  # (3, nk, 3)
    load: np.ndarray  # (4, nk, 3)


def _blocks(system) -> _Blocks:
    """The reduced system of ``condensed._reduced_system`` over the kept discs, 3 × 3."""
    kept, free = system.kept, system.free
    n_kept = int(kept.sum()) if system.k_uu is not None else 0
    if n_kept == 0:
        return _Blocks(np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros((0, 3, 3)),
                       np.zeros((0, 3, 3)), np.zeros((N_SOLVE, 0, 3)), np.zeros((4, 0, 3)))
    kept_index = np.cumsum(kept) - 1
    full = (3 * kept_index[:, None] + np.arange(3)).ravel()  # of each of the 3N unknowns
    solved = full[free]  # the full index of each reduced unknown
    fixed = full[np.repeat(kept, 3) & ~free]
    k_uu = system.k_uu.tocoo()
    size = 3 * n_kept
    matrix = sp.coo_matrix(
        (np.concatenate([k_uu.data, np.ones(len(fixed))]),
         (np.concatenate([solved[k_uu.row], fixed]), np.concatenate([solved[k_uu.col], fixed]))),
        shape=(size, size)).tocsr().tobsr(blocksize=(3, 3))
    matrix.sort_indices()
    row = np.repeat(np.arange(n_kept), np.diff(matrix.indptr))
    on_diagonal = matrix.indices == row
    assert on_diagonal.sum() == n_kept
    inverse = np.linalg.inv(matrix.data[on_diagonal])
    k_ug = np.zeros((size, 4))
    k_ug[solved] = system.k_ug
    k_gu = np.zeros((4, size))
    k_gu[:, solved] = system.k_gu
    rhs = np.stack([k_ug[:, 0], 0.5 * (k_ug[:, 1] + k_ug[:, 2]), k_ug[:, 3]])
    return _Blocks(matrix.indptr, matrix.indices, matrix.data, inverse,
                   rhs.reshape(N_SOLVE, n_kept, 3), k_gu.reshape(4, n_kept, 3))


def _check_tolerance(tolerance: float) -> None:
    """Raise ValueError unless the CG's relative tolerance is a number > 0."""
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance must be a number > 0, got {tolerance!r}")


def _iteration_cap(max_iterations: int | None, unknowns: np.ndarray) -> int:
    """``max_iterations``, or by default 4 × the most unknowns of an RVE, at least 1000."""
    if max_iterations is not None:
        return max_iterations
    return max(1000, 4 * int(unknowns.max(initial=0)))


def _converged_or_raise(index: np.ndarray, failed: np.ndarray, active: np.ndarray,
                        residual: np.ndarray, tolerance: float, max_iterations: int,
                        raise_unconverged: bool) -> np.ndarray:
    """Which RVEs ``index`` converged (B,): none of their systems (rows of the (B, 3) flags)
    broke down or is still active; with ``raise_unconverged``, :class:`CGNotConvergedError`
    naming those that did not."""
    converged = ~(failed.any(axis=1) | active.any(axis=1))
    if raise_unconverged:
        _raise_unless_converged(index, converged, residual, tolerance, max_iterations)
    return converged


def _raise_unless_converged(index: np.ndarray, converged: np.ndarray, residual: np.ndarray,
                            tolerance: float, max_iterations: int | np.ndarray) -> None:
    """:class:`CGNotConvergedError` naming the RVEs ``index`` that did not converge;
    ``max_iterations``: the iteration cap they ran under, one for all or one per RVE (B,)."""
    bad = np.flatnonzero(~converged)
    if len(bad):
        caps = np.unique(np.broadcast_to(np.asarray(max_iterations), converged.shape)[bad])
        within = (f"{caps[0]} iterations" if len(caps) == 1
                  else f"their caps of {caps.tolist()} iterations")
        raise CGNotConvergedError(
            f"condensed tangent: CG did not reach ‖r‖/‖b‖ <= {tolerance:g} within {within} "
            f"(or broke down) for RVEs {index[bad].tolist()} "
            f"(relative residuals {residual[bad].max(axis=1).tolist()})")


def condensed_tangent_cg(data: RVEData, rves: np.ndarray | None = None, device: str = "cpu",
                         tolerance: float = 1e-10, max_iterations: int | None = None,
                         regularization: float = 1e-9,
                         cap_tolerance: float = SLIDING_TOLERANCE,
                         check_every: int = 32, sliding: str = "free",
                         raise_unconverged: bool = True) -> CondensedTangentCG:
    """The condensed tangent C [Pa] (B, 2, 2, 2, 2) of every RVE of ``data`` (or of the
    indices ``rves``), as :func:`condensed.condensed_tangent` with ``sliding`` ("free" or
    "stick"), its solves by a batched block-Jacobi CG on the warp ``device`` (module
    docstring).

    ``tolerance``: relative residual ‖r‖/‖b‖ at which each system stops. ``max_iterations``
    (default 4 × the largest number of unknowns of an RVE, at least 1000): past it, or on a
    breakdown, :class:`CGNotConvergedError` names the RVEs (with ``raise_unconverged=False``
    the result says which in ``converged`` instead). ``check_every``: iterations
    launched between the host's checks for active systems. ``seconds`` is each RVE's
    assembly plus an equal share of the batch's solve [s]; ``assembly_seconds`` and
    ``solve_seconds`` split the batch's between the two."""
    _check_tolerance(tolerance)
    _check_sliding(sliding, SYMMETRIC_SLIDING)
    index = _selected(data.n_rve, rves, regularization)
    count = len(index)
    affine, affine_all = np.zeros((count, 4, 4)), np.zeros((count, 4, 4))
    volume = np.zeros(count)
    n_contacts, n_sliding, n_left_out, n_unknowns, seconds = _counters(count)
    parts = []
    for slot, rve in enumerate(index):
        start = time.perf_counter()
        net = contact_network(data, int(rve), cap_tolerance)
        system = _reduced_system(net, sliding, regularization)
        parts.append(_blocks(system))
        affine[slot], affine_all[slot] = system.affine, system.affine_all
        volume[slot] = net.volume
        n_left_out[slot] = system.left_out
        n_unknowns[slot] = 0 if system.k_uu is None else system.k_uu.shape[0]
        n_contacts[slot], n_sliding[slot] = len(net.a), int(net.sliding.sum())
        seconds[slot] = time.perf_counter() - start
    max_iterations = _iteration_cap(max_iterations, n_unknowns)
    start = time.perf_counter()
    product, iterations, residual, failed, active = _solve(parts, device, tolerance,
                                                           max_iterations, check_every)
    solve_seconds = time.perf_counter() - start
    seconds += solve_seconds / max(count, 1)
    converged = _converged_or_raise(index, failed, active, residual, tolerance,
                                    max_iterations, raise_unconverged)
    # C = (K_GG − K_Gu X) / V, X's columns per G_kl
    condensed = affine - product[:, :, _COLUMN_OF]
    tangent = condensed / volume[:, None, None]
    return CondensedTangentCG(
        tangent=tangent.reshape(count, 2, 2, 2, 2),
        affine=(affine_all / volume[:, None, None]).reshape(count, 2, 2, 2, 2),
        n_contacts=n_contacts, n_sliding=n_sliding, n_left_out=n_left_out,
        n_unknowns=n_unknowns, seconds=seconds, iterations=iterations, residual=residual,
        converged=converged, assembly_seconds=float(seconds.sum() - solve_seconds),
        solve_seconds=solve_seconds,
    )


def _solve(parts: list[_Blocks], device: str, tolerance: float, max_iterations: int,
           check_every: int) -> tuple[np.ndarray, ...]:
    """The batched CG of ``parts`` on ``device``: K_Gu X (B, 4, 3), iterations, residuals,
    breakdowns and still-active flags (B, 3)."""
    count = len(parts)
    n_kept = np.array([len(p.inverse_diagonal) for p in parts], dtype=np.int64)
    disc_start = np.concatenate([[0], np.cumsum(n_kept)])
    n_total = int(disc_start[-1])
    block_count = np.array([len(p.disc) for p in parts], dtype=np.int64)
    block_offset = np.concatenate([[0], np.cumsum(block_count)])
    block_start = np.concatenate(
        [p.start[:-1] + block_offset[b] for b, p in enumerate(parts)] + [[block_offset[-1]]])
    block_disc = np.concatenate([p.disc + disc_start[b] for b, p in enumerate(parts)])
    block_value = np.concatenate([p.value for p in parts])
    inverse_diagonal = np.concatenate([p.inverse_diagonal for p in parts])
    rhs = np.concatenate([p.rhs for p in parts], axis=1)  # (3, n_total, 3)
    load = np.concatenate([p.load for p in parts], axis=1)  # (4, n_total, 3)
    disc_rve = np.repeat(np.arange(count), n_kept)
    if n_total == 0 or count == 0:
        zeros = np.zeros((count, N_SOLVE))
        return (np.zeros((count, 4, N_SOLVE)), zeros.astype(np.int64), zeros,
                zeros.astype(bool), zeros.astype(bool))

    def int_array(values: np.ndarray) -> wp.array:
        return wp.array(np.ascontiguousarray(values, dtype=np.int32), dtype=wp.int32,
                        device=device)

    def vectors(values: np.ndarray) -> wp.array:
        return wp.array(np.ascontiguousarray(values.reshape(-1, 3), dtype=np.float64),
                        dtype=vec3, device=device)

    def matrices(values: np.ndarray) -> wp.array:
        return wp.array(np.ascontiguousarray(values, dtype=np.float64), dtype=mat33,
                        device=device)

    lock = _CPU_LOCK if wp.get_device(device).is_cpu else _NoLock()
    with lock, wp.ScopedDevice(device):
        system = DeviceSystem(
            disc_start=int_array(disc_start), disc_rve=int_array(disc_rve),
            block_start=int_array(block_start[:-1]), row_end=int_array(block_start[1:]),
            block_disc=int_array(block_disc),
            block_value=matrices(block_value), inverse_diagonal=matrices(inverse_diagonal),
            rhs=vectors(rhs), load=vectors(load), count=count, n_total=n_total)
        return solve_on_device(system, device, tolerance, max_iterations, check_every)


@dataclass
class DeviceSystem:
    """The batched systems on the device, as the CG kernels read them: per RVE its discs
    ``disc_start[b] : disc_start[b + 1]`` (and each disc's RVE), per disc its row of 3 × 3
    blocks ``block_start[k] : row_end[k]`` (columns ``block_disc``, values
    ``block_value`` [N/m]), the inverse diagonal blocks, the right-hand sides (3 columns,
    ``3 · n_total`` vec3) and K_Gu's rows (4 rows, ``4 · n_total`` vec3)."""

    disc_start: wp.array
    disc_rve: wp.array
    block_start: wp.array
    row_end: wp.array
    block_disc: wp.array
    block_value: wp.array
    inverse_diagonal: wp.array
    rhs: wp.array
    load: wp.array
    count: int
    n_total: int


def solve_on_device(system: DeviceSystem, device: str, tolerance: float, max_iterations: int,
                    check_every: int) -> tuple[np.ndarray, ...]:
    """The batched CG of ``system`` on ``device`` (the caller holds the CPU module's lock):
    K_Gu X (B, 4, 3), iterations, residuals, breakdowns and still-active flags (B, 3)."""
    count, n_total = system.count, system.n_total
    n_system = N_SOLVE * count
    block_dim = BLOCK_DIM if wp.get_device(device).is_cuda else 1
    with wp.ScopedDevice(device):
        x, r, z, p, q = (wp.zeros(N_SOLVE * n_total, dtype=vec3) for _ in range(5))
        rhs_norm2, rz, beta, residual = (wp.zeros(n_system, dtype=wp.float64)
                                         for _ in range(4))
        iterations, active, failed = (wp.zeros(n_system, dtype=wp.int32) for _ in range(3))
        wp.launch_tiled(cg_start, dim=[n_system], block_dim=block_dim,
                        inputs=[system.disc_start, n_total, system.inverse_diagonal,
                                system.rhs, x, r, z, p, rhs_norm2, rz, residual, iterations,
                                active])
        done = 0
        tolerance2 = wp.float64(tolerance * tolerance)
        while done < max_iterations and active.numpy().any():
            for _ in range(min(check_every, max_iterations - done)):
                wp.launch_tiled(cg_iterate, dim=[n_system], block_dim=block_dim,
                                inputs=[system.disc_start, n_total, system.block_start,
                                        system.row_end,
                                        system.block_disc, system.block_value,
                                        system.inverse_diagonal, tolerance2, x, r, z, p, q,
                                        rhs_norm2, rz, beta, residual, iterations, active,
                                        failed])
                wp.launch(cg_direction, dim=N_SOLVE * n_total,
                          inputs=[system.disc_rve, n_total, active, beta, z, p])
                done += 1
        product = wp.zeros(12 * count, dtype=wp.float64)
        wp.launch_tiled(load_products, dim=[12 * count], block_dim=block_dim,
                        inputs=[system.disc_start, n_total, system.load, x, product])
        shape = (count, N_SOLVE)
        return (product.numpy().reshape(count, 4, N_SOLVE),
                iterations.numpy().reshape(shape).astype(np.int64),
                residual.numpy().reshape(shape), failed.numpy().reshape(shape) != 0,
                active.numpy().reshape(shape) != 0)


class _NoLock:
    """A context manager that does nothing (CUDA streams need no lock)."""

    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None
