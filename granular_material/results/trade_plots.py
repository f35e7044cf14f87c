"""Figures of the trade study: error against wall time with the Pareto front, and one
figure per knob."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from granular_material.results.plots import pyplot, save_figure

__all__ = ["pareto_front", "plot_knob", "plot_pareto"]

_COLOURS = {"dem": "tab:blue", "element": "tab:orange", "specimen": "tab:green"}


def pareto_front(cost: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Indices of the points no other point beats in both ``cost`` and ``error`` (lower is
    better), by increasing cost."""
    order = np.lexsort((error, cost))
    front, best = [], np.inf
    for i in order:
        if error[i] < best:
            front.append(int(i))
            best = error[i]
    return np.array(front, dtype=int)


def plot_pareto(table: pd.DataFrame, error: pd.Series, path: str | Path) -> Path:
    """``error`` [%] against wall time [s] of every row of ``trade.csv``, one marker per
    run coloured by test (x: a run that stopped short, left out of the front), each test's
    Pareto front drawn; errors below 10⁻³ % (the reference itself) are drawn at 10⁻³."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 5), constrained_layout=True)
    shown = table.assign(accuracy=error.to_numpy())
    shown = shown[np.isfinite(shown["accuracy"]) & (shown["wall_s"] > 0)]
    failed = shown["error"].fillna("") != "" if "error" in shown else False
    for test, group in shown.groupby("test"):
        colour = _COLOURS.get(str(test), "k")
        ran = group[~failed[group.index]] if "error" in shown else group
        stopped = group[failed[group.index]] if "error" in shown else group.iloc[:0]
        ax.scatter(ran["wall_s"], ran["accuracy"].clip(lower=1e-3), s=22, color=colour,
                   label=str(test))
        ax.scatter(stopped["wall_s"], stopped["accuracy"].clip(lower=1e-3), s=30,
                   color=colour, marker="x")
        front = pareto_front(ran["wall_s"].to_numpy(), ran["accuracy"].to_numpy())
        ax.plot(ran["wall_s"].to_numpy()[front],
                ran["accuracy"].clip(lower=1e-3).to_numpy()[front], color=colour, lw=1)
        for _, row in group.iterrows():
            ax.annotate(f"{row['knob']}={row['value']}", (row["wall_s"],
                        max(row["accuracy"], 1e-3)), fontsize=6, alpha=0.7,
                        xytext=(3, 2), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time of the run [s]")
    ax.set_ylabel("|peak σ1/σ3 error| [% of the reference peak]")
    ax.legend(title="test")
    try:
        return save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)


def plot_knob(rows: pd.DataFrame, knob: str, path: str | Path) -> Path:
    """Errors [%] and wall time [s] against the values of one knob."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    x = np.arange(len(rows))
    ax.plot(x, rows["peak_error_pct"].abs(), "o-", label="|peak σ1/σ3| error")
    ax.plot(x, rows["stress_ratio_rms_pct"], "s-", label="RMS σ1/σ3")
    if rows["volumetric_strain_rms_pct"].notna().any():
        ax.plot(x, rows["volumetric_strain_rms_pct"], "^-", label="RMS εv")
    ax.set_xticks(x, [str(v) for v in rows["value"]], rotation=30)
    ax.set_xlabel(knob)
    ax.set_ylabel("error [% of the reference]")
    ax.legend(loc="upper left", fontsize=8)
    twin = ax.twinx()
    twin.plot(x, rows["wall_s"], "k:", marker="x", label="wall time")
    twin.set_ylabel("wall time [s] (dotted)")
    try:
        return save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
