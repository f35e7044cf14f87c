"""The footing rows in ``report.md``: the table, its Pareto figure, and each preset's
footing against the reference."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from granular_material.results.compare import markdown_table
from granular_material.results.plots import pyplot, save_figure
from granular_material.results.trade_plots import pareto_front
from granular_material.studies.footing_rows import (
    FOOTING_BUDGETS,
    MECHANISM_FRACTION,
    FootingScale,
    keeps_footing,
)

__all__ = ["footing_section", "plot_footing_pareto"]

_COLUMNS = {"knob": "knob", "value": "value", "q_0.05": "q s/B 0.05 kPa",
            "q_0.1": "q s/B 0.1 kPa", "q_peak": "q peak kPa", "s_peak_mm": "at s mm",
            "q_0.05_pct": "Δ 0.05 %", "q_0.1_pct": "Δ 0.1 %", "q_peak_pct": "Δ peak %",
            "mechanism_reach_B": "reach /B", "mechanism_depth_B": "depth /B",
            "iterations_per_step": "iterations a step", "cost_ratio": "cost",
            "wall_s": "wall s", "error": "error"}


def plot_footing_pareto(table: pd.DataFrame, path: str | Path) -> Path:
    """The size of Δq at s/B = 0.05, 0.1 and the peak [%] against the cost (DEM
    particle-steps over the reference's; the Mohr–Coulomb twin, which has none, drawn at
    10⁻³), one panel each, the Pareto front drawn."""
    plt = pyplot()
    measures = {"q_0.05_pct": "s/B = 0.05", "q_0.1_pct": "s/B = 0.1", "q_peak_pct": "peak"}
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.5), constrained_layout=True)
    for ax, (column, label) in zip(axes, measures.items(), strict=True):
        error = table[column].abs().to_numpy(dtype=float)
        cost = np.maximum(table["cost_ratio"].to_numpy(dtype=float), 1e-3)
        ok = np.isfinite(error) & np.isfinite(cost)
        shown = np.maximum(error, 1e-2)
        ax.scatter(cost[ok], shown[ok], s=26)
        front = pareto_front(cost[ok], error[ok])
        ax.plot(cost[ok][front], shown[ok][front], lw=1)
        for i in np.flatnonzero(ok):
            ax.annotate(f"{table['knob'].iloc[i]}={table['value'].iloc[i]}",
                        (cost[i], shown[i]), fontsize=6, xytext=(3, 2),
                        textcoords="offset points")
        if ok.any():
            ax.set_xscale("log")
            ax.set_yscale("log")
        ax.set_xlabel("cost [DEM particle-steps / the reference's]")
        ax.set_ylabel(f"|bearing pressure error| at {label} [%]")
        ax.grid(alpha=0.3, which="both")
    try:
        return save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)


def footing_section(table: pd.DataFrame, scale: FootingScale) -> list[str]:
    """The footing rows' lines of ``report.md``."""
    size = ("the scene as written (192 tri6, 576 Gauss points of one 64-disc packing, 58 "
            "steps of 0.25 mm)" if scale.steps is None else
            f"the scene cut to {scale.steps} steps, {scale.discs}-disc RVEs, "
            f"{scale.elements} elements")
    lines = [
        "## The footing (boundary-value rows)", "",
        f"Guo & Zhao's reduced strip footing (`examples/scenes/footing-gz2016-cpu.toml`): "
        f"{size}. q = −F_y / b, the bearing pressure of the half model; B = 2b = 0.1 m. The "
        "reference is the scene as written (the Kruyt–Rothenburg tangent held over each "
        "increment, the commands' residual-displacement test). `seed 2` prepares the "
        "packing every point copies from another seed: the scatter a knob's Δ must exceed. "
        f"The mechanism: the Gauss points whose shear strain at s/B = 0.1 is at least "
        f"{MECHANISM_FRACTION:g} of the largest; `reach` is the farthest of them from the "
        "footing's centre line, `depth` the deepest below the surface, both in B. Cost: the "
        "DEM particle-steps over the reference's (0 for the Mohr–Coulomb twin, which takes "
        "seconds); wall times were taken on a machine shared with other work, a resumed "
        "run's of its last part only.", "",
        "![footing Pareto](footing_pareto.png)", "",
    ]
    keep = [c for c in _COLUMNS if c in table and (c != "error" or
                                                   (table[c].fillna("") != "").any())]
    lines += [markdown_table(table[keep].rename(columns=_COLUMNS)), ""]
    verdicts = []
    for name, budget in FOOTING_BUDGETS.items():
        row = table[(table["knob"] == "preset") & (table["value"] == name)]
        kept = keeps_footing(row.iloc[0], budget) if not row.empty else True
        verdicts.append({
            "preset": name,
            "footing budget": ", ".join(f"q at s/B {c.split('_')[1]} within {v:g} %"
                                        for c, v in budget.items()),
            "its footing": "the scene's settings (the reference)" if row.empty else
            f"Δ {row.iloc[0]['q_0.05_pct']:+.1f} % / {row.iloc[0]['q_0.1_pct']:+.1f} %",
            "keeps it": "yes" if kept else "NO"})
    lines += ["### What each preset keeps and gives up (footing)", "",
              markdown_table(pd.DataFrame(verdicts)), ""]
    return lines
