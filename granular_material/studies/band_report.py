"""The band rows in ``report.md``: the specimen, a table per knob, the figures, and what
each preset keeps and gives up."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pandas as pd

from granular_material.results.band_measures import (
    MEASURE_STRAINS,
    ONSET_RATIO,
    localisation_history,
)
from granular_material.results.band_plots import plot_band_histories, plot_band_pareto
from granular_material.results.compare import markdown_table
from granular_material.runs.run_folder import ended_summary
from granular_material.studies.band import BandRow, BandScale, read_band_run, run_folder
from granular_material.studies.band_scoring import BAND_BUDGETS, keeps_band

__all__ = ["band_figures", "band_section", "preset_verdicts"]

_COLUMNS = {
    "value": "value", "banded": "banded", "onset_%": "onset %",
    "onset_scatter_pp": "± seeds", "onset_delay_pp": "Δ onset pp",
    "onset_delay_spread_pp": "± Δ",
    **{f"ratio_{100 * e:g}": f"γ ratio {100 * e:g} %" for e in MEASURE_STRAINS},
    "inclination_deg": "band °", "elongation": "elongation",
    "crossing_x_mm": "crosses at x mm",
    "stress_ratio_5": "σ1/σ3 5 %", "stress_ratio_10": "σ1/σ3 10 %",
    "stress_ratio_10_pct": "Δ σ1/σ3 10 % %", "stress_ratio_10_spread_pct": "± Δ %",
    "volumetric_strain_10_pct": "Δ εv 10 % %", "cost_ratio": "cost",
    "iterations": "iterations", "wall_s": "wall s", "failed": "failed",
}


def band_figures(out: Path, table: pd.DataFrame, rows: list[BandRow],
                 scale: BandScale) -> None:
    """``band_pareto.png`` and ``band_histories.png`` under ``out``."""
    plot_band_pareto(table, out / "band_pareto.png",
                     never_formed=100 * scale.axial_strain)
    histories: dict[str, dict[str, list[pd.DataFrame]]] = {}
    reference = [r for r in rows if r.knob == "reference"]
    for row in rows:
        if row.knob == "reference":
            continue
        for shown in (*reference, row):
            done = [run_folder(out, shown, s) for s in shown.seeds]
            histories.setdefault(row.knob, {})[shown.value] = [
                localisation_history(read_band_run(f)[1]) for f in done
                if ended_summary(f) is not None]
    plot_band_histories(histories, out / "band_histories.png", ONSET_RATIO)


def preset_verdicts(table: pd.DataFrame, presets: dict[str, dict[str, Any]]) -> pd.DataFrame:
    """Per preset: its band budget, its band row's measures, and what it keeps and gives
    up (a preset without a band budget, publication, is the reference's settings)."""
    lines = []
    for name in presets:
        row = table[(table["knob"] == "preset") & (table["value"] == name)]
        budget = BAND_BUDGETS.get(name)
        line: dict[str, Any] = {"preset": name}
        if budget is not None:
            line["band budget"] = (f"onset ≤ +{budget['onset_pp']:g} pp, σ1/σ3 at 10 % "
                                   f"within {budget['stress_ratio_10_pct']:g} %")
        if row.empty:
            lines.append(line)
            continue
        r = row.iloc[0]
        line.update({"banded": r["banded"], "Δ onset pp": r["onset_delay_pp"],
                     "Δ σ1/σ3 10 % %": r["stress_ratio_10_pct"],
                     "Δ εv 10 % %": r["volumetric_strain_10_pct"], "cost": r["cost_ratio"],
                     "wall s": r["wall_s"]})
        if budget is not None:
            line["keeps the band"] = "yes" if keeps_band(r, budget) else "NO"
        lines.append(line)
    return pd.DataFrame(lines)


def band_section(table: pd.DataFrame, presets: dict[str, dict[str, Any]],
                 scale: BandScale) -> list[str]:
    """The band rows' lines of ``report.md``."""
    reference = table[table["knob"] == "reference"].iloc[0]
    lines = [
        "## The shear band (specimen rows)", "",
        f"The commands' reduced biaxial specimen: {scale.elements[0]} × {scale.elements[1]} "
        f"quad4 of {scale.discs}-disc RVEs, {scale.steps} load steps to "
        f"{100 * scale.axial_strain:g} % axial strain at p0 = {scale.confining:g} Pa, one "
        f"independent set of RVEs per seed (seeds {', '.join(map(str, scale.seeds))} for the "
        "reference and the presets, the first two for the knobs). The reference is the "
        "commands' defaults (residual-displacement test to 1e-2, the condensed-sticking "
        "tangent held over each increment, extrapolating predictor with Aitken relaxation, "
        "every trial from the committed state, 1e-5 strain a DEM step); every other row "
        "changes one setting.", "",
        f"Measures (`granular_material.results.band_measures`): the band's onset is the "
        f"axial strain at which γmax/γmean of the Gauss points first reaches {ONSET_RATIO:g} "
        "(linear between steps; a run that never reaches it counts at its last strain and is "
        "not `banded`); γ ratio = γmax/γmean at that strain; at the last step, the band's "
        "|inclination| to the horizontal, its elongation (1: one straight band; near 0: a "
        "cross of two, whose mean inclination means little) and where its axis crosses "
        "mid-height (– where it leaves the specimen first); σ1/σ3 and εv at 5 and 10 %. "
        "Δ are against the reference run of the same set of RVEs, averaged over the row's "
        "sets (so the scatter between sets drops out of them), `± Δ` their standard "
        "deviation between sets; `± seeds` is a measure's own scatter between sets of RVEs; "
        "cost is the DEM particle-steps over the reference's, set by set. A setting is "
        "cheaper only where it saves more than the reference's own scatter of "
        "particle-steps between sets.", "",
        f"The reference: band at {reference['onset_%']:.2f} ± "
        f"{reference['onset_scatter_pp']:.2f} % axial strain, σ1/σ3 at 10 % "
        f"{reference['stress_ratio_10']:.3f} (± {reference['stress_ratio_10_scatter_pct']:.1f} "
        f"%), {reference['particle_steps']:.3g} particle-steps, {reference['wall_s']:.0f} s a "
        "run.", "",
        "![band Pareto](band_pareto.png)", "",
        "![γmax/γmean](band_histories.png)", "",
    ]
    for knob, rows in table.groupby("knob", sort=False):
        keep = [c for c in _COLUMNS if c in rows and rows[c].notna().any()]
        shown = rows[keep].rename(columns=_COLUMNS)
        lines += [f"### {knob}", "", markdown_table(shown)]
    verdicts = preset_verdicts(table, presets)
    lines += ["### What each preset keeps and gives up (band)", "",
              markdown_table(verdicts) if not verdicts.empty else "(no preset rows)", ""]
    if not math.isfinite(float(reference["onset_%"])):
        lines.append("The reference formed no band: the band budgets cannot be judged.")
    return lines
