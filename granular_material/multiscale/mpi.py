"""The MPI backend of the DEM material: contiguous shards of the RVEs on the ranks of a job.

Rank 0 runs the program (the FEM, Newton, every file written and every line printed). Every
rank, rank 0 included, owns a contiguous shard of the Gauss points' RVEs, points
``start:stop`` (:func:`shard_bounds`), as an
:class:`~granular_material.multiscale.backend.InProcessBackend` of its own on its own device:
CUDA device ``local_rank % n_gpus`` (ranks numbered within their node), or the CPU with the
node's cores shared among its ranks. The other ranks run :func:`serve`: they wait for rank
0's commands and answer them. :func:`launch` starts both sides and tells the workers to stop
however rank 0's program ends.

One Newton evaluation is one round trip of buffers (no pickling on this path):

========  =========  =====================================================================
command   Bcast      2 int64: the command and its argument
∇u        Scatterv   4 float64 a point (∂u_k/∂x_l, row-major)
header    Gather     ``HEADER`` int64 a rank: error flag, complete flag, drives done, the
                     rank's compute time [ns], then DEM steps, RVE paths and particle-steps
                     of each drive (up to 5: four perturbed runs and the trial), then its
                     time [ns] in each of the backend's phases (DEM, homogenisation, tangent)
rows      Gatherv    ``ROW`` float64 a point: failure code (0: OK, else 1 + the index of
                     its reason in ``FailureReason``), then every field of
                     :class:`~granular_material.dem.Homogenized` flattened in its order
                     (stress 4, tangent 16, void ratio, coordination, fabric 4, unbalanced
                     force, contacts, sliding fraction, volume)
========  =========  =====================================================================

Commit, revert and a held tangent (the Newton driver's ``tangent_update="hold"``: a flag
broadcast, pickled) are per rank, answered by an error flag each; set-up, checkpoints and the
RVEs of tracked points (rare) travel as pickled RVE data. A checkpoint is one RVE file written
by rank 0 (the same file as in process), so a run resumes on any number of ranks or in
process.

Failures: a rank whose work raises catches it and says so in its answer (an error flag, then
its message sent to rank 0); rank 0 raises :class:`MPIRankError` naming the rank and the
error once the exchange is complete, and :func:`launch` then tells every rank to stop. RVEs
that blow up are no error: they are failed points, as in process, and Newton cuts back. MPI
Abort is the last resort, for an exchange left half done.
"""


from __future__ import annotations

import sys
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from granular_material.dem import Homogenized, RVEData, save_rve
from granular_material.multiscale.evaluation import Evaluation
from granular_material.multiscale.mpi_ranks import (
    _EXCHANGES,
    _exchange_evaluate,
    _process_shard,
    _send_command,
    _Shard,
    launch,
    launched,
    serve,
)
from granular_material.multiscale.mpi_wire import (
    _COMPLETE,
    _DRIVES,
    _FIELD_SHAPES,
    _MAX_DRIVES,
    _NANOSECONDS,
    _PHASE_START,
    FAULT_VARIABLE,
    HEADER,
    ROW,
    MPIRankError,
    _Command,
    _critical_phases,
    _signals_held,
    _unpack,
    _wait,
    _world,
    message_bytes,
    shard_bounds,
)
from granular_material.multiscale.parameters import DEMMaterialParameters

__all__ = [
    "FAULT_VARIABLE",
    "HEADER",
    "ROW",
    "ExchangeTiming",
    "MPIBackend",
    "MPIRankError",
    "exchange_time",
    "launch",
    "message_bytes",
    "serve",
    "shard_bounds",
]

def exchange_time(n_points: int, repeats: int = 20) -> float:
    """The messages of one evaluation alone: the median wall time [s], on rank 0, of the
    command, ∇u scattered and the headers and rows gathered for ``n_points`` points shared
    out over the job's ranks, with no RVE behind them (nothing is stepped). Every rank calls
    it, outside :func:`launch`; the others get NaN."""
    world = _world()
    shard = _Shard(world)
    shard.bounds = shard_bounds(n_points, world.size)
    grad_u = np.zeros((n_points, 2, 2)) if world.rank == 0 else None
    message = np.array([int(_Command.EVALUATE), 0], dtype=np.int64)
    times = []
    for _ in range(repeats):
        world.comm.Barrier()
        started = time.perf_counter()
        _wait(world.comm.Ibcast(message, root=0))
        _exchange_evaluate(world, shard, grad_u)
        times.append(time.perf_counter() - started)
    return float(np.median(times)) if world.rank == 0 else float("nan")


# -- rank 0's side ---------------------------------------------------------------------------
@dataclass(frozen=True)
class ExchangeTiming:
    """The clock of one evaluation on rank 0.

    Attributes:
        wall: from the command to the last answer [s].
        compute: each rank's own work on its shard [s], shape (size,).
    """

    wall: float
    compute: np.ndarray

    @property
    def overhead(self) -> float:
        """What the exchange added to the slowest rank's work [s]: communication, packing
        and waiting for the command."""
        return max(self.wall - float(self.compute.max()), 0.0)


class MPIBackend:
    """The RVEs of every rank of an MPI job behind the calls of
    :class:`~granular_material.multiscale.evaluation.DEMBackend`, for rank 0.

    Each rank's shard is an :class:`InProcessBackend` that reuses, drives on (``continue``)
    and commits its own RVEs exactly as the whole batch would in process, so the response
    is the in-process one bit for bit. Build it on rank 0 within :func:`launch` (or in a job
    of one rank).

    Args:
        data: every RVE, one per Gauss point (a checkpoint's, with its ``backend_*``
            arrays, when ``resume``).
        parameters: how the RVEs are driven, their device and CPU threads (per rank).
        resume: ``data`` is a checkpoint (see :meth:`InProcessBackend.resume_from`).
    """

    def __init__(self, data: RVEData, parameters: DEMMaterialParameters,
                 resume: bool = False) -> None:
        self.world = _world()
        if self.world.rank != 0:
            raise RuntimeError(f"the MPI backend is rank 0's; rank {self.world.rank} serves "
                               "its shard (run the program through launch())")
        if self.world.size > 1 and not launched():
            raise RuntimeError("the MPI backend of a job of several ranks needs its workers "
                               "serving: run the program through launch()")
        self.shard = _process_shard()
        self._n_rve = data.n_rve
        #: the clock of every evaluation, in order
        self.timings: list[ExchangeTiming] = []
        self._run(_Command.SETUP, (data.n_rve, parameters, data, resume), "set-up")

    @property
    def n_rve(self) -> int:
        """Number of RVEs B, all ranks together."""
        return self._n_rve

    @property
    def bounds(self) -> np.ndarray:
        """First point of each rank's shard and the end, shape (size + 1,)."""
        return self.shard.bounds.copy()

    def _run(self, command: _Command, payload: Any, what: str) -> Any:
        """One exchange from rank 0: the command, then the exchange on every rank; its
        answers. An exception in the middle of it would leave the workers stranded: then
        the job is aborted."""
        try:
            with _signals_held():
                if self.world.size > 1:
                    _send_command(self.world, command)
                result, errors = _EXCHANGES[command](self.world, self.shard, payload)
        except Exception:
            print(f"granular-material: MPI rank 0 cannot finish the {what} exchange:\n"
                  f"{traceback.format_exc()}", file=sys.stderr, flush=True)
            self.world.comm.Abort(1)
            raise
        if errors:
            raise MPIRankError("; ".join(f"MPI rank {rank} failed in {what}: {message}"
                                         for rank, message in sorted(errors.items())))
        return result

    def evaluate(self, grad_u: np.ndarray) -> Evaluation:
        """Every shard responds to its points' ∇u [-] (B, 2, 2) since the commit (see
        :meth:`InProcessBackend.evaluate`). If a shard's drive blew up, every shard goes
        back to its committed state and the response is NaN, as for one batch."""
        grad_u = np.ascontiguousarray(grad_u, dtype=np.float64)
        if grad_u.shape != (self.n_rve, 2, 2):
            raise ValueError(f"grad_u must have shape ({self.n_rve}, 2, 2), got "
                             f"{grad_u.shape}")
        started = time.perf_counter()
        headers, rows = self._run(_Command.EVALUATE, grad_u, "evaluate")
        self.timings.append(ExchangeTiming(time.perf_counter() - started,
                                           headers[:, _NANOSECONDS] * 1e-9))
        h, failed, reasons = _unpack(rows)
        costs = headers[:, 4:_PHASE_START].reshape(self.world.size, _MAX_DRIVES, 3)
        incomplete = headers[:, _COMPLETE] == 0
        # as one batch: an evaluation ends with the drive that blew up, whose cost is lost
        n_drives = int(headers[incomplete, _DRIVES].min() if incomplete.any()
                       else headers[:, _DRIVES].max())
        drives = tuple((int(costs[:, k, 0].max()), int(costs[:, k, 1].sum()),
                        int(costs[:, k, 2].sum())) for k in range(n_drives))
        totals = [int(sum(d[k] for d in drives)) for k in range(3)]
        if incomplete.any():
            self._run(_Command.REVERT, None, "revert")
            h = Homogenized(**{name: np.full_like(np.asarray(getattr(h, name),
                                                             dtype=np.float64), np.nan)
                               for name in _FIELD_SHAPES})
        return Evaluation(h, failed, *totals, drives=drives, complete=not incomplete.any(),
                          reasons=reasons, timings=_critical_phases(headers))

    def commit(self) -> None:
        """Every shard's state of the last evaluate becomes its committed state."""
        self._run(_Command.COMMIT, None, "commit")

    def revert(self) -> None:
        """Every shard back to its committed state."""
        self._run(_Command.REVERT, None, "revert")

    def hold_tangent(self, hold: bool) -> None:
        """Every shard holds its next evaluation's tangent (``hold``) or stops holding it,
        as :meth:`InProcessBackend.hold_tangent`: one condensation (or one set of perturbed
        drives) an increment on every rank."""
        self._run(_Command.HOLD, bool(hold), "hold")

    def committed_rves(self, rves: np.ndarray | None = None) -> RVEData:
        """The committed RVE states of all points, or of the indices ``rves`` in their
        order, gathered from the ranks that own them."""
        points = None if rves is None else np.asarray(rves, dtype=np.int64).reshape(-1)
        if points is not None and len(points) and (points.min() < 0
                                                   or points.max() >= self.n_rve):
            raise IndexError(f"points must lie in 0…{self.n_rve - 1}, got {points.tolist()}")
        parts = self._run(_Command.COMMITTED, points, "committed RVEs")
        data = RVEData.concatenate([p for p in parts if p is not None])
        if points is None:
            return data
        owner = np.searchsorted(self.shard.bounds, points, side="right") - 1
        gathered = np.concatenate([np.flatnonzero(owner == r) for r in range(self.world.size)])
        return data.take(np.argsort(gathered, kind="stable"))

    def checkpoint_data(self) -> RVEData:
        """Every rank's committed RVEs with the backend's arrays, as one batch."""
        parts = self._run(_Command.CHECKPOINT, None, "checkpoint")
        return RVEData.concatenate([p for p in parts if p is not None])

    def checkpoint(self, path: str | Path) -> None:
        """Write :meth:`checkpoint_data` to the RVE file ``path`` (rank 0 alone writes)."""
        save_rve(path, self.checkpoint_data())
