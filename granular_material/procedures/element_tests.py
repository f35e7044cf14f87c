"""Element tests of DEM batches: the drained biaxial test (its key figures:
:func:`granular_material.results.summarize_biaxial`)."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from granular_material.lazy_names import lazy_names
from granular_material.procedures.packing import DEFAULT_PRESSURE, given_as
from granular_material.progress import progress_bar
from granular_material.reference_values import DEFAULT_STRAIN_PER_STEP, STEP_LIMIT

if TYPE_CHECKING:
    from granular_material.dem import DEMBatch

# The DEM (warp) is imported where a test runs: a run specification reads this module's
# defaults without loading it (issue 62).
#: names of this module loaded on first use (:func:`__getattr__`), by the module they are in
_LATE = {"CONTROL_STRAIN": "granular_material.procedures.servo",
         "CONTROL_STRESS": "granular_material.procedures.servo",
         "servo_steps": "granular_material.procedures.servo"}


# the names of _LATE, imported on first use and kept as this module's
__getattr__ = lazy_names(__name__, _LATE, globals())[0]

__all__ = ["BIAXIAL_NAMES", "DEFAULT_AXIAL_STRAIN", "DEFAULT_RECORD_EVERY", "MAX_AXIAL_STRAIN",
           "BiaxialInterrupted", "BiaxialStart", "biaxial_steps", "biaxial_test", "check_biaxial",
           "lateral_stress_error"]

#: final axial strain of a drained biaxial test [-], engineering, compression positive (Wu et
#: al. 2025 load their specimens to 10 %)
DEFAULT_AXIAL_STRAIN = 0.1
#: DEM steps between the recorded rows of :func:`biaxial_test`
DEFAULT_RECORD_EVERY = 100
#: a biaxial test's final axial strain stays below this [-] (the cell would be crushed flat)
MAX_AXIAL_STRAIN = 0.9
#: how :func:`check_biaxial` names the values in its messages by default (a library
#: caller's keywords); the command line names its options instead
BIAXIAL_NAMES = {"axial_strain": "axial_strain", "confining": "confining",
                 "strain_per_step": "strain_per_step", "max_steps": "max_steps"}


class BiaxialInterrupted(KeyboardInterrupt):
    """Ctrl-C (or what the caller maps to it, e.g. SIGTERM) during :func:`biaxial_test`,
    raised ``from`` that interrupt: ``curve`` holds the rows recorded before it (step 0 at
    least), in the layout the test returns."""

    def __init__(self, curve: pd.DataFrame, steps_done: int, steps_total: int) -> None:
        super().__init__(f"interrupted after DEM step {steps_done} of {steps_total}")
        self.curve = curve
        self.steps_done = steps_done
        self.steps_total = steps_total


@dataclass(frozen=True)
class BiaxialStart:
    """Where a resumed :func:`biaxial_test` starts: ``curve``, its rows recorded up to DEM
    step ``done`` (the batch being in the state of that step), and ``cell0`` (B, 2, 2) [m],
    the cells the test started from (its strains are measured from them)."""

    curve: pd.DataFrame
    done: int
    cell0: np.ndarray


def biaxial_steps(axial_strain: float, strain_per_step: float) -> int:
    """DEM steps of :func:`biaxial_test`: ``ceil(−ln(1 − ε_a)/strain_per_step)`` (ε_a
    engineering, compression positive); ``ValueError`` past
    :data:`~granular_material.procedures.strain_path.STEP_LIMIT` (no longer an integer)."""
    total = math.ceil(-math.log1p(-axial_strain) / strain_per_step)
    if total > STEP_LIMIT:
        raise ValueError(f"axial_strain {axial_strain!r} at strain_per_step "
                         f"{strain_per_step!r} needs {total:.4g} DEM steps, more than 1e15")
    return total


def check_biaxial(axial_strain: float, confining: float, strain_per_step: float,
                  max_steps: int | None = None, names: dict[str, str] | None = None) -> int:
    """The one check of a drained biaxial test's settings, before any step: ``ValueError``
    naming the value (as ``names`` does: :data:`BIAXIAL_NAMES` where it gives none) when a
    strain, the pressure or the step is not a positive number, the axial strain reaches
    :data:`MAX_AXIAL_STRAIN`, or the test needs more than ``max_steps`` DEM steps (None: no
    cap but :func:`biaxial_steps`'). Returns the test's DEM steps."""
    names = {**BIAXIAL_NAMES, **(names or {})}
    for key, value in (("axial_strain", axial_strain), ("confining", confining),
                       ("strain_per_step", strain_per_step)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{names[key]} must be a positive number, got {value!r}")
    if axial_strain >= MAX_AXIAL_STRAIN:
        raise ValueError(f"{names['axial_strain']} must be below {MAX_AXIAL_STRAIN:g}, got "
                         f"{axial_strain:g}")
    if max_steps is None:
        return biaxial_steps(axial_strain, strain_per_step)
    try:
        total: float = biaxial_steps(axial_strain, strain_per_step)
    except ValueError:  # past the integer limit: more than any cap
        total = math.inf
    if total > max_steps:
        raise ValueError(
            f"{given_as(names['axial_strain'], axial_strain)} at "
            f"{given_as(names['strain_per_step'], strain_per_step)} needs {total:.4g} DEM "
            f"steps, more than {given_as(names['max_steps'], max_steps)}; raise "
            f"{names['max_steps']} or {names['strain_per_step']}")
    return int(total)


def lateral_stress_error(curve: pd.DataFrame, confining: float) -> pd.DataFrame:
    """How well the servo of :func:`biaxial_test` held σxx at −``confining`` [Pa], per RVE,
    over the records after the first (the first is the packing as it came): ``max_error``
    and ``median_error`` of |σxx/(−confining) − 1|, ``final_sxx`` [Pa] and ``records``."""
    later = curve[curve["step"] > 0]
    error = (later["sxx"] / -float(confining) - 1.0).abs()
    grouped = error.groupby(later["rve"])
    return pd.DataFrame({
        "max_error": grouped.max(),
        "median_error": grouped.median(),
        "final_sxx": later.groupby("rve")["sxx"].last(),
        "records": grouped.size(),
    })


def biaxial_test(
    batch: DEMBatch,
    axial_strain: float = DEFAULT_AXIAL_STRAIN,
    confining: float = DEFAULT_PRESSURE,
    strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
    record_every: int = DEFAULT_RECORD_EVERY,
    gain: float = 0.5,
    progress: bool = False,
    max_steps: int | None = None,
    *,
    start: BiaxialStart | None = None,
    after_record: Callable[[int, list[pd.DataFrame], np.ndarray], None] | None = None,
) -> pd.DataFrame:
    """Drained biaxial test: σxx held at −``confining`` while εyy is driven in compression.

    Args:
        axial_strain: final axial (yy) compressive strain [-], engineering.
        confining: lateral stress magnitude [Pa].
        strain_per_step: largest axial (logarithmic) strain per step [-].
        record_every: steps between recorded rows.
        gain: servo gain on σxx (0.5 holds it within 0.8 % of ``confining`` on the 400-disc
            Guo & Zhao RVE; YADE's PeriTriaxController holds 1.2–1.5 %; check it with
            :func:`lateral_stress_error`).
        max_steps: ``ValueError`` before any step when the test needs more DEM steps
            (:func:`biaxial_steps`); None: no cap.
        start: continue a test stopped after a record (the batch in that record's state)
            instead of starting one; None: record step 0 and start.
        after_record: called after every record but the first with the DEM steps done, the
            rows so far (frames, in order) and the starting cells: where a run saves its
            checkpoint.

    Raises:
        BiaxialInterrupted: on Ctrl-C after the first record, with the rows recorded so far.

    Returns:
        One row per record and RVE: ``rve``, ``step``, ``axial_strain`` (compression
        positive), ``lateral_strain``, ``volumetric_strain`` (area change, tension positive),
        ``sxx``, ``syy``, ``sxy`` [Pa] (tension positive), ``stress_ratio`` σ1/σ3 = syy/sxx,
        ``void_ratio``, ``coordination``.
    """
    # n equal logarithmic steps ending exactly at the requested engineering strain
    total = check_biaxial(axial_strain, confining, strain_per_step, max_steps)
    b = batch.n_rve
    cell0 = batch.cell() if start is None else np.array(start.cell0, dtype=np.float64)
    area0 = np.linalg.det(cell0)
    step_strain = (1.0 - axial_strain) ** (1.0 / total) - 1.0
    rows: list[pd.DataFrame] = []

    def record(step: int) -> None:
        h = batch.homogenize()
        cell = batch.cell()
        rows.append(pd.DataFrame({
            "rve": np.arange(b),
            "step": step,
            "axial_strain": 1.0 - cell[:, 1, 1] / cell0[:, 1, 1],
            "lateral_strain": cell[:, 0, 0] / cell0[:, 0, 0] - 1.0,
            "volumetric_strain": np.linalg.det(cell) / area0 - 1.0,
            "sxx": h.stress[:, 0, 0],
            "syy": h.stress[:, 1, 1],
            "sxy": 0.5 * (h.stress[:, 0, 1] + h.stress[:, 1, 0]),
            "stress_ratio": h.stress[:, 1, 1] / h.stress[:, 0, 0],
            "void_ratio": h.void_ratio,
            "coordination": h.coordination,
        }))

    if start is None:
        record(0)
        done = 0
    else:
        rows.append(start.curve)
        done = int(start.done)
    target = np.tile([-float(confining), step_strain], (b, 1))
    module = sys.modules[__name__]  # the servo as this module holds it
    servo_steps = module.servo_steps
    control = np.tile([module.CONTROL_STRESS, module.CONTROL_STRAIN], (b, 1))
    bar = progress_bar(total, "biaxial", progress)
    if done:
        bar.update(done)
    try:
        while done < total:
            chunk = min(record_every, total - done)
            servo_steps(batch, chunk, target, control, gain=gain,
                        max_strain=4.0 * strain_per_step, check_every=chunk)
            done += chunk
            record(done)
            if after_record is not None:
                after_record(done, rows, cell0)
            bar.update(chunk)
            last = rows[-1]
            bar.set_postfix(q=f"{last['stress_ratio'].mean():.3f}")
    except KeyboardInterrupt as exc:
        recorded = int(rows[-1]["step"].iloc[-1])
        raise BiaxialInterrupted(pd.concat(rows, ignore_index=True), recorded, total) from exc
    finally:
        bar.close()
    return pd.concat(rows, ignore_index=True)
