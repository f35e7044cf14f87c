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

import contextlib
import enum
import os
import sys
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from granular_material.dem import Homogenized, RVEData, resolve_device, save_rve
from granular_material.fem.material import FailureReason
from granular_material.filesafe import deferred_signals
from granular_material.multiscale.backend import InProcessBackend
from granular_material.multiscale.evaluation import Evaluation
from granular_material.multiscale.parameters import DEMMaterialParameters
from granular_material.timing import MATERIAL_PHASES

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

#: test hook: "RANK:N" makes rank RANK raise at its N-th evaluation (the tests' failing rank)
FAULT_VARIABLE = "GRANULAR_MATERIAL_MPI_FAULT"

#: trailing shape of each field of Homogenized (a row holds them flattened, in field order)
_FIELD_SHAPES: dict[str, tuple[int, ...]] = {
    "stress": (2, 2), "tangent": (2, 2, 2, 2), "void_ratio": (), "coordination": (),
    "fabric": (2, 2), "unbalanced_force": (), "n_contacts": (), "sliding_fraction": (),
    "volume": (),
}
_INTEGER_FIELDS = frozenset({"n_contacts"})
if [f.name for f in fields(Homogenized)] != list(_FIELD_SHAPES):
    raise ImportError("granular_material.multiscale.mpi: the row layout does not match "
                      "Homogenized's fields")

#: float64 a point in the gathered rows: the failed flag and the homogenised fields
ROW = 1 + sum(int(np.prod(shape)) for shape in _FIELD_SHAPES.values())
#: the most drives of one evaluation (four perturbed runs and the trial)
_MAX_DRIVES = 5
_ERROR, _COMPLETE, _DRIVES, _NANOSECONDS = range(4)
#: where a rank's seconds by phase (:data:`~granular_material.timing.MATERIAL_PHASES`, its
#: :attr:`Evaluation.timings`) start in its header, after the drives
_PHASE_START = 4 + 3 * _MAX_DRIVES
#: int64 a rank in the gathered header
HEADER = _PHASE_START + len(MATERIAL_PHASES)
_ERROR_TAG = 77


class _Command(enum.IntEnum):
    STOP = 0
    SETUP = 1
    EVALUATE = 2
    COMMIT = 3
    REVERT = 4
    CHECKPOINT = 5
    COMMITTED = 6
    HOLD = 7


class MPIRankError(RuntimeError):
    """A rank's work raised: the rank, what it was doing and its error."""


def message_bytes(n_points: int, n_ranks: int) -> dict[str, int]:
    """Bytes one Newton evaluation moves for ``n_points`` Gauss points on ``n_ranks``
    ranks: the command (to every worker), ∇u (scattered), the headers and the rows
    (gathered), and their total; the points of rank 0's own shard are counted too."""
    workers = max(n_ranks - 1, 0)
    sizes = {"command": 2 * 8 * workers, "grad_u": 4 * 8 * n_points,
             "header": HEADER * 8 * n_ranks, "rows": ROW * 8 * n_points}
    sizes["total"] = sum(sizes.values())
    return sizes


def shard_bounds(n_points: int, n_ranks: int) -> np.ndarray:
    """First point of each rank's shard and the end, shape (n_ranks + 1,): contiguous shards
    whose sizes differ by at most one, the larger ones first (a rank may hold none)."""
    sizes = np.full(n_ranks, n_points // n_ranks, dtype=np.int64)
    sizes[: n_points % n_ranks] += 1
    return np.concatenate([[0], np.cumsum(sizes)])


# -- the job ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class _World:
    """MPI_COMM_WORLD with this rank's place in it and in its node."""

    comm: Any
    rank: int
    size: int
    local_rank: int
    local_size: int


_WORLD: _World | None = None
_LAUNCHED = False


def _world() -> _World:
    global _WORLD
    if _WORLD is None:
        try:
            from mpi4py import MPI
        except ImportError as exc:
            raise RuntimeError(
                "the MPI backend needs mpi4py: pip install 'granular-material[mpi]' (or "
                f"mpi4py built against your cluster's MPI) ({exc})") from None
        comm = MPI.COMM_WORLD
        node = comm.Split_type(MPI.COMM_TYPE_SHARED)
        _WORLD = _World(comm, comm.Get_rank(), comm.Get_size(), node.Get_rank(),
                        node.Get_size())
        node.Free()
    return _WORLD


def _wait(request: Any) -> None:
    """Wait for a non-blocking operation, sleeping between tests (at most 0.2 ms) so that a
    waiting rank leaves its core to the ones still working."""
    pause = 1.0e-5
    while not request.Test():
        time.sleep(pause)
        pause = min(2.0 * pause, 2.0e-4)


@contextlib.contextmanager
def _signals_held(deliver: bool = True) -> Iterator[None]:
    """The stop signals (Ctrl-C, SIGTERM, SIGHUP) wait while the block runs (an exchange must
    not be left half done); afterwards one that came is delivered as it would have been
    (``deliver``) or dropped (:func:`granular_material.filesafe.deferred_signals`)."""
    with deferred_signals(deliver):
        yield


def _describe(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def _device(device: str | None, local_rank: int) -> str:
    """The device of a rank's shard: the CPU, the device named, or for plain ``cuda`` the
    node's GPU ``local_rank % n_gpus``."""
    device = resolve_device(device)
    if device != "cuda":
        return device
    import warp as wp

    return f"cuda:{local_rank % max(wp.get_cuda_device_count(), 1)}"


def _threads(shards: int | None, device: str, local_size: int) -> int | None:
    """CPU threads of a rank's batch: as asked, else the node's cores shared by its ranks."""
    if shards is not None or device != "cpu":
        return shards
    return max(1, (os.cpu_count() or 1) // local_size)


# -- what one rank holds ----------------------------------------------------------------------
class _Shard:
    """This rank's part of the RVEs (points ``start:stop``), or none."""

    def __init__(self, world: _World) -> None:
        self.world = world
        self.backend: InProcessBackend | None = None
        self.bounds = shard_bounds(0, world.size)
        self.evaluations = 0
        fault = os.environ.get(FAULT_VARIABLE, "")
        rank, _, call = fault.partition(":")
        self.fault = int(call) if fault and int(rank) == world.rank else 0

    @property
    def size(self) -> int:
        """Points of this rank."""
        r = self.world.rank
        return int(self.bounds[r + 1] - self.bounds[r])

    def setup(self, n_points: int, parameters: DEMMaterialParameters, data: RVEData,
              resume: bool) -> None:
        """Hold ``data`` (this rank's RVEs; a checkpoint's with ``resume``)."""
        self.backend = None
        self.bounds = shard_bounds(n_points, self.world.size)
        if data.n_rve != self.size:
            raise ValueError(f"rank {self.world.rank} got {data.n_rve} RVEs for "
                             f"{self.size} points")
        if self.size == 0:
            return
        device = _device(parameters.device, self.world.local_rank)
        threads = _threads(parameters.shards, device, self.world.local_size)
        self.backend = InProcessBackend.holding(data, parameters, device, threads, resume)

    def evaluate(self, grad_u: np.ndarray) -> tuple[np.ndarray, np.ndarray, str | None]:
        """The header and rows of this rank's answer to ∇u (size, 2, 2), and its error."""
        header = np.zeros(HEADER, dtype=np.int64)
        rows = np.full((self.size, ROW), np.nan)
        error = None
        started = time.perf_counter_ns()
        try:
            self.evaluations += 1
            if self.evaluations == self.fault:
                raise RuntimeError(f"fault injected by {FAULT_VARIABLE} at evaluation "
                                   f"{self.evaluations}")
            header[_COMPLETE] = 1
            if self.backend is not None:
                ev = self.backend.evaluate(grad_u)
                if len(ev.drives) > _MAX_DRIVES:
                    raise RuntimeError(f"{len(ev.drives)} drives in one evaluation, more "
                                       f"than the header's {_MAX_DRIVES}")
                rows = _pack(ev.homogenized, ev.failed, ev.failure_reasons())
                header[_COMPLETE] = int(ev.complete)
                header[_DRIVES] = len(ev.drives)
                for k, cost in enumerate(ev.drives):
                    header[4 + 3 * k: 7 + 3 * k] = cost
                for k, phase in enumerate(MATERIAL_PHASES):
                    header[_PHASE_START + k] = round(ev.timings.get(phase, 0.0) * 1e9)
        except Exception as exc:
            header[_ERROR] = 1
            error = _describe(exc)
        header[_NANOSECONDS] = time.perf_counter_ns() - started
        return header, rows, error

    def call(self, what: str, *args: Any) -> str | None:
        """``commit``, ``revert`` or ``hold_tangent(*args)`` of this rank's RVEs; the error,
        if any."""
        try:
            if self.backend is not None:
                getattr(self.backend, what)(*args)
        except Exception as exc:
            return _describe(exc)
        return None

    def checkpoint_data(self) -> RVEData | None:
        """This rank's committed RVEs with the backend's arrays, or None if it holds none."""
        return None if self.backend is None else self.backend.checkpoint_data()

    def committed(self, points: np.ndarray | None) -> RVEData | None:
        """The committed RVEs of this rank's points among ``points`` (global indices, in
        their order; None: all), or None if it holds none of them."""
        if self.backend is None:
            return None
        start, stop = self.bounds[self.world.rank], self.bounds[self.world.rank + 1]
        if points is None:
            return self.backend.committed_rves()
        mine = points[(points >= start) & (points < stop)] - start
        return self.backend.committed_rves(mine) if len(mine) else None


def _critical_phases(headers: np.ndarray) -> dict[str, float]:
    """Seconds [s] by phase of the evaluation's critical path: those of the rank that took
    longest (the ranks work at once; rank 0 waits for the slowest), from the gathered
    ``headers`` (size, HEADER)."""
    slowest = int(np.argmax(headers[:, _NANOSECONDS]))
    return {phase: float(headers[slowest, _PHASE_START + k]) * 1e-9
            for k, phase in enumerate(MATERIAL_PHASES)}


#: the reasons a failure code stands for (code k > 0: _REASONS[k - 1])
_REASONS = tuple(r.value for r in FailureReason if r is not FailureReason.NONE)


def _pack(h: Homogenized, failed: np.ndarray, reasons: np.ndarray | None = None
          ) -> np.ndarray:
    """The rows (B, ROW) float64 of homogenised RVEs and their failure codes (``reasons``
    None: "failed" for every failed RVE)."""
    if reasons is None:
        reasons = np.where(failed, FailureReason.FAILED.value, "")
    codes = np.array([0.0 if not bad else 1.0 + _REASONS.index(str(reason) or "failed")
                      for bad, reason in zip(failed, reasons, strict=True)])
    parts = [codes[:, None]]
    parts += [np.asarray(getattr(h, name), dtype=np.float64).reshape(len(failed), -1)
              for name in _FIELD_SHAPES]
    return np.ascontiguousarray(np.concatenate(parts, axis=1))


def _unpack(rows: np.ndarray) -> tuple[Homogenized, np.ndarray, np.ndarray]:
    """Homogenised RVEs, failed flags and failure reasons from rows (B, ROW)."""
    n = rows.shape[0]
    values, column = {}, 1
    for name, shape in _FIELD_SHAPES.items():
        width = int(np.prod(shape))
        block = rows[:, column: column + width].reshape((n, *shape))
        values[name] = block.astype(np.int64) if name in _INTEGER_FIELDS else block.copy()
        column += width
    codes = rows[:, 0]
    failed = codes != 0
    reasons = np.array(["" if not bad else (_REASONS[int(code) - 1] if np.isfinite(code)
                                            else FailureReason.FAILED.value)
                        for bad, code in zip(failed, codes, strict=True)], dtype=object)
    return Homogenized(**values), failed, reasons


# -- the exchanges: every rank runs the same function, rank 0 with its payload ---------------
def _errors(world: _World, flag: bool, error: str | None, flags: np.ndarray | None
            ) -> dict[int, str]:
    """Rank 0: the messages of the ranks whose ``flags`` are set (its own ``error`` among
    them); the others send theirs. ``flags`` (size,) was gathered on rank 0."""
    if world.rank != 0:
        if flag:
            world.comm.send(error, dest=0, tag=_ERROR_TAG)
        return {}
    assert flags is not None
    messages = {0: str(error)} if flag else {}
    for rank in np.flatnonzero(flags[1:]) + 1:
        messages[int(rank)] = world.comm.recv(source=int(rank), tag=_ERROR_TAG)
    return messages


def _report(world: _World, error: str | None) -> dict[int, str]:
    """Every rank's error flag gathered to rank 0, then the messages: rank 0's dict of
    rank -> error (empty when all went well)."""
    flag = np.array([error is not None], dtype=np.int64)
    flags = np.empty(world.size, dtype=np.int64) if world.rank == 0 else None
    _wait(world.comm.Igather(flag, flags, root=0))
    return _errors(world, bool(flag[0]), error, flags)


#: what rank 0 gets from an exchange: its result and the errors of the ranks (rank -> message)
_Outcome = tuple[Any, dict[int, str]]


def _exchange_setup(world: _World, shard: _Shard, payload: Any = None) -> _Outcome:
    """Rank 0's ``payload`` (points, parameters, data, resume) shared out, one shard a rank."""
    if world.rank == 0:
        n_points, parameters, data, resume = payload
        bounds = shard_bounds(n_points, world.size)
        parts = [data.take(slice(int(bounds[r]), int(bounds[r + 1])))
                 for r in range(world.size)]
        common = (n_points, parameters, resume)
    else:
        parts, common = None, None
    n_points, parameters, resume = world.comm.bcast(common, root=0)
    part = world.comm.scatter(parts, root=0)
    error = None
    try:
        shard.setup(n_points, parameters, part, resume)
    except Exception as exc:
        error = _describe(exc)
    return None, _report(world, error)


def _exchange_evaluate(world: _World, shard: _Shard, grad_u: np.ndarray | None = None
                       ) -> _Outcome:
    """∇u scattered from rank 0, every shard evaluated, the answers gathered to rank 0:
    there the headers (size, HEADER) int64 and rows (B, ROW) float64."""
    from mpi4py import MPI

    counts = [int(c) for c in np.diff(shard.bounds)]
    starts = [int(s) for s in shard.bounds[:-1]]
    local = np.empty((shard.size, 2, 2))
    send = None
    if world.rank == 0:
        send = [grad_u, [4 * c for c in counts], [4 * s for s in starts], MPI.DOUBLE]
    _wait(world.comm.Iscatterv(send, local, root=0))
    header, rows, error = shard.evaluate(local)
    headers = gathered = receive = None
    if world.rank == 0:
        headers = np.empty((world.size, HEADER), dtype=np.int64)
        gathered = np.empty((int(shard.bounds[-1]), ROW))
        receive = [gathered, [ROW * c for c in counts], [ROW * s for s in starts], MPI.DOUBLE]
    _wait(world.comm.Igather(header, headers, root=0))
    _wait(world.comm.Igatherv(rows, receive, root=0))
    flags = None if headers is None else headers[:, _ERROR]
    return (headers, gathered), _errors(world, bool(header[_ERROR]), error, flags)


def _exchange_call(what: str) -> Callable[..., _Outcome]:
    def exchange(world: _World, shard: _Shard, payload: Any = None) -> _Outcome:
        return None, _report(world, shard.call(what))

    exchange.__doc__ = f"{what} on every rank; rank 0 gets the errors."
    return exchange


def _exchange_hold(world: _World, shard: _Shard, hold: bool | None = None) -> _Outcome:
    """Rank 0's ``hold`` broadcast, every rank's shard told; rank 0 gets the errors."""
    hold = world.comm.bcast(hold, root=0)
    return None, _report(world, shard.call("hold_tangent", bool(hold)))


def _gather_data(world: _World, produce: Callable[[], RVEData | None]) -> _Outcome:
    """Every rank's ``produce()`` gathered to rank 0, in rank order, with the errors."""
    try:
        answer: tuple[str | None, RVEData | None] = (None, produce())
    except Exception as exc:
        answer = (_describe(exc), None)
    answers = world.comm.gather(answer, root=0)
    if answers is None:
        return None, {}
    return [d for _, d in answers], {r: e for r, (e, _) in enumerate(answers) if e is not None}


def _exchange_checkpoint(world: _World, shard: _Shard, payload: Any = None) -> _Outcome:
    """Every rank's committed RVEs (with the backend's arrays) gathered to rank 0."""
    return _gather_data(world, shard.checkpoint_data)


def _exchange_committed(world: _World, shard: _Shard, points: np.ndarray | None = None
                        ) -> _Outcome:
    """The committed RVEs of rank 0's ``points`` (None: all) gathered from their ranks."""
    points = world.comm.bcast(points, root=0)
    return _gather_data(world, lambda: shard.committed(points))


_EXCHANGES: dict[_Command, Callable[..., _Outcome]] = {
    _Command.SETUP: _exchange_setup,
    _Command.EVALUATE: _exchange_evaluate,
    _Command.COMMIT: _exchange_call("commit"),
    _Command.REVERT: _exchange_call("revert"),
    _Command.CHECKPOINT: _exchange_checkpoint,
    _Command.COMMITTED: _exchange_committed,
    _Command.HOLD: _exchange_hold,
}

_SHARD: _Shard | None = None


def _process_shard() -> _Shard:
    """The shard of this process (one per rank, kept across materials)."""
    global _SHARD
    if _SHARD is None:
        _SHARD = _Shard(_world())
    return _SHARD


def _send_command(world: _World, command: _Command, argument: int = 0) -> None:
    message = np.array([int(command), argument], dtype=np.int64)
    _wait(world.comm.Ibcast(message, root=0))


def serve() -> int:
    """A worker rank's loop: answer rank 0's commands with this rank's shard until rank 0
    says stop; returns the exit code (0). Ctrl-C and SIGTERM are left to rank 0, which
    stops the workers in order. An exchange that cannot be finished aborts the job."""
    world = _world()
    shard = _process_shard()
    message = np.zeros(2, dtype=np.int64)
    with _signals_held(deliver=False):
        while True:
            _wait(world.comm.Ibcast(message, root=0))
            command = _Command(int(message[0]))
            if command == _Command.STOP:
                return 0
            try:
                _EXCHANGES[command](world, shard)
            except Exception:
                print(f"granular-material: MPI rank {world.rank} cannot continue the "
                      f"{command.name.lower()} exchange:\n{traceback.format_exc()}",
                      file=sys.stderr, flush=True)
                world.comm.Abort(1)


def launch(main: Callable[[], int]) -> int:
    """Run ``main`` on rank 0 of MPI_COMM_WORLD and :func:`serve` on every other rank. However
    ``main`` ends (a return, an exception, Ctrl-C), the workers are then told to stop.
    Returns this rank's exit code (``main``'s on rank 0, 0 on the workers); an exception of
    ``main`` propagates on rank 0."""
    global _LAUNCHED
    world = _world()
    if world.rank != 0:
        return serve()
    _LAUNCHED = True
    code = 1
    try:
        code = main()
        return code
    finally:
        _LAUNCHED = False
        if world.size > 1:
            with _signals_held():
                _send_command(world, _Command.STOP, int(code or 0))


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
        if self.world.size > 1 and not _LAUNCHED:
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
