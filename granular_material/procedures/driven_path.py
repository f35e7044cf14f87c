"""A ∇u path in increments, each RVE's state recorded after every one: what ``dem-drive``
plans (:func:`plan_path`), runs and tabulates (:func:`drive_path`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from granular_material.dem import DEMBatch, DEMInstabilityError
from granular_material.procedures.packing import given_as
from granular_material.procedures.strain_path import (
    DEFAULT_MAX_DEM_STEPS,
    DEFAULT_MIN_STEPS,
    DEFAULT_STRAIN_PER_STEP,
    drive_grad_u,
    has_real_logarithm,
    path_increment,
    path_steps,
)

__all__ = ["PATH_NAMES", "DrivenPath", "drive_path", "plan_path"]


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
               after_increment: Callable[[int, int], None] | None = None, *,
               start: DrivenPath | None = None,
               after_record: Callable[[int, list[pd.DataFrame], int], None] | None = None,
               ) -> DrivenPath:
    """Apply ∇u (2, 2) [-] to every RVE of ``batch`` in ``increments`` equal increments
    (:func:`~granular_material.procedures.path_increment`, each over the steps
    :func:`~granular_material.procedures.drive_grad_u` takes), recording each RVE after every
    one. ``after_increment(increment, steps)`` is called after each. A blow-up or a collapse
    (not a refused input, which is raised) and an interrupt end the path with the
    increments before them kept.

    ``start`` continues a path stopped after increment ``start.finished`` (its table so far
    and DEM steps; the batch in that increment's state) instead of starting one;
    ``after_record(increment, rows, steps)`` is called after each increment's record with
    the rows so far (frames, in order) and the DEM steps: where a run saves its
    checkpoint."""
    grad = np.asarray(grad_u, dtype=np.float64).reshape(2, 2)
    rows: list[pd.DataFrame] = []
    done = DrivenPath(table=pd.DataFrame(), steps=0 if start is None else int(start.steps))

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

    if start is None:
        record(0)
        first = 1
    else:
        rows.append(start.table)
        first = start.finished + 1
    try:
        for increment in range(first, increments + 1):
            steps = drive_grad_u(batch, path_increment(grad, increment, increments),
                                 max_strain_per_step=max_strain_per_step,
                                 max_steps=max_steps)
            done.steps += steps
            record(increment)
            if after_record is not None:
                after_record(increment, rows, done.steps)
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


#: how :func:`plan_path` names the values in its messages by default (a library caller's
#: keywords); the command line names its options instead
PATH_NAMES = {"grad_u": "grad_u", "increments": "increments",
              "max_strain_per_step": "max_strain_per_step", "max_steps": "max_steps"}


def plan_path(grad_u: np.ndarray, increments: int,
              max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
              max_steps: int = DEFAULT_MAX_DEM_STEPS, min_steps: int = DEFAULT_MIN_STEPS,
              names: dict[str, str] | None = None) -> list[int]:
    """The DEM steps of each of the ``increments`` equal increments of the path to ∇u (2, 2)
    (:func:`path_increment`, each driven by :func:`drive_grad_u`), checked before any work:
    ``ValueError`` naming the values (as ``names`` does: :data:`PATH_NAMES` where it gives
    none) when an increment inverts the cell or has no real logarithm, or the path needs
    more than ``max_steps`` DEM steps in all."""
    names = {**PATH_NAMES, **(names or {})}
    g = np.asarray(grad_u, dtype=np.float64)
    grad = given_as(names["grad_u"], ",".join(f"{v:g}" for v in g.ravel()))
    cap = given_as(names["max_steps"], max_steps)
    per_step = given_as(names["max_strain_per_step"], max_strain_per_step)
    n = increments
    if n * min_steps > max_steps:  # before a loop over them: 10⁷ would take minutes
        raise ValueError(f"{given_as(names['increments'], n)} needs at least {n * min_steps} "
                         f"DEM steps ({min_steps} an increment), more than {cap}; use fewer "
                         f"{names['increments']}")
    plan = []
    for k in range(1, n + 1):
        det = float(np.linalg.det(np.eye(2) + g * k / n))
        if not det > 0:
            raise ValueError(f"{grad} inverts the cell at increment {k} of {n}: "
                             f"det(I + {k}/{n}·∇u) = {det:.4g} <= 0")
        increment = path_increment(g, k, n)[None]
        try:
            plan.append(int(path_steps(increment, max_strain_per_step, min_steps,
                                       max_steps)[0]))
        except ValueError:
            wanted = float(np.abs(increment).max()) / max_strain_per_step
            raise ValueError(
                f"{grad} needs more than {cap} DEM steps: increment {k} of {n} alone takes "
                f"{wanted:.4g} at {per_step}; raise {names['max_steps']} or "
                f"{names['max_strain_per_step']}") from None
        if not has_real_logarithm(np.eye(2) + increment)[0]:
            raise ValueError(f"increment {k} of {n} of {grad} has no real logarithm (it turns "
                             f"the cell by half a turn or more); use more "
                             f"{names['increments']}")
    if sum(plan) > max_steps:
        raise ValueError(f"{grad} needs {sum(plan)} DEM steps in {n} increments at "
                         f"{per_step}, more than {cap}; raise {names['max_steps']} or "
                         f"{names['max_strain_per_step']}")
    return plan
