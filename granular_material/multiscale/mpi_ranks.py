"""What every rank of an MPI job does (:mod:`granular_material.multiscale.mpi` describes the
protocol): its shard of the RVEs, the exchanges every rank runs for one command (rank 0 with
its payload), the workers' loop (:func:`serve`) and :func:`launch`, which starts both sides."""

from __future__ import annotations

import os
import sys
import time
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np

from granular_material.dem import RVEData
from granular_material.multiscale.backend import InProcessBackend
from granular_material.multiscale.mpi_wire import (
    _COMPLETE,
    _DRIVES,
    _ERROR,
    _ERROR_TAG,
    _MAX_DRIVES,
    _NANOSECONDS,
    _PHASE_START,
    FAULT_VARIABLE,
    HEADER,
    ROW,
    _Command,
    _describe,
    _device,
    _pack,
    _signals_held,
    _threads,
    _wait,
    _World,
    _world,
    shard_bounds,
)
from granular_material.multiscale.parameters import DEMMaterialParameters
from granular_material.timing import MATERIAL_PHASES

__all__ = ["launch", "launched", "serve"]

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


def launched() -> bool:
    """Whether rank 0's program runs within :func:`launch` (its workers serving)."""
    return _LAUNCHED
