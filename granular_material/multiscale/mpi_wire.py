"""The MPI backend's wire and world (:mod:`granular_material.multiscale.mpi` describes the
protocol): MPI_COMM_WORLD with each rank's place in its node, how the points are shared out
(:func:`shard_bounds`), the layouts of the gathered header and rows (:data:`HEADER`,
:data:`ROW`) and the packing of homogenised RVEs into rows and back."""

from __future__ import annotations

import contextlib
import enum
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from granular_material.dem import Homogenized, resolve_device
from granular_material.fem.materials.protocol import FailureReason
from granular_material.filesafe import deferred_signals
from granular_material.timing import MATERIAL_PHASES

__all__ = ["FAULT_VARIABLE", "HEADER", "ROW", "MPIRankError", "message_bytes", "shard_bounds"]

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


