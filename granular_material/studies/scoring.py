"""The trade study's scoring: a run's errors against its reference run and the row of
``trade.csv`` they make, the accuracy a row is judged by, and the rule that chooses the
presets from the rows (:func:`recommend`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd

from granular_material.results.compare import ERROR_COLUMNS, curve_errors, mean_curve
from granular_material.runs.presets import SETTING_NAMES
from granular_material.studies.band import (
    BAND_SCALES,
    NEWTON_KNOBS,
    band_rows,
    command_settings,
)
from granular_material.studies.band_scoring import BAND_BUDGETS, keeps_band
from granular_material.studies.footing_rows import FOOTING_BUDGETS, keeps_footing
from granular_material.studies.plan import (
    Knob,
    PlannedRow,
    StudyScale,
    _reference,
    knobs,
    run_key,
)
from granular_material.studies.running import RunResult

__all__ = ["PRESETS", "PRESET_KNOBS", "accuracy", "band_scale_name", "recommend"]


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

#: the knobs of the pure-DEM and single-element rows a preset takes its value from (the
#: mesh, the test and the physics stay the user's; float32 is measured but the DEM material
#: runs float64); Newton's test, tangent, relaxation and drive come from the band rows
PRESET_KNOBS = ("discs", "strain_per_step", "reuse_tol")


def recommend(table: pd.DataFrame, scale: StudyScale, band: pd.DataFrame | None = None,
              footing: pd.DataFrame | None = None) -> dict[str, dict[str, Any]]:
    """The presets' settings (:data:`~granular_material.runs.presets.SETTING_NAMES`) from the
    measured rows.

    Rule, per preset:

    - ``discs``, ``strain_per_step`` and ``reuse_tol``: the value of the pure-DEM or
      single-element rows with the least cost in DEM particle-steps, the tangent's work
      included (:func:`~granular_material.studies.running._dem_equivalent`: a cost that does
      not depend on the machine's load), among those that ran without error and whose
      :func:`accuracy` (the peak) is within the preset's budget; costs within the scatter
      that round-off alone gives the test's reference run (:func:`_cost_scatter`) are a tie,
      which the reference value wins. A strain per DEM step whose band row (``band``, the
      specimen's rows of :mod:`granular_material.studies.band_scoring`) breaks the preset's
      band budget is replaced by the largest that keeps it (the commands' 1e-5 does);
    - Newton's test, tangent, relaxation and the drive: the commands' defaults
      (:func:`~granular_material.studies.band.command_settings`), each changed to the
      cheapest band row of its knob that keeps the preset's band budget
      (:data:`~granular_material.studies.band_scoring.BAND_BUDGETS`) and costs less than the
      reference by more than the reference's own scatter between seeds, and whose footing
      row (``footing``, where the knob's value has one) keeps the preset's footing budget
      (:data:`~granular_material.studies.footing_rows.FOOTING_BUDGETS`). Without band rows
      they stay the defaults;
    - reuse of undisturbed RVEs only with the force test (the displacement tests judge a
      correction a reused response does not make);
    - ``publication``: the commands' defaults with the finest strain per DEM step and the
      most discs of the pure-DEM rows.
    """
    ref = _reference(scale) | {"discs": max(scale.discs)}
    chosen: dict[str, dict[str, Any]] = {}
    for name, budget in PRESETS.items():
        values: dict[str, Any] = {**command_settings(), "discs": ref["discs"],
                                  "strain_per_step": ref["strain_per_step"]}
        if budget is not None:
            for knob in knobs(scale):
                if knob.name in PRESET_KNOBS:
                    values[knob.name] = _cheapest_within(table, knob, budget, ref)
            if band is not None:
                allowed = _allowed(band, footing, name)
                values.update(_newton_from_band(band, scale, allowed))
                values["strain_per_step"] = _band_strain_per_step(
                    band, values["strain_per_step"], allowed)
        if values["convergence"] != "force":
            values["reuse_tol"] = 0.0
        chosen[name] = values
    return chosen


def _cheapest_within(table: pd.DataFrame, knob: Knob, budget: float,
                     ref: dict[str, Any]) -> Any:
    """The value of ``knob`` the peak rule chooses (see :func:`recommend`)."""
    rows = table[(table["knob"] == knob.name) & (table["error"] == "")]
    fine = rows[accuracy(rows) <= budget] if not rows.empty else rows
    if fine.empty:
        return ref[knob.name]
    fine = fine.assign(not_reference=fine["value"] != str(ref[knob.name]), cost=_cost(fine))
    scatter = _cost_scatter(table, knob.test)
    tied = fine[fine["cost"] <= fine["cost"].min() * (1.0 + scatter)]
    return _typed(tied.sort_values(["not_reference", "cost"]).iloc[0]["value"], knob)


def _allowed(band: pd.DataFrame, footing: pd.DataFrame | None,
             name: str) -> Callable[[pd.Series], bool]:
    """Whether a band row's setting is allowed to preset ``name``: it keeps the preset's
    band budget, and its footing row, where the same knob and value has one, the footing
    budget."""
    def allowed(line: pd.Series) -> bool:
        if not keeps_band(line, BAND_BUDGETS[name]):
            return False
        if footing is None or footing.empty:
            return True
        same = footing[(footing["knob"] == line["knob"])
                       & (footing["value"].astype(str) == str(line["value"]))]
        return same.empty or keeps_footing(same.iloc[0], FOOTING_BUDGETS[name])
    return allowed


def _newton_from_band(band: pd.DataFrame, scale: StudyScale,
                      allowed: Callable[[pd.Series], bool]) -> dict[str, Any]:
    """Newton's settings the band (and footing) rows allow a preset (see
    :func:`recommend`)."""
    rows = {(r.knob, r.value): r for r in band_rows(BAND_SCALES[band_scale_name(scale)])}
    reference = band[band["knob"] == "reference"].iloc[0]
    margin = 1.0 - reference["particle_steps_scatter"] / reference["particle_steps"]
    settings: dict[str, Any] = {}
    for knob in NEWTON_KNOBS:
        lines = band[(band["knob"] == knob)]
        lines = lines[[allowed(line) and line["cost_ratio"] < margin
                       for _, line in lines.iterrows()]]
        if not lines.empty:
            best = lines.sort_values("cost_ratio").iloc[0]
            settings.update(rows[(knob, best["value"])].settings)
    return {k: v for k, v in settings.items() if k in SETTING_NAMES}


def _band_strain_per_step(band: pd.DataFrame, value: float,
                          allowed: Callable[[pd.Series], bool]) -> float:
    """``value`` if its band row is allowed (or it is no coarser than the commands'), else
    the largest strain per DEM step whose row is."""
    default = command_settings()["strain_per_step"]
    kept = [default] + [float(line["value"]) for _, line in
                        band[band["knob"] == "strain_per_step"].iterrows() if allowed(line)]
    return value if value <= default or value in kept else max(v for v in kept if v <= value)


def band_scale_name(scale: StudyScale) -> str:
    """The band rows' scale of a study scale (the GPU study's band rows are the CPU's)."""
    return scale.name if scale.name in BAND_SCALES else "cpu"


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
