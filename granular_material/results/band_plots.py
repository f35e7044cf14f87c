"""Figures of the trade study's band rows: each measure's error against the cost with its
Pareto front, and γmax/γmean against axial strain for every setting."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from granular_material.results.plots import pyplot, save_figure
from granular_material.results.trade_plots import pareto_front

__all__ = ["BAND_PARETO_MEASURES", "plot_band_histories", "plot_band_pareto"]

#: the band table's columns drawn against the cost, with their axis labels
BAND_PARETO_MEASURES = {
    "onset_delay_pp": "band onset after the reference's [% axial strain]",
    "stress_ratio_10_pct": "|σ1/σ3 at 10 % error| [%]",
    "volumetric_strain_10_pct": "|εv at 10 % error| [% of the reference's]",
}


def plot_band_pareto(table: pd.DataFrame, path: str | Path,
                     never_formed: float) -> Path:
    """One panel per :data:`BAND_PARETO_MEASURES`: the error's size against the cost (DEM
    particle-steps over the reference's) of every row of the band table, its Pareto front
    drawn; presets in red. A row whose band did not form on every seed is drawn at
    ``never_formed`` (the onset panel) with an x."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(BAND_PARETO_MEASURES), figsize=(15, 4.8),
                             constrained_layout=True)
    for ax, (column, label) in zip(axes, BAND_PARETO_MEASURES.items(), strict=True):
        error = table[column].abs().to_numpy(dtype=float)
        if column == "onset_delay_pp":
            error = np.where(_all_banded(table), error, never_formed)
        cost = table["cost_ratio"].to_numpy(dtype=float)
        ok = np.isfinite(error) & np.isfinite(cost)
        shown = np.maximum(error, 1e-2)
        preset = (table["knob"] == "preset").to_numpy()
        unformed = ~_all_banded(table) if column == "onset_delay_pp" else np.zeros_like(ok)
        for mask, colour, marker in ((ok & ~preset & ~unformed, "tab:blue", "o"),
                                     (ok & preset & ~unformed, "tab:red", "o"),
                                     (ok & unformed, "k", "x")):
            ax.scatter(cost[mask], shown[mask], color=colour, marker=marker, s=26)
        front = pareto_front(cost[ok], error[ok])
        ax.plot(cost[ok][front], shown[ok][front], color="tab:blue", lw=1)
        for i in np.flatnonzero(ok):
            ax.annotate(f"{table['knob'].iloc[i]}={table['value'].iloc[i]}",
                        (cost[i], shown[i]), fontsize=6, alpha=0.7, xytext=(3, 2),
                        textcoords="offset points")
        if ok.any():
            ax.set_xscale("log")
            ax.set_yscale("log")
        else:
            ax.text(0.5, 0.5, "no finite measure", ha="center", transform=ax.transAxes)
        ax.set_xlabel("cost [DEM particle-steps / the reference's]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, which="both")
    try:
        return save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)


def _all_banded(table: pd.DataFrame) -> np.ndarray:
    """Whether every seed of each row formed its band ("k/k" in ``banded``)."""
    parts = table["banded"].str.split("/", expand=True)
    return (parts[0] == parts[1]).to_numpy()


def plot_band_histories(histories: Mapping[str, Mapping[str, list[pd.DataFrame]]],
                        path: str | Path, threshold: float) -> Path:
    """γmax/γmean against axial strain [%]: one panel per knob (``histories``: knob →
    value → the seeds' histories, as
    :func:`~granular_material.results.band_measures.localisation_history` gives them), each
    value's seeds drawn in one colour, the reference's in black; the onset's threshold
    dashed."""
    plt = pyplot()
    names = list(histories)
    columns = min(3, len(names))
    rows = -(-len(names) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(5 * columns, 3.6 * rows),
                             constrained_layout=True, squeeze=False, sharey=True)
    for ax, knob in zip(axes.flat, names, strict=False):
        for index, (value, seeds) in enumerate(histories[knob].items()):
            colour = "k" if value == "defaults" else f"C{index}"
            for k, history in enumerate(seeds):
                ax.plot(100 * history["axial_strain"], history["ratio"], color=colour, lw=1,
                        alpha=0.8, label=value if k == 0 else None)
        ax.axhline(threshold, ls="--", color="0.5", lw=0.8)
        ax.set_title(knob, fontsize=9)
        ax.set_xlabel("axial strain [%]")
        ax.set_ylabel("γmax / γmean")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    try:
        return save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
