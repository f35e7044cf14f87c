"""The figures of the reproduction report (Figs. 3–11 of Wu et al. 2025, ours). Axial
strain, stress and volumetric strain are drawn compression positive."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from granular_material.results.plots import pyplot, save_figure

__all__ = ["plot_coupled", "plot_fits", "plot_histories", "plot_ratio_by_size",
           "plot_resolution", "plot_size_curves", "plot_spectra", "plot_speedup"]

#: the box rules, as the figures name them
_RULE_TITLES = {"cell": "cell rule: ε = 2⁻ᵏL, k = 1…8",
                "physical": "physical rule: ε = 2.4–38.4 mm"}


def _save(fig: Figure, path: Path) -> Path:
    """``fig`` written to ``path`` (PNG) and closed."""
    try:
        return save_figure(fig, path, dpi=110)
    finally:
        pyplot().close(fig)


def plot_spectra(spectra: pd.DataFrame, sizes: tuple[int, ...], path: Path) -> Path:
    """Fig. 3: q–D_q and α–f(α), the seeds' mean, for the RVE sizes ``sizes`` [discs], one
    row per box rule."""
    plt = pyplot()
    rules = [rule for rule in _RULE_TITLES if (spectra["box_rule"] == rule).any()]
    fig, axes = plt.subplots(len(rules), 2, figsize=(9, 3.6 * len(rules)),
                             constrained_layout=True, squeeze=False)
    for (left, right), rule in zip(axes, rules, strict=True):
        of_rule = spectra[spectra["box_rule"] == rule]
        for discs in sizes:
            mean = of_rule[of_rule["discs"] == discs].groupby("q").mean(numeric_only=True)
            label = f"{discs} discs"
            left.plot(mean.index, mean["Dq"], marker=".", label=label)
            right.plot(mean["alpha"], mean["f"], marker=".", label=label)
        left.set(xlabel="q", ylabel="$D_q$", title=f"generalised dimensions ({rule} rule)")
        right.set(xlabel="α", ylabel="f(α)", title=f"singularity spectrum ({rule} rule)")
        left.legend(fontsize=8)
    return _save(fig, path)


def _band(ax, x: pd.Index, mean: pd.Series, std: pd.Series, color: str, label: str) -> None:
    """The seeds' mean as a line and mean ± one standard deviation as a shaded band."""
    ax.plot(x, mean, "-", color=color, label=label)
    ax.fill_between(x, mean - std, mean + std, color=color, alpha=0.25, lw=0)


def plot_ratio_by_size(indices: pd.DataFrame, settle: dict[str, int], path: Path) -> Path:
    """Fig. 4: α0/D0 of every RVE against its number of discs, the seeds' mean with a band
    of ± one standard deviation (the seed scatter), and the size from which it has settled;
    one panel per box rule (``settle``: rule → discs)."""
    plt = pyplot()
    rules = [rule for rule in _RULE_TITLES if rule in settle]
    fig, axes = plt.subplots(1, len(rules), figsize=(5.5 * len(rules), 3.8),
                             constrained_layout=True, squeeze=False)
    for ax, rule in zip(axes[0], rules, strict=True):
        of_rule = indices[indices["box_rule"] == rule]
        ax.plot(of_rule["discs"], of_rule["alpha0_over_D0"], "o", alpha=0.4, ms=4,
                label="one RVE")
        stats = of_rule.groupby("discs")["alpha0_over_D0"].agg(["mean", "std"])
        _band(ax, stats.index, stats["mean"], stats["std"].fillna(0.0), "k",
              "seeds' mean ± std")
        ax.axvline(settle[rule], color="tab:red", ls="--",
                   label=f"settled from {settle[rule]} discs")
        ax.set(xlabel="discs per RVE", ylabel="α0/D0", title=_RULE_TITLES[rule])
        ax.legend(fontsize=8)
    return _save(fig, path)


def plot_resolution(table: pd.DataFrame, path: Path) -> Path:
    """The resolution study: D0 and α0/D0 of the same RVEs against the pixel [mm], the
    seeds' mean with a ± one standard deviation band, one line per box rule."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    colors = {"cell": "tab:blue", "physical": "tab:orange"}
    for ax, column, label in zip(axes, ("D0", "alpha0_over_D0"), ("$D_0$", "α0/D0"),
                                 strict=True):
        for rule, of_rule in table.groupby("box_rule"):
            stats = of_rule.groupby("pixel_request")[column].agg(["mean", "std"])
            _band(ax, 1e3 * stats.index, stats["mean"], stats["std"].fillna(0.0),
                  colors.get(str(rule), "k"), f"{rule} rule")
            ax.plot(1e3 * of_rule["pixel_request"], of_rule[column], "o", ms=3, alpha=0.4,
                    color=colors.get(str(rule), "k"))
        ax.set(xscale="log", xlabel="requested pixel [mm]", ylabel=label,
               title=f"{label} of {int(table['discs'].iloc[0])}-disc RVEs by pixel")
        pixels = sorted(1e3 * table["pixel_request"].unique())
        ax.set_xticks(pixels, [f"{v:g}" for v in pixels])
        ax.minorticks_off()
        ax.invert_xaxis()
        ax.legend(fontsize=8)
    return _save(fig, path)


def plot_size_curves(curves: pd.DataFrame, path: Path) -> Path:
    """Fig. 5: σ1/σ3 and εv against axial strain, every seed thin, per size."""
    plt = pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6, 6), sharex=True,
                                      constrained_layout=True)
    for index, (discs, group) in enumerate(curves.groupby("discs")):
        colour = f"C{index}"
        for n, (_, seed) in enumerate(group.groupby("seed")):
            label = f"{discs} discs" if n == 0 else None
            top.plot(100 * seed["axial_strain"], seed["stress_ratio"], color=colour, lw=0.8,
                     label=label)
            bottom.plot(100 * seed["axial_strain"], -100 * seed["volumetric_strain"],
                        color=colour, lw=0.8)
    top.set(ylabel="σ1/σ3")
    bottom.set(xlabel="axial strain [%]", ylabel="εv [%] (compression +)")
    top.legend(fontsize=8)
    return _save(fig, path)


def plot_coupled(fem: pd.DataFrame, dem: pd.DataFrame, title: str, path: Path) -> Path:
    """Figs. 6 and 7: the FEM × DEM curve against the pure-DEM tests (each thin, their mean
    thick)."""
    plt = pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6, 6), sharex=True,
                                      constrained_layout=True)
    for n, (_, rve) in enumerate(dem.groupby("rve")):
        label = "pure DEM" if n == 0 else None
        top.plot(100 * rve["axial_strain"], rve["stress_ratio"], color="0.6", lw=0.8,
                 label=label)
        bottom.plot(100 * rve["axial_strain"], -100 * rve["volumetric_strain"], color="0.6",
                    lw=0.8)
    top.plot(100 * fem["axial_strain"], fem["stress_ratio"], "o-", ms=3, color="tab:red",
             label="FEM × DEM")
    bottom.plot(100 * fem["axial_strain"], -100 * fem["volumetric_strain"], "o-", ms=3,
                color="tab:red")
    top.set(ylabel="σ1/σ3", title=title)
    bottom.set(xlabel="axial strain [%]", ylabel="εv [%] (compression +)")
    top.legend(fontsize=8)
    return _save(fig, path)


def plot_histories(histories: pd.DataFrame, path: Path) -> Path:
    """Fig. 9: σ1 − σ3, volumetric strain, D0 and α0 of the chosen RVEs through the
    loading."""
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(9, 6), sharex=True, constrained_layout=True)
    panels = (("deviator", "σ1 − σ3 [kPa]", 1e-3), ("contraction", "εv [%] (compression +)",
                                                      100.0),
              ("D0", "$D_0$", 1.0), ("alpha0", "$α_0$", 1.0))
    for ax, (column, label, factor) in zip(axes.flat, panels, strict=True):
        for (role, point), history in histories.groupby(["role", "point"], sort=False):
            ax.plot(100 * history["axial_strain"], factor * history[column], "o-", ms=3,
                    label=f"{role} (point {point})")
        ax.set(ylabel=label)
    for ax in axes[1]:
        ax.set(xlabel="axial strain [%]")
    axes[0, 0].legend(fontsize=8)
    return _save(fig, path)


def plot_fits(histories: pd.DataFrame, fits: pd.DataFrame, path: Path) -> Path:
    """Fig. 10: D0 and α0 against the volumetric strain with their least-squares lines."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8), constrained_layout=True)
    for ax, index in zip(axes, ("D0", "alpha0"), strict=True):
        for n, ((role, _point), history) in enumerate(histories.groupby(["role", "point"],
                                                                       sort=False)):
            fit = fits[(fits["role"] == role) & (fits["index"] == index)].iloc[0]
            ev = history["contraction"].to_numpy()
            ax.plot(100 * ev, history[index], "o", ms=3, color=f"C{n}",
                    label=f"{role}: slope {fit['slope']:.3g}, R² {fit['r2']:.2f}")
            line = np.linspace(ev.min(), ev.max(), 2)
            ax.plot(100 * line, fit["intercept"] + fit["slope"] * line, color=f"C{n}")
        ax.set(xlabel="εv [%] (compression +)", ylabel={"D0": "$D_0$", "alpha0": "$α_0$"}[index])
        ax.legend(fontsize=7)
    return _save(fig, path)


def plot_speedup(table: pd.DataFrame, path: Path) -> Path:
    """Fig. 11: speed-up of the batched DEM over serial stepping against the number of
    RVEs, per RVE size."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.8), constrained_layout=True)
    for discs, group in table.groupby("discs"):
        ax.plot(group["rves"], group["speed_up"], "o-", label=f"{discs} discs")
    ax.set(xscale="log", xlabel="RVEs in the batch", ylabel="speed-up over serial",
           title=f"device {table['device'].iloc[0]}")
    ax.legend(fontsize=8)
    return _save(fig, path)
