"""The band rows scored: every run's band measures, each row's mean and scatter over its
sets of RVEs, its errors against the reference row, and whether a preset keeps its band
budget.

Errors against the reference run of the same seed (the same sets of RVEs), averaged over a
row's seeds: the band's onset in percentage points of axial strain (positive: later; a run
whose ratio never reaches the onset's is given the strain it ran to and marked), σ1/σ3 at 5
and 10 % in per cent of the reference's, εv there in per cent of the reference's mean. The
spread of those errors between seeds is reported beside them, and each measure's scatter
between sets of RVEs: an error within them is chaos, not the knob.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.results.band_measures import band_measures
from granular_material.runs.run_folder import ended_summary
from granular_material.studies.band import BandRow, BandScale, read_band_run, run_folder

__all__ = ["BAND_BUDGETS", "band_table", "keeps_band", "run_measures"]

#: each preset's band budget: the latest its band may form after the reference's, in
#: percentage points of axial strain, and the largest error of σ1/σ3 at 10 % [%]
BAND_BUDGETS: dict[str, dict[str, float]] = {
    "quick": {"onset_pp": 1.0, "stress_ratio_10_pct": 10.0},
    "engineering": {"onset_pp": 0.5, "stress_ratio_10_pct": 5.0},
}


def run_measures(out: Path, rows: list[BandRow], scale: BandScale) -> pd.DataFrame:
    """One line per done run: the row, the seed, its band measures and its cost
    (particle-steps, Newton iterations, wall time) and error."""
    lines = []
    for row in rows:
        for seed in row.seeds:
            folder = run_folder(out, row, seed)
            if ended_summary(folder) is None:
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
    seeds), its error against the reference seed by seed (the same sets of RVEs: the
    knob's own effect, the scatter between sets of RVEs taken out) and the spread of those
    errors, and the mean cost."""
    runs = runs.assign(onset_at_least=np.where(np.isfinite(runs["onset"]), runs["onset"],
                                               runs["final_strain"]))
    reference = runs[runs["knob"] == "reference"].set_index("seed")
    if reference.empty:
        raise ValueError("the band rows' reference has not run")
    lines = []
    for (knob, value), group in runs.groupby(["knob", "value"], sort=False):
        paired = group[group["seed"].isin(reference.index)]
        ref = reference.loc[paired["seed"]]
        onset = group["onset"].to_numpy(dtype=float)
        # a run without a band by its last strain: its onset is at least that strain
        delay = 100 * (paired["onset_at_least"].to_numpy() - ref["onset_at_least"].to_numpy())
        line: dict[str, Any] = {
            "knob": knob, "value": value, "seeds": len(group),
            "banded": f"{int(np.isfinite(onset).sum())}/{len(group)}",
            "onset_%": 100 * float(group["onset_at_least"].mean()),
            "onset_scatter_pp": _std(100 * group["onset_at_least"]),
            "onset_delay_pp": float(delay.mean()), "onset_delay_spread_pp": _std(delay),
        }
        for m in ("ratio_2", "ratio_3", "ratio_5", "ratio_10", "inclination_deg",
                  "elongation"):
            line[m] = float(group[m].mean())
        line["crossing_x_mm"] = 1e3 * float(group["crossing_x"].mean())
        for e in ("5", "10"):
            sr, ev = f"stress_ratio_{e}", f"volumetric_strain_{e}"
            line[sr] = float(group[sr].mean())
            error = 100 * (paired[sr].to_numpy() / ref[sr].to_numpy() - 1)
            line[f"{sr}_pct"] = float(error.mean())
            line[f"{sr}_spread_pct"] = _std(error)
            line[f"{sr}_scatter_pct"] = _std(100 * group[sr] / group[sr].mean())
            line[f"{ev}_pct"] = float((100 * (paired[ev].to_numpy() - ref[ev].to_numpy())
                                       / abs(reference[ev].mean())).mean())
        cost = paired["particle_steps"].to_numpy() / ref["particle_steps"].to_numpy()
        line.update({"particle_steps": float(group["particle_steps"].mean()),
                     "particle_steps_scatter": _std(group["particle_steps"]),
                     "cost_ratio": float(cost.mean()),
                     "iterations": float(group["iterations"].mean()),
                     "wall_s": float(group["wall_s"].mean()),
                     "failed": int((group["error"] != "").sum())})
        lines.append(line)
    return pd.DataFrame(lines)


def _std(values: Any) -> float:
    """The standard deviation of ``values`` (NaN for fewer than two)."""
    values = np.asarray(values, dtype=float)
    return float(np.std(values, ddof=1)) if values.size > 1 else math.nan


def keeps_band(line: pd.Series, budget: dict[str, float]) -> bool:
    """Whether a row of :func:`band_table` keeps a preset's band ``budget``: every seed
    formed its band, no later than ``onset_pp`` after the reference's, σ1/σ3 at 10 % within
    ``stress_ratio_10_pct``, and no run failed."""
    seeds = line["banded"].split("/")
    return (seeds[0] == seeds[1] and line["failed"] == 0
            and line["onset_delay_pp"] <= budget["onset_pp"]
            and abs(line["stress_ratio_10_pct"]) <= budget["stress_ratio_10_pct"])
