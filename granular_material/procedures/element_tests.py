"""Element tests of DEM batches: the drained biaxial test (its key figures:
:func:`granular_material.results.summarize_biaxial`)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from granular_material.dem import DEMBatch
from granular_material.procedures.packing import DEFAULT_PRESSURE
from granular_material.procedures.progress import progress_bar
from granular_material.procedures.servo import CONTROL_STRAIN, CONTROL_STRESS, servo_steps
from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP, STEP_LIMIT

__all__ = ["DEFAULT_AXIAL_STRAIN", "DEFAULT_RECORD_EVERY", "BiaxialInterrupted", "biaxial_steps",
           "biaxial_test", "lateral_stress_error"]

#: final axial strain of a drained biaxial test [-], engineering, compression positive (Wu et
#: al. 2025 load their specimens to 10 %)
DEFAULT_AXIAL_STRAIN = 0.1
#: DEM steps between the recorded rows of :func:`biaxial_test`
DEFAULT_RECORD_EVERY = 100


class BiaxialInterrupted(KeyboardInterrupt):
    """Ctrl-C (or what the caller maps to it, e.g. SIGTERM) during :func:`biaxial_test`,
    raised ``from`` that interrupt: ``curve`` holds the rows recorded before it (step 0 at
    least), in the layout the test returns."""

    def __init__(self, curve: pd.DataFrame, steps_done: int, steps_total: int) -> None:
        super().__init__(f"interrupted after DEM step {steps_done} of {steps_total}")
        self.curve = curve
        self.steps_done = steps_done
        self.steps_total = steps_total


def biaxial_steps(axial_strain: float, strain_per_step: float) -> int:
    """DEM steps of :func:`biaxial_test`: ``ceil(−ln(1 − ε_a)/strain_per_step)`` (ε_a
    engineering, compression positive); ``ValueError`` past
    :data:`~granular_material.procedures.strain_path.STEP_LIMIT` (no longer an integer)."""
    total = math.ceil(-math.log1p(-axial_strain) / strain_per_step)
    if total > STEP_LIMIT:
        raise ValueError(f"axial_strain {axial_strain!r} at strain_per_step "
                         f"{strain_per_step!r} needs {total:.4g} DEM steps, more than 1e15")
    return total


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

    Raises:
        BiaxialInterrupted: on Ctrl-C after the first record, with the rows recorded so far.

    Returns:
        One row per record and RVE: ``rve``, ``step``, ``axial_strain`` (compression
        positive), ``lateral_strain``, ``volumetric_strain`` (area change, tension positive),
        ``sxx``, ``syy``, ``sxy`` [Pa] (tension positive), ``stress_ratio`` σ1/σ3 = syy/sxx,
        ``void_ratio``, ``coordination``.
    """
    for name, value in (("axial_strain", axial_strain), ("confining", confining),
                        ("strain_per_step", strain_per_step)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, got {value!r}")
    if axial_strain >= 0.9:
        raise ValueError(f"axial_strain must be below 0.9, got {axial_strain!r}")
    # n equal logarithmic steps ending exactly at the requested engineering strain
    total = biaxial_steps(axial_strain, strain_per_step)
    if max_steps is not None and total > max_steps:
        raise ValueError(f"axial_strain {axial_strain:g} at strain_per_step {strain_per_step:g}"
                         f" needs {total} DEM steps, more than max_steps = {max_steps}")
    b = batch.n_rve
    cell0 = batch.cell()
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

    record(0)
    target = np.tile([-float(confining), step_strain], (b, 1))
    control = np.tile([CONTROL_STRESS, CONTROL_STRAIN], (b, 1))
    bar = progress_bar(total, "biaxial", progress)
    done = 0
    try:
        while done < total:
            chunk = min(record_every, total - done)
            servo_steps(batch, chunk, target, control, gain=gain,
                        max_strain=4.0 * strain_per_step, check_every=chunk)
            done += chunk
            record(done)
            bar.update(chunk)
            last = rows[-1]
            bar.set_postfix(q=f"{last['stress_ratio'].mean():.3f}")
    except KeyboardInterrupt as exc:
        recorded = int(rows[-1]["step"].iloc[0])
        raise BiaxialInterrupted(pd.concat(rows, ignore_index=True), recorded, total) from exc
    finally:
        bar.close()
    return pd.concat(rows, ignore_index=True)
