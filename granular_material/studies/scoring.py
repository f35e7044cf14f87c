"""The trade study's scoring: a run's errors against its reference run and the row of
``trade.csv`` they make, the accuracy a row is judged by, and the rule that chooses the
presets from the rows (:func:`recommend`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from granular_material.results.compare import ERROR_COLUMNS, curve_errors, mean_curve
from granular_material.studies.plan import (
    Knob,
    PlannedRow,
    StudyScale,
    _reference,
    knobs,
    run_key,
)
from granular_material.studies.running import RunResult

__all__ = ["PRESETS", "PRESET_KNOBS", "accuracy", "recommend"]


def _errors(row: PlannedRow, curve: pd.DataFrame, reference: pd.DataFrame) -> dict[str, float]:
    """The row's errors: its curve against its reference's (see
    :mod:`granular_material.studies.trade`)."""
    if "rve" not in curve:
        return curve_errors(curve, reference)
    seeds = sorted(curve["rve"].unique())
    mean_ref = mean_curve([g for _, g in reference.groupby("rve")])
    per_seed = [curve_errors(curve[curve["rve"] == k],
                             reference[reference["rve"] == k] if row.per_seed else mean_ref)
                for k in seeds]
    errors = {c: float(np.mean([abs(e[c]) for e in per_seed])) for c in ERROR_COLUMNS}
    peaks = [curve[curve["rve"] == k]["stress_ratio"].max() for k in seeds]
    errors["seed_scatter_pct"] = (100.0 * float(np.std(peaks, ddof=1) / np.mean(peaks))
                                  if len(peaks) > 1 else math.nan)
    return errors


def _row(row: PlannedRow, result: RunResult, reference: pd.DataFrame, device: str,
         commit: str) -> dict[str, Any]:
    errors = _errors(row, result.curve, reference)
    return {"knob": row.knob, "value": str(row.value), "test": row.settings["test"],
            "run": run_key(row.settings), "reference_run": run_key(row.reference),
            "is_reference": run_key(row.settings) == run_key(row.reference), **errors,
            "wall_s": result.wall_s, "particle_steps": result.particle_steps,
            "newton_iterations": result.iterations, **result.extra,
            "error": result.error or "", "device": device, "commit": commit}


def accuracy(rows: pd.DataFrame) -> pd.Series:
    """The error a row is judged by [%]: |peak σ1/σ3 error| against the reference. The RMS
    differences of whole curves are reported beside it but not used: past the peak, runs of
    the same packing that differ by round-off already part by several per cent (DEM is
    chaotic; the ``noise`` rows measure it)."""
    return rows["peak_error_pct"].abs()


#: the three recommended settings: their error budget [%] for :func:`accuracy` (None: the
#: reference settings themselves)
PRESETS: dict[str, float | None] = {"quick": 10.0, "engineering": 3.0, "publication": None}

#: the knobs a preset sets: what the FEM commands take as options (the mesh, the test and
#: the physics stay the user's; float32 is measured but the DEM material runs float64)
PRESET_KNOBS = ("discs", "strain_per_step", "rtol", "stress_floor", "tangent",
                "acceleration", "reuse_tol")


def recommend(table: pd.DataFrame, scale: StudyScale) -> dict[str, dict[str, Any]]:
    """The presets' values from the measured rows. Rule: for each knob of
    :data:`PRESET_KNOBS`, the value with the least cost in DEM particle-steps, the tangent's
    work included (:func:`~granular_material.studies.running._dem_equivalent`: a cost that
    does not depend on the machine's load; wall time on a shared machine does), among those
    that ran without error and whose :func:`accuracy` is within the preset's budget. Costs
    within the scatter that round-off alone gives the test's reference run
    (:func:`_cost_scatter`, the ``noise`` row: a FEM run's Newton path, and so its
    particle-steps, is chaotic) are a tie, which the reference value wins, else the least
    cost among them. The reference value when none is within
    the budget, and for ``publication``."""
    ref = _reference(scale) | {"discs": max(scale.discs)}
    chosen: dict[str, dict[str, Any]] = {}
    for name, budget in PRESETS.items():
        values: dict[str, Any] = {}
        for knob in knobs(scale):
            if knob.name not in PRESET_KNOBS:
                continue
            values[knob.name] = ref[knob.name]
            rows = table[(table["knob"] == knob.name) & (table["error"] == "")]
            if budget is None or rows.empty:
                continue
            fine = rows[accuracy(rows) <= budget]
            fine = fine.assign(not_reference=fine["value"] != str(ref[knob.name]))
            if not fine.empty:
                fine = fine.assign(cost=_cost(fine))
                scatter = _cost_scatter(table, knob.test)
                tied = fine[fine["cost"] <= fine["cost"].min() * (1.0 + scatter)]
                best = tied.sort_values(["not_reference", "cost"]).iloc[0]["value"]
                values[knob.name] = _typed(best, knob)
        chosen[name] = values
    return chosen


def _cost(rows: pd.DataFrame) -> pd.Series:
    """The rows' cost [particle-steps], the tangent's work included (the particle-steps
    alone in a table of an older study)."""
    return rows["cost_particle_steps"] if "cost_particle_steps" in rows else rows["particle_steps"]


def _cost_scatter(table: pd.DataFrame, test: str) -> float:
    """How far round-off alone moves the cost of ``test``'s reference run [-]: the
    ``noise`` row's cost against the reference's (0 where either is missing, or the cost
    does not depend on the run's path, as a pure-DEM run's)."""
    if not {"test", "run", "reference_run"} <= set(table.columns):
        return 0.0
    rows = table[(table["test"] == test) & (table["error"] == "")]
    noise = rows[rows["knob"] == "noise"]
    if noise.empty:
        return 0.0
    reference = rows[rows["run"] == noise["reference_run"].iloc[0]]
    if reference.empty:
        return 0.0
    base = float(_cost(reference).iloc[0])
    return abs(float(_cost(noise).iloc[0]) - base) / base if base > 0 else 0.0


def _typed(text: str, knob: Knob) -> Any:
    """A ``trade.csv`` value back as the knob's own type."""
    for value in knob.values:
        if str(value) == str(text):
            return value
    raise ValueError(f"{text!r} is not a value of the knob {knob.name}")
