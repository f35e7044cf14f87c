"""The condensed tangent of a batch's current state, assembled and solved on its own device
(issue 26: on CUDA nothing leaves the device but the 4 × 4 tangents).

:func:`granular_material.dem.condensed.cg.condensed_tangent_cg` builds each RVE's system on
the host from an :class:`RVEData` copy of the batch, RVE by RVE: on an H200 that assembly
took 2.4 s for 600 RVEs of 400 discs against 0.16 s for the CG itself (docs/performance.md,
"On an H200"). Here the same systems are assembled by kernels from the engine's own arrays
(fractional positions, cell, radii, neighbour slots, tangential springs and their mirror
slots), then solved by the same CG kernels
(:func:`~granular_material.dem.condensed.cg_solve.solve_on_device`).

The assembly kernels, one thread a slot, disc or RVE, are
:mod:`~granular_material.dem.condensed.device_kernels`' (their names importable from here as
well). float64 batches only; a float32 batch takes the host assembly.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Any

import numpy as np
import warp as wp

from granular_material.dem.condensed.cg_solve import (
    _COLUMN_OF,
    _CPU_LOCK,
    CondensedTangentCG,
    DeviceSystem,
    _check_tolerance,
    _converged_or_raise,
    _iteration_cap,
    _NoLock,
    _raise_unless_converged,
    solve_on_device,
)
from granular_material.dem.condensed.device_kernels import MODULE as MODULE
from granular_material.dem.condensed.device_kernels import (
    Network,
    assemble_rows,
    drop_weak_discs,
    first_kept_disc,
    kernel_modules,
    mat33,
    mat44,
    regularize,
    rve_sums,
    slot_contacts,
    vec2,
    vec3,
)
from granular_material.dem.condensed.device_kernels import mat22 as mat22
from granular_material.dem.condensed.device_kernels import vec4 as vec4
from granular_material.dem.condensed.tangent import (
    SLIDING_TOLERANCE,
    SYMMETRIC_SLIDING,
    _check_sliding,
    _selected,
)

if TYPE_CHECKING:
    from granular_material.dem.batch import DEMBatch
    from granular_material.dem.model import Model
    from granular_material.dem.state import State

__all__ = [
    "Network",
    "condensed_tangent_of_batch",
    "condensed_tangent_on_device",
    "kernel_modules",
]


def condensed_tangent_on_device(model: Model, state: State, rves: np.ndarray | None = None,
                                tolerance: float = 1e-10, max_iterations: int | None = None,
                                regularization: float = 1e-9,
                                cap_tolerance: float = SLIDING_TOLERANCE,
                                check_every: int = 32,
                                sliding: str = "free",
                                raise_unconverged: bool = True) -> CondensedTangentCG:
    """The condensed tangent C [Pa] (B, 2, 2, 2, 2) of the RVEs ``rves`` (default all) of
    one shard's ``model`` and ``state`` (float64), as
    :func:`~granular_material.dem.condensed.cg.condensed_tangent_cg` gives it for
    ``state_to_data(model, state)``, with its systems assembled on the shard's device (module
    docstring); the arguments are that function's.
    ``assembly_seconds`` is the assembly's, ``solve_seconds`` the CG's [s]."""
    if model.dtype != "float64":
        raise ValueError(f"the device assembly reads float64 states, got {model.dtype}")
    _check_tolerance(tolerance)
    _check_sliding(sliding, SYMMETRIC_SLIDING)
    free_slip = 1 if sliding == "free" else 0
    n_rve, n_disc, capacity = model.n_rve, model.n_disc, model.capacity
    index = _selected(n_rve, rves, regularization)
    count = len(index)
    device = model.device
    lock = _CPU_LOCK if wp.get_device(device).is_cpu else _NoLock()
    start = time.perf_counter()
    with lock, wp.ScopedDevice(device):
        chosen = np.zeros(n_rve, dtype=np.int32)
        chosen[index] = 1
        selected = wp.array(chosen, dtype=wp.int32)
        radius = wp.array(np.ascontiguousarray(model.radius, dtype=np.float64).ravel(),
                          dtype=wp.float64)
        n_slot, n_total = n_rve * n_disc * capacity, n_rve * n_disc
        touching, at_cap = (wp.zeros(n_slot, dtype=wp.int32) for _ in range(2))
        branch = wp.zeros(n_slot, dtype=vec2)
        kn, kt = (wp.zeros(n_slot, dtype=wp.float64) for _ in range(2))
        wp.launch(slot_contacts, dim=n_slot, inputs=[
            n_disc, capacity, selected, state.fractional_position, state.cell, radius,
            state.contact_partner, state.contact_count, state.contact_shear_force,
            state.contact_mirror_slot, model.law,
            wp.float64(math.tan(model.meta.friction_angle)), wp.float64(cap_tolerance),
            free_slip], outputs=[touching, at_cap, branch, kn, kt])
        kept = wp.array(np.repeat(chosen, n_disc), dtype=wp.int32)
        kept_next = wp.zeros(n_total, dtype=wp.int32)
        changed = wp.zeros(1, dtype=wp.int32)
        while True:  # leave out discs of fewer than two contacts until none drops
            changed.zero_()
            wp.launch(drop_weak_discs, dim=n_total, inputs=[
                n_disc, capacity, state.contact_partner, state.contact_count, touching,
                kept, kept_next, changed])
            kept, kept_next = kept_next, kept
            if not changed.numpy()[0]:
                break
        first_kept = wp.zeros(n_rve, dtype=wp.int32)
        wp.launch(first_kept_disc, dim=n_rve, inputs=[n_disc, kept, first_kept])
        blocks = n_total * (capacity + 1)
        row_end = wp.zeros(n_total, dtype=wp.int32)
        block_disc = wp.zeros(blocks, dtype=wp.int32)
        block_value = wp.zeros(blocks, dtype=mat33)
        rhs = wp.zeros(3 * n_total, dtype=vec3)
        load = wp.zeros(4 * n_total, dtype=vec3)
        diagonal_stiffness = wp.zeros(n_total, dtype=vec3)
        net = Network()
        net.partner, net.count = state.contact_partner, state.contact_count
        net.radius, net.touching, net.sliding = radius, touching, at_cap
        net.branch, net.kn, net.kt, net.kept = branch, kn, kt, kept
        wp.launch(assemble_rows, dim=n_total, inputs=[n_disc, capacity, net, first_kept],
                  outputs=[row_end, block_disc, block_value, rhs, load, diagonal_stiffness])
        scale = wp.zeros(n_rve, dtype=wp.float64)
        affine, affine_all = (wp.zeros(n_rve, dtype=mat44) for _ in range(2))
        counters = wp.zeros(4 * n_rve, dtype=wp.int32)
        wp.launch(rve_sums, dim=n_rve, inputs=[n_disc, capacity, net, diagonal_stiffness],
                  outputs=[scale, affine, affine_all, counters])
        inverse = wp.zeros(n_total, dtype=mat33)
        wp.launch(regularize, dim=n_total, inputs=[
            n_disc, capacity, wp.float64(regularization), first_kept, kept, scale,
            block_value, inverse])
        system = DeviceSystem(
            disc_start=wp.array(np.arange(n_rve + 1, dtype=np.int32) * n_disc,
                                dtype=wp.int32),
            disc_rve=wp.array(np.repeat(np.arange(n_rve, dtype=np.int32), n_disc),
                              dtype=wp.int32),
            block_start=wp.array(np.arange(n_total, dtype=np.int32) * (capacity + 1),
                                 dtype=wp.int32),
            row_end=row_end, block_disc=block_disc, block_value=block_value,
            inverse_diagonal=inverse, rhs=rhs, load=load, count=n_rve, n_total=n_total)
        tallies = counters.numpy().reshape(n_rve, 4)[index].astype(np.int64)
        max_iterations = _iteration_cap(max_iterations, tallies[:, 3])
        wp.synchronize_device(device)
        assembled = time.perf_counter()
        product, iterations, residual, failed, active = solve_on_device(
            system, device, tolerance, max_iterations, check_every)
        k_gg = affine.numpy()[index]
        k_gg_all = affine_all.numpy()[index]
        cells = state.cell.numpy()[index]
    solved = time.perf_counter()
    product, iterations, residual = product[index], iterations[index], residual[index]
    converged = _converged_or_raise(index, failed[index], active[index], residual, tolerance,
                                    max_iterations, raise_unconverged)
    volume = (np.linalg.det(cells) * model.meta.thickness)[:, None, None]
    tangent = (k_gg - product[:, :, _COLUMN_OF]) / volume
    return CondensedTangentCG(
        tangent=tangent.reshape(count, 2, 2, 2, 2),
        affine=(k_gg_all / volume).reshape(count, 2, 2, 2, 2),
        n_contacts=tallies[:, 0], n_sliding=tallies[:, 1], n_left_out=tallies[:, 2],
        n_unknowns=tallies[:, 3], seconds=np.full(count, (solved - start) / max(count, 1)),
        iterations=iterations, residual=residual, converged=converged,
        assembly_seconds=assembled - start,
        solve_seconds=solved - assembled,
    )


def condensed_tangent_of_batch(batch: DEMBatch, rves: np.ndarray | None = None,
                               **options: Any) -> CondensedTangentCG:
    """:func:`condensed_tangent_on_device` of the RVEs ``rves`` (distinct batch indices,
    default all) of a float64 :class:`~granular_material.dem.batch.DEMBatch`, shard by
    shard, returned in the order of ``rves``; ``options`` are that function's (an
    unconverged RVE is named by its index in the batch)."""
    index = _selected(batch.n_rve, rves, options.get("regularization", 1e-9))
    raise_unconverged = options.pop("raise_unconverged", True)
    parts, order = [], []
    for shard in batch.shards:
        inside = index[(index >= shard.first) & (index < shard.first + shard.model.n_rve)]
        if len(inside):
            parts.append(condensed_tangent_on_device(shard.model, shard.state,
                                                     rves=inside - shard.first,
                                                     raise_unconverged=False, **options))
            order.append(inside)
    if not parts:  # nothing asked for: nothing launched
        none = np.zeros(0, dtype=np.int64)
        return CondensedTangentCG(
            tangent=np.zeros((0, 2, 2, 2, 2)), affine=np.zeros((0, 2, 2, 2, 2)),
            n_contacts=none, n_sliding=none, n_left_out=none, n_unknowns=none,
            seconds=np.zeros(0), iterations=np.zeros((0, 3), dtype=np.int64),
            residual=np.zeros((0, 3)), converged=np.zeros(0, dtype=bool))
    where = {int(rve): k for k, rve in enumerate(np.concatenate(order))}
    wanted = np.array([where[int(rve)] for rve in index], dtype=int)  # rves' order

    def joined(name: str) -> np.ndarray:
        return np.concatenate([getattr(p, name) for p in parts])[wanted]

    result = CondensedTangentCG(
        **{name: joined(name) for name in (
            "tangent", "affine", "n_contacts", "n_sliding", "n_left_out", "n_unknowns",
            "seconds", "iterations", "residual", "converged")},
        assembly_seconds=sum(p.assembly_seconds for p in parts),
        solve_seconds=sum(p.solve_seconds for p in parts))
    if raise_unconverged:  # each shard ran under the cap of its own RVEs
        caps = np.concatenate([np.full(len(p.n_unknowns), _iteration_cap(
            options.get("max_iterations"), p.n_unknowns)) for p in parts])[wanted]
        _raise_unless_converged(index, result.converged, result.residual,
                                options.get("tolerance", 1e-10), caps)
    return result
