"""What one evaluation of a DEM material's RVEs gives (:class:`Evaluation`), why a point
failed (:func:`instability_reason`), and what the material asks of whoever holds its RVEs
(:class:`DEMBackend`: :class:`~granular_material.multiscale.backend.InProcessBackend` in this
process, :class:`~granular_material.multiscale.mpi.MPIBackend` on the ranks of an MPI job)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Protocol

import numpy as np

from granular_material.dem import Homogenized, RVEData
from granular_material.fem.materials.protocol import FailureReason

__all__ = ["DEMBackend", "Evaluation", "instability_reason", "nan_like", "totals"]


@dataclass(frozen=True)
class Evaluation:
    """What one evaluation of the RVEs gave.

    Attributes:
        homogenized: the homogenised RVEs (stress, tangent, void ratio, ... of
            :class:`~granular_material.dem.Homogenized`); with the "perturbation" tangent its
            ``tangent`` is the forward-difference one. NaN throughout when the batch failed.
        failed: RVEs whose state blew up or whose ∇u inverts the cell, shape (B,), bool.
        dem_steps: DEM steps run: the longest path of each drive, the drives of the
            evaluation together.
        rve_evaluations: RVE paths run (an RVE stepped in a drive counts once per drive).
        particle_steps: disc-steps run, Σ over the stepped RVEs of their steps × discs.
        drives: the cost (DEM steps, RVE paths, particle-steps) of each drive the evaluation
            completed, in order (the totals above are their sums, DEM steps included).
        complete: False when a drive blew up: the batch is then back in its committed state
            and the response is NaN throughout.
        reasons: why each failed RVE failed, shape (B,), str (:class:`FailureReason`
            values, "" where it did not); None: "failed" where ``failed``.
        timings: wall-clock seconds [s] by phase: ``dem`` (stepping the RVEs, restoring
            them included), ``homogenization`` (Love stress, tangent, fabric) and ``tangent``
            (the objective or condensed tangent on top); empty where not timed.
    """

    homogenized: Homogenized
    failed: np.ndarray
    dem_steps: int
    rve_evaluations: int = 0
    particle_steps: int = 0
    drives: tuple[tuple[int, int, int], ...] = ()
    complete: bool = True
    reasons: np.ndarray | None = None
    timings: dict[str, float] = field(default_factory=dict)

    def failure_reasons(self) -> np.ndarray:
        """:attr:`reasons`, or "failed" where ``failed`` when the backend gave none."""
        if self.reasons is not None:
            return np.asarray(self.reasons, dtype=object)
        reasons = np.full(len(self.failed), "", dtype=object)
        reasons[np.asarray(self.failed, dtype=bool)] = FailureReason.FAILED.value
        return reasons


#: the DEM's messages (:class:`~granular_material.dem.DEMInstabilityError`) by the words that
#: tell them apart, most telling first, and the reason each gives a point
_INSTABILITIES = (("non-finite", FailureReason.BLOW_UP),
                  ("cell became too small", FailureReason.CELL_TOO_THIN),
                  ("thins its cell", FailureReason.CELL_TOO_THIN),  # refused before a step
                  ("would collapse", FailureReason.OVERCOMPRESSED),  # refused before a step
                  ("overflowed", FailureReason.OVERCOMPRESSED),
                  ("coincide", FailureReason.COINCIDENT))


def instability_reason(messages: list[str]) -> FailureReason:
    """The reason of the RVEs of a :class:`~granular_material.dem.DEMInstabilityError`: the
    first of its messages, in the order blow-up, cell too thin (in a step, or a path refused
    before any), overcompressed (likewise), coincident discs (the DEM reports the messages of
    the batch together, not one per RVE)."""
    text = " ".join(messages)
    for words, reason in _INSTABILITIES:
        if words in text:
            return reason
    return FailureReason.BLOW_UP


def nan_like(h: Homogenized) -> Homogenized:
    """``h`` with every value NaN: the response of an evaluation that did not complete."""
    return Homogenized(**{f.name: np.full_like(np.asarray(getattr(h, f.name), dtype=np.float64),
                                               np.nan) for f in fields(h)})


def totals(drives: list[tuple[int, int, int]]) -> tuple[int, int, int]:
    """DEM steps, RVE paths and particle-steps of ``drives`` together."""
    steps, paths, particles = (int(sum(d[k] for d in drives)) for k in range(3))
    return steps, paths, particles


class DEMBackend(Protocol):
    """What the DEM material asks of whoever holds its RVEs."""

    n_rve: int

    def evaluate(self, grad_u: np.ndarray) -> Evaluation:
        """Deform every RVE from its committed state by ∇u (B, 2, 2) and homogenise."""
        ...

    def committed_rves(self) -> RVEData:
        """The committed RVE states (contact history included)."""
        ...

    def commit(self) -> None:
        """The state reached by the last evaluate becomes the committed state."""
        ...

    def revert(self) -> None:
        """Return every RVE to its committed state."""
        ...

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed state as an RVE file."""
        ...
