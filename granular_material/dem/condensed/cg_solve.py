"""The condensed tangent's batched CG on a device, host side (issue 26): the systems as the
CG kernels of :mod:`~granular_material.dem.condensed.cg_kernels` read them
(:class:`DeviceSystem`), their launches (:func:`solve_on_device`: the host only checks
every ``check_every`` iterations whether any system is still active), the result
(:class:`CondensedTangentCG`) and the checks of its convergence, shared by the host-assembled
path (:mod:`~granular_material.dem.condensed.cg`) and the device-assembled one
(:mod:`~granular_material.dem.condensed.device`)."""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np
import warp as wp

from granular_material.dem.condensed.cg_kernels import (
    cg_direction,
    cg_iterate,
    cg_start,
    load_products,
    vec3,
)
from granular_material.dem.condensed.tangent import CondensedTangent

__all__ = [
    "BLOCK_DIM",
    "N_SOLVE",
    "CGFallbackWarning",
    "CGNotConvergedError",
    "CondensedTangentCG",
    "DeviceSystem",
    "solve_on_device",
]

N_SOLVE = 3  #: solution columns per RVE: G_00, sym(G_01), G_11
#: which solution column each macro component G_kl (index 2k + l) takes
_COLUMN_OF = np.array([0, 1, 1, 2])
BLOCK_DIM = 128  #: threads per system on CUDA (the CPU runs one)
_CPU_LOCK = threading.Lock()  # a CPU tile module must not run on two threads at once


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
