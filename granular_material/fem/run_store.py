"""Where a run keeps what it has done, and what it resumes from.

:func:`~granular_material.fem.runner.run_biaxial` hands every committed step, and the
committed state when one is due, to a :class:`RunStore`, and resumes from the
:class:`SavedRun` the store loads. How and where a store keeps them is its own affair: the
commands' store is the checkpoint folder of a run
(:class:`granular_material.runs.RunCheckpoint`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import pandas as pd

if TYPE_CHECKING:
    from granular_material.fem.material import Material
    from granular_material.fem.newton import CommittedState, NewtonSolver

__all__ = ["RunStore", "SavedRun", "SavedStep"]


@dataclass
class SavedStep:
    """One committed load step as the run's observer saw it.

    Attributes:
        row: the step's row of the ``steps`` table.
        points: its Gauss-point table.
        u: nodal displacement [m], shape (ndofs,), float64.
        tracked: its tracked post-processor rows, or None when the step was not tracked.
    """

    row: dict[str, Any]
    points: pd.DataFrame
    u: np.ndarray
    tracked: pd.DataFrame | None


@dataclass
class SavedRun:
    """The last whole checkpoint of a run.

    Attributes:
        step: the last committed load step it holds.
        steps: steps 0 … ``step``, in order.
        state: the solver's committed state after ``step``.
        material_path: the material's committed state (for :meth:`Material.restore`).
    """

    step: int
    steps: list[SavedStep]
    state: CommittedState
    material_path: Path


class RunStore(Protocol):
    """What :func:`~granular_material.fem.runner.run_biaxial` saves a run into and resumes
    it from (its ``checkpoint``)."""

    def save_step(self, row: dict[str, Any], points: pd.DataFrame, u: np.ndarray,
                  tracked: pd.DataFrame | None) -> None:
        """Keep one committed step's row, Gauss-point table, displacement [m] and tracked
        rows (None: not tracked)."""
        ...

    def due(self, step: int, last_step: int) -> bool:
        """Whether the committed state after load ``step`` of ``last_step`` is to be saved."""
        ...

    def save_state(self, step: int, solver: NewtonSolver, material: Material) -> None:
        """Save the committed state of ``solver`` and ``material`` after load ``step``."""
        ...

    def has_state(self) -> bool:
        """Whether a committed state has been saved (else a resume starts from the beginning)."""
        ...

    def load(self) -> SavedRun:
        """The last whole saved state, with the steps up to it."""
        ...
