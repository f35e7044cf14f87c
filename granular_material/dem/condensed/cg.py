"""The condensed tangent's linear solves as a batched preconditioned conjugate gradient on
warp, on any device (issue 26): on CUDA the fluctuations' solves stay on the device.

Per RVE the system is the one :func:`granular_material.dem.condensed.tangent.condensed_tangent`
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
own device instead (:mod:`granular_material.dem.condensed.device`, through
:func:`solve_on_device`), which the DEM material does on CUDA.
float64 only: a relative residual of 1e-10 is below float32's resolution.

This module assembles the systems on the host and hands them to the batched CG; the CG's
kernels are :mod:`~granular_material.dem.condensed.cg_kernels`', its launches, result type
and convergence checks :mod:`~granular_material.dem.condensed.cg_solve`'s (their names
importable from here as well).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import warp as wp

from granular_material.dem.condensed.cg_kernels import MODULE as MODULE
from granular_material.dem.condensed.cg_kernels import cg_direction as cg_direction
from granular_material.dem.condensed.cg_kernels import cg_iterate as cg_iterate
from granular_material.dem.condensed.cg_kernels import cg_start as cg_start
from granular_material.dem.condensed.cg_kernels import kernel_modules, mat33, vec3
from granular_material.dem.condensed.cg_kernels import load_products as load_products
from granular_material.dem.condensed.cg_solve import (
    _COLUMN_OF,
    _CPU_LOCK,
    N_SOLVE,
    CGFallbackWarning,
    CGNotConvergedError,
    CondensedTangentCG,
    DeviceSystem,
    _check_tolerance,
    _converged_or_raise,
    _iteration_cap,
    _NoLock,
    solve_on_device,
)
from granular_material.dem.condensed.cg_solve import BLOCK_DIM as BLOCK_DIM
from granular_material.dem.condensed.cg_solve import (
    _raise_unless_converged as _raise_unless_converged,
)
from granular_material.dem.condensed.tangent import (
    SLIDING_TOLERANCE,
    SYMMETRIC_SLIDING,
    _check_sliding,
    _counters,
    _reduced_system,
    _selected,
    contact_network,
)
from granular_material.dem.rve.file import RVEData

__all__ = [
    "CGFallbackWarning",
    "CGNotConvergedError",
    "CondensedTangentCG",
    "condensed_tangent_cg",
    "kernel_modules",
]


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
