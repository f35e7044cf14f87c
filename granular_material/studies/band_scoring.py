"""The band rows scored: every run's band measures, each row's mean and scatter over its
sets of RVEs, its errors against the reference row, and whether a preset keeps its band
budget.

Errors against the reference's mean over its seeds: the band's onset in percentage points
of axial strain (positive: later; a run whose ratio never reaches the onset's is given the
strain it ran to and marked), |inclination| in degrees, σ1/σ3 and εv at 5 and 10 % in per
cent of the reference's value. The scatter of each measure between a row's seeds is reported
beside it: an error within the reference's own scatter is chaos, not the knob.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.results.band_measures import band_measures
from granular_material.studies.band import BandRow, BandScale, read_band_run, run_folder

__all__ = ["BAND_BUDGETS", "band_table", "keeps_band", "run_measures"]

#: each preset's band budget: the latest its band may form after the reference's, in
#: percentage points of axial strain, and the largest error of σ1/σ3 at 10 % [%]
BAND_BUDGETS: dict[str, dict[str, float]] = {
    "quick": {"onset_pp": 1.0, "stress_ratio_10_pct": 10.0},
    "engineering": {"onset_pp": 0.5, "stress_ratio_10_pct": 5.0},
}

_MEASURES = ("onset", "ratio_2", "ratio_3", "ratio_5", "ratio_10", "inclination_deg",
             "elongation", "crossing_x", "stress_ratio_5", "stress_ratio_10", "volumetric_strain_5",
             "volumetric_strain_10")


def run_measures(out: Path, rows: list[BandRow], scale: BandScale) -> pd.DataFrame:
    """One line per done run: the row, the seed, its band measures and its cost
    (particle-steps, Newton iterations, wall time) and error."""
    lines = []
    for row in rows:
        for seed in row.seeds:
            folder = run_folder(out, row, seed)
            if not (folder / "summary.json").is_file():
                continue
            steps, points, summary = read_band_run(folder)
            done = steps[steps["step"] > 0]
            lines.append({
                "knob": row.knob, "value": row.value, "seed": seed,
                **band_measures(steps, points, height=scale.height, width=scale.width),
                "final_strain": float(steps["axial_strain"].iloc[-1]),
                "particle_steps": float(summary.get("particle_steps", math.nan)),
                "iterations": int(done["iterations"].sum()),
                "wall_s": float(summary.get("wall_time_s", math.nan)),
                "error": summary.get("error") or ""})
    return pd.DataFrame(lines)


def band_table(runs: pd.DataFrame, scale: BandScale) -> pd.DataFrame:
    """One line per row: each measure's mean and scatter (standard deviation over the
    seeds), its error against the reference, and the mean cost."""
    reference = runs[runs["knob"] == "reference"]
    if reference.empty:
        raise ValueError("the band rows' reference has not run")
    ref = {m: float(reference[m].mean()) for m in _MEASURES}
    lines = []
    for (knob, value), group in runs.groupby(["knob", "value"], sort=False):
        onset = group["onset"].to_numpy(dtype=float)
        formed = np.isfinite(onset)
        # a run without a band by its last strain: its onset is at least that strain
        onset_at_least = np.where(formed, onset, group["final_strain"].to_numpy())
        line: dict[str, Any] = {
            "knob": knob, "value": value, "seeds": len(group),
            "banded": f"{int(formed.sum())}/{len(group)}",
            "onset_%": 100 * float(onset_at_least.mean()),
            "onset_scatter_pp": 100 * float(np.std(onset_at_least, ddof=1))
            if len(group) > 1 else math.nan,
            "onset_delay_pp": 100 * (float(onset_at_least.mean()) - ref["onset"]),
        }
        for m in ("ratio_2", "ratio_3", "ratio_5", "ratio_10", "inclination_deg",
                  "elongation"):
            line[m] = float(group[m].mean())
        line["inclination_error_deg"] = line["inclination_deg"] - ref["inclination_deg"]
        line["crossing_x_mm"] = 1e3 * float(group["crossing_x"].mean())
        for e in ("5", "10"):
            sr, ev = group[f"stress_ratio_{e}"], group[f"volumetric_strain_{e}"]
            line[f"stress_ratio_{e}"] = float(sr.mean())
            line[f"stress_ratio_{e}_pct"] = 100 * (float(sr.mean()) / ref[f"stress_ratio_{e}"]
                                                   - 1)
            line[f"stress_ratio_{e}_scatter_pct"] = (100 * float(sr.std(ddof=1) / sr.mean())
                                                     if len(group) > 1 else math.nan)
            line[f"volumetric_strain_{e}_pct"] = 100 * (
                float(ev.mean()) - ref[f"volumetric_strain_{e}"]) / abs(
                ref[f"volumetric_strain_{e}"])
        line.update({"particle_steps": float(group["particle_steps"].mean()),
                     "particle_steps_scatter": float(group["particle_steps"].std(ddof=1))
                     if len(group) > 1 else 0.0,
                     "iterations": float(group["iterations"].mean()),
                     "wall_s": float(group["wall_s"].mean()),
                     "failed": int((group["error"] != "").sum())})
        lines.append(line)
    table = pd.DataFrame(lines)
    base = float(table.loc[table["knob"] == "reference", "particle_steps"].iloc[0])
    return table.assign(cost_ratio=table["particle_steps"] / base)


def keeps_band(line: pd.Series, budget: dict[str, float]) -> bool:
    """Whether a row of :func:`band_table` keeps a preset's band ``budget``: every seed
    formed its band, no later than ``onset_pp`` after the reference's, σ1/σ3 at 10 % within
    ``stress_ratio_10_pct``, and no run failed."""
    seeds = line["banded"].split("/")
    return (seeds[0] == seeds[1] and line["failed"] == 0
            and line["onset_delay_pp"] <= budget["onset_pp"]
            and abs(line["stress_ratio_10_pct"]) <= budget["stress_ratio_10_pct"])
