"""A ∇u path in increments, each RVE's state recorded after every one: what ``dem-drive``
runs and tabulates (:func:`drive_path`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from granular_material.dem import DEMBatch, DEMInstabilityError
from granular_material.procedures.strain_path import (
    DEFAULT_MAX_DEM_STEPS,
    DEFAULT_STRAIN_PER_STEP,
    drive_grad_u,
    path_increment,
)

__all__ = ["DrivenPath", "drive_path"]


@dataclass
class DrivenPath:
    """A driven path: ``table`` one row per RVE and recorded increment (0 first: ``rve``,
    ``increment``, the applied ``Gxx``, ``Gxy``, ``Gyx``, ``Gyy`` [-], Love ``sxx``, ``syy``,
    ``sxy`` [Pa] tension positive, ``void_ratio``, ``coordination``, ``steps`` done so far),
    the DEM steps run, and what stopped it early: a blow-up or collapse (``failure``; the
    increments before it are kept) or an interrupt."""

    table: pd.DataFrame
    steps: int
    failure: DEMInstabilityError | None = None
    interrupt: KeyboardInterrupt | None = None

    @property
    def finished(self) -> int:
        """The last increment recorded."""
        return int(self.table["increment"].max())

    def summary(self) -> dict[str, Any]:
        """The state after the last recorded increment (a value per RVE, the value itself for
        one RVE): Love ``sxx``, ``syy``, ``sxy`` [Pa], ``void_ratio``, ``coordination``, and
        the DEM ``steps`` run."""
        last = self.table[self.table["increment"] == self.finished]

        def batch(name: str) -> Any:
            values = last[name].tolist()
            return values[0] if len(values) == 1 else values

        return {**{name: batch(name) for name in
                   ("sxx", "syy", "sxy", "void_ratio", "coordination")},
                "steps": self.steps}

    def failure_message(self, increments: int) -> str | None:
        """Why the path of ``increments`` stopped short (a blow-up or collapse), or None."""
        if self.failure is None:
            return None
        return (f"{self.failure} (in increment {self.finished + 1} of {increments}; the path "
                f"to increment {self.finished} is kept)")


def drive_path(batch: DEMBatch, grad_u: np.ndarray, increments: int,
               max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
               max_steps: int = DEFAULT_MAX_DEM_STEPS,
               after_increment: Callable[[int, int], None] | None = None) -> DrivenPath:
    """Apply ∇u (2, 2) [-] to every RVE of ``batch`` in ``increments`` equal increments
    (:func:`~granular_material.procedures.path_increment`, each over the steps
    :func:`~granular_material.procedures.drive_grad_u` takes), recording each RVE after every
    one. ``after_increment(increment, steps)`` is called after each. A blow-up or a collapse
    (not a refused input, which is raised) and an interrupt end the path with the
    increments before them kept."""
    grad = np.asarray(grad_u, dtype=np.float64).reshape(2, 2)
    rows: list[pd.DataFrame] = []
    done = DrivenPath(table=pd.DataFrame(), steps=0)

    def record(increment: int) -> None:
        h = batch.homogenize()
        applied = grad * increment / increments
        rows.append(pd.DataFrame({
            "rve": np.arange(batch.n_rve), "increment": increment,
            "Gxx": applied[0, 0], "Gxy": applied[0, 1], "Gyx": applied[1, 0],
            "Gyy": applied[1, 1],
            "sxx": h.stress[:, 0, 0], "syy": h.stress[:, 1, 1],
            "sxy": 0.5 * (h.stress[:, 0, 1] + h.stress[:, 1, 0]),
            "void_ratio": h.void_ratio, "coordination": h.coordination,
            "steps": done.steps,
        }))

    record(0)
    try:
        for increment in range(1, increments + 1):
            steps = drive_grad_u(batch, path_increment(grad, increment, increments),
                                 max_strain_per_step=max_strain_per_step,
                                 max_steps=max_steps)
            done.steps += steps
            record(increment)
            if after_increment is not None:
                after_increment(increment, steps)
    except KeyboardInterrupt as exc:
        done.interrupt = exc
    except DEMInstabilityError as exc:
        if isinstance(exc, ValueError):  # refused input (a cell made too thin)
            raise
        done.failure = exc
    done.table = pd.concat(rows, ignore_index=True)
    return done
