"""The figures and tables of benchmarks/regularisation_study.py: ``report.md`` and the
``*.png`` beside it, from the runs' folders and ``results.json``."""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from granular_material.results import read_points


def _label(length: float) -> str:
    return "no regularisation" if length == 0 else f"second gradient, ℓ = {length * 1e3:g} mm"


def _f(value: Any, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value:.{digits}f}"


def _mm(value: Any) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value * 1e3:.1f}"


def _panels(table: pd.DataFrame, lengths: list[float], meshes: list[str]
            ) -> tuple[Any, list[tuple[Any, str, float, pd.DataFrame]]]:
    """A figure of one panel per internal length (rows) and mesh (columns), ticks off, and
    each panel with its mesh, length and row of ``table`` (empty where that run is not)."""
    fig, axes = plt.subplots(len(lengths), len(meshes), figsize=(2.3 * len(meshes),
                                                                   3.9 * len(lengths)),
                             squeeze=False)
    panels = []
    for i, length in enumerate(lengths):
        for j, mesh in enumerate(meshes):
            ax = axes[i, j]
            ax.set_xticks([])
            ax.set_yticks([])
            line = table[(table["mesh"] == mesh) & (table["internal_length"] == length)]
            panels.append((ax, mesh, length, line))
    return fig, panels


def specimen_figures(out: Path, rows: list[dict[str, Any]]) -> list[str]:
    """Stress ratio against axial strain per internal length; the shear strain of every
    mesh at the last step; band width against element size."""
    table = pd.DataFrame(rows)
    lengths = sorted(table["internal_length"].unique())
    meshes = list(dict.fromkeys(table["mesh"]))
    fig, axes = plt.subplots(1, len(lengths), figsize=(4.2 * len(lengths), 3.6), sharey=True)
    for ax, length in zip(np.atleast_1d(axes), lengths, strict=True):
        for mesh in meshes:
            line = table[(table["mesh"] == mesh) & (table["internal_length"] == length)]
            if line.empty:
                continue
            steps = pd.read_csv(out / line["folder"].iloc[0] / "steps.csv")
            ax.plot(100 * steps["axial_strain"], steps["stress_ratio"], label=mesh)
        ax.set_title(_label(length), fontsize=10)
        ax.set_xlabel("axial strain [%]")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("σ1/σ3")
    np.atleast_1d(axes)[0].legend(title="quad8 elements", fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "specimen_curves.png", dpi=110)
    plt.close(fig)

    fig, panels = _panels(table, lengths, meshes)
    for ax, mesh, length, line in panels:
        if line.empty:
            continue
        points = read_points(out / line["folder"].iloc[0])
        last = points[points["step"] == points["step"].max()]
        ax.scatter(last["x"], last["y"], c=last["shear_strain"], s=4 if len(last) > 600
                   else 12, cmap="inferno", marker="s", linewidths=0)
        ax.set_aspect("equal")
        row = line.iloc[0]
        width = "no band found" if not row["band_count"] else (
            f"w = {_mm(row['band_width'])} mm")
        ax.set_title(f"{mesh}, {_label(length).split(',')[-1].strip()}\n{width}",
                     fontsize=8)
    fig.suptitle("shear strain γ at the last step", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "specimen_maps.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.4, 3.9))
    for k, length in enumerate(lengths):
        line = table[table["internal_length"] == length]
        if "active_band_width" in line:
            ax.plot(1e3 * line["element_size"], 1e3 * line["active_band_width"], "o-",
                    color=f"C{k}", label=f"{_label(length)}: active")
        ax.plot(1e3 * line["element_size"], 1e3 * line["band_width"], "x--", color=f"C{k}",
                alpha=0.6, label="accumulated γ" if k == len(lengths) - 1 else None)
    sizes = 1e3 * np.array(sorted(table["element_size"].unique()))
    ax.plot(sizes, sizes, "k:", label="one element")
    ax.set_xlabel("element size [mm]")
    ax.set_ylabel("band width (FWHM) [mm]")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "band_width.png", dpi=110)
    plt.close(fig)
    if "active_band_width" not in table:
        return ["specimen_curves.png", "specimen_maps.png", "band_width.png"]

    from granular_material.results.active_bands import active_bands, incremental_points

    fig, panels = _panels(table, lengths, meshes)
    for ax, mesh, length, line in panels:
        if line.empty:
            ax.axis("off")
            continue
        points = read_points(out / line["folder"].iloc[0])
        if points["step"].nunique() < 2:
            continue
        field = incremental_points(points)
        ax.tricontourf(field["x"], field["y"], field["shear_strain"], levels=24,
                       cmap="inferno")
        low, high = field[["x", "y"]].min().to_numpy(), field[["x", "y"]].max().to_numpy()
        for band in active_bands(points):
            t = np.radians(band.inclination_deg)
            along = np.array([np.cos(t), np.sin(t)])
            normal = np.array([-np.sin(t), np.cos(t)])
            centre = np.array([band.centre_x, band.centre_y])
            for side in (-0.5, 0.0, 0.5):
                ends = centre + side * band.width * normal + np.outer([-1, 1], along)
                ax.plot(ends[:, 0], ends[:, 1], "-" if side == 0 else "--", color="c",
                        lw=0.8)
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(low[1], high[1])
        ax.set_aspect("equal")
        row = line.iloc[0]
        window = row["active_window"]
        width = "no band found" if not row["active_band_count"] else (
            f"w = {_mm(row['active_band_width'])} mm")
        span = (f"{100 * window[0]:.1f}–{100 * window[1]:.1f} %"
                if len(window) == 2 else "")
        ax.set_title(f"{mesh}, {_label(length).split(',')[-1].strip()}\n{span}: {width}",
                     fontsize=8)
    fig.suptitle("shear strain of the increment over the last fifth of the axial strain;\n"
                 "the fitted bands' axes (solid) and half widths (dashed)", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(out / "specimen_active_maps.png", dpi=110)
    plt.close(fig)
    return ["specimen_curves.png", "specimen_maps.png", "band_width.png",
            "specimen_active_maps.png"]


def field_differences(out: Path, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """For each internal length, how far apart two meshes' fields are at their last common
    step, point by point: the finer mesh's γ interpolated (linearly) onto the coarser
    one's Gauss points, the root-mean-square difference over the coarser γ's root mean
    square, for the accumulated γ and the increment over the last fifth of the strain."""
    from scipy.interpolate import griddata

    from granular_material.results.active_bands import incremental_points

    table = pd.DataFrame(rows)
    out_rows = []
    for length, group in table.groupby("internal_length", sort=True):
        group = group.sort_values("element_size", ascending=False)
        folders = list(zip(group["mesh"], group["folder"], strict=True))
        for (coarse, a), (fine, b) in itertools.pairwise(folders):
            pa, pb = (read_points(out / f) for f in (a, b))
            last = min(int(pa["step"].max()), int(pb["step"].max()))
            if last < 1:
                continue
            row = {"internal_length": length, "meshes": f"{coarse} / {fine}", "step": last}
            fields = {"accumulated": (pa[pa["step"] == last], pb[pb["step"] == last]),
                      "increment": (incremental_points(pa, last),
                                    incremental_points(pb, last))}
            for name, (fa, fb) in fields.items():
                at = griddata(fb[["x", "y"]].to_numpy(), fb["shear_strain"].to_numpy(),
                              fa[["x", "y"]].to_numpy(), method="linear")
                ok = np.isfinite(at)
                ga = fa["shear_strain"].to_numpy()[ok]
                row[name] = float(np.sqrt(np.mean((ga - at[ok]) ** 2))
                                  / np.sqrt(np.mean(ga ** 2)))
            out_rows.append(row)
    return out_rows


def dem_figure(out: Path, rows: list[dict[str, Any]]) -> list[str]:
    table = pd.DataFrame(rows)
    fig, axes = plt.subplots(1, 2, figsize=(8.5, 3.6), sharey=True)
    lengths = sorted(table["internal_length"].unique())
    meshes = list(dict.fromkeys(table["mesh"]))
    for ax, column, strain in zip(axes, ("ratio_5", "ratio_10"), (5, 10), strict=True):
        for k, length in enumerate(lengths):
            for j, mesh in enumerate(meshes):
                values = table[(table["mesh"] == mesh)
                               & (table["internal_length"] == length)][column]
                x = j + 0.15 * (2 * k - 1)
                ax.plot(np.full(len(values), x), values, "o", color=f"C{k}",
                        label=_label(length) if j == 0 else None)
        ax.set_xticks(range(len(meshes)), meshes)
        ax.set_xlabel("quad8 elements")
        ax.set_title(f"σ1/σ3 at {strain} % (each dot a seed)", fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "dem_ratios.png", dpi=110)
    plt.close(fig)
    return ["dem_ratios.png"]


def footing_figure(out: Path, rows: list[dict[str, Any]]) -> list[str]:
    table = pd.DataFrame(rows)
    if "continuation" not in table:
        table["continuation"] = "load"
    panels = [("mc", "load", "softening Mohr–Coulomb twin"), ("dem", "load", "DEM RVEs"),
              ("mc", "arc-length", "the twin by arc length")]
    panels = [p for p in panels if p[1] == "load"
              or (table["continuation"] == "arc-length").any()]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.5 * len(panels), 3.8), sharey=True)
    for ax, (kind, continuation, title) in zip(axes, panels, strict=True):
        rows = table[(table["material"] == kind) & (table["continuation"] == continuation)]
        meshes = list(dict.fromkeys(rows["mesh"]))
        lengths = sorted(rows["internal_length"].unique())
        styles = dict(zip(lengths, ("--", "-", "-.", ":"), strict=False))
        for _, row in rows.iterrows():
            steps = pd.read_csv(out / row["folder"] / "steps.csv")
            ax.plot(-1e3 * steps["footing_displacement_y"],
                    -steps["footing_force_y"] / 0.05 / 1e3, styles[row["internal_length"]],
                    color=f"C{meshes.index(row['mesh'])}",
                    label=f"{row['mesh']}, {_label(row['internal_length'])}")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("settlement [mm]")
        ax.grid(alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=7)
    axes[0].set_ylabel("bearing pressure [kPa]")
    fig.tight_layout()
    fig.savefig(out / "footing_curves.png", dpi=110)
    plt.close(fig)
    return ["footing_curves.png"]


def write_report(out: Path, results: dict[str, Any]) -> None:
    """``report.md`` and the figures of the stages in ``results``."""
    lines = ["# Regularisation study: the numbers", "",
             "Written by `benchmarks/regularisation_study.py` (see README.md beside it for "
             "what they mean).", ""]
    if results.get("specimen"):
        specimen_figures(out, results["specimen"])
        lines += ["## Mohr–Coulomb softening specimen", "",
                  "| mesh | ℓ [mm] | steps | peak σ1/σ3 | at ε [%] | σ1/σ3 at 5 % | bands | "
                  "widths [mm] | lengths [mm] | angles [°] | iterations / step | time [s] | "
                  "linear solve [s] |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in results["specimen"]:
            angles = ", ".join(f"{a:.0f}" for a in r["band_angles"]) or "–"
            widths = ", ".join(_mm(w) for w in r["band_widths"]) or "–"
            lengths = ", ".join(_mm(w) for w in r.get("band_lengths", [])) or "–"
            lines.append(
                f"| {r['mesh']} | {r['internal_length'] * 1e3:g} | {r['steps_completed']} | "
                f"{_f(r['peak_ratio'])} | {_f(100 * r['peak_strain'], 1)} | "
                f"{_f(r['ratio_5'])} | {r['band_count']} | {widths} | {lengths} | "
                f"{angles} | {_f(r['iterations'], 1)} | {_f(r['time_s'], 1)} | "
                f"{_f(r['linear_solve_s'], 1)} |")
        lines += ["", "![stress ratio](specimen_curves.png)", "",
                  "![shear strain](specimen_maps.png)", ""]
        if any("active_band_width" in r for r in results["specimen"]):
            lines += ["Active bands: Gaussian ridges fitted to the shear strain of the last "
                      "fifth of the axial strain (`granular_material.results.active_bands`), "
                      "beside the accumulated γ's bands of the table above:", "",
                      "| mesh | ℓ [mm] | increment [%] | bands | widths [mm] | mean [mm] | "
                      "angles [°] | fit residual | mean width at 3 % [mm] | at 4 % [mm] | "
                      "accumulated γ: widths [mm] |",
                      "|---|---|---|---|---|---|---|---|---|---|---|"]
            for r in results["specimen"]:
                window = r.get("active_window") or []
                span = (f"{100 * window[0]:.1f}–{100 * window[1]:.1f}" if len(window) == 2
                        else "–")
                at = r.get("active_width_at", {})
                lines.append(
                    f"| {r['mesh']} | {r['internal_length'] * 1e3:g} | {span} | "
                    f"{r.get('active_band_count', 0)} | "
                    f"{', '.join(_mm(w) for w in r.get('active_widths', [])) or '–'} | "
                    f"{_mm(r.get('active_band_width'))} | "
                    f"{', '.join(f'{a:.0f}' for a in r.get('active_angles', [])) or '–'} | "
                    f"{_f(r.get('active_residual'), 2)} | {_mm(at.get('3'))} | "
                    f"{_mm(at.get('4'))} | "
                    f"{', '.join(_mm(w) for w in r['band_widths']) or '–'} |")
            lines += ["", "![active bands](specimen_active_maps.png)", ""]
            lines += ["Two meshes' fields point by point at their last common step (the "
                      "finer mesh's γ interpolated onto the coarser one's Gauss points; "
                      "root-mean-square difference over the coarser γ's root mean square):",
                      "", "| ℓ [mm] | meshes | step | accumulated γ | increment |",
                      "|---|---|---|---|---|"]
            for d in field_differences(out, results["specimen"]):
                lines.append(f"| {d['internal_length'] * 1e3:g} | {d['meshes']} | "
                             f"{d['step']} | {100 * d['accumulated']:.1f} % | "
                             f"{100 * d['increment']:.1f} % |")
            lines.append("")
        lines += ["![band width](band_width.png)", ""]
    if results.get("dem"):
        dem_figure(out, results["dem"])
        lines += ["## FEM × DEM specimen", "",
                  "| mesh | seed | ℓ [mm] | steps | peak σ1/σ3 | σ1/σ3 at 5 % | at 10 % | "
                  "bands | band width [mm] | angles [°] | active bands: widths [mm] | "
                  "angles [°] | iterations / step | time [s] |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in results["dem"]:
            angles = ", ".join(f"{a:.0f}" for a in r["band_angles"]) or "–"
            lines.append(
                f"| {r['mesh']} | {r['seed']} | {r['internal_length'] * 1e3:g} | "
                f"{r['steps_completed']} | {_f(r['peak_ratio'])} | {_f(r['ratio_5'])} | "
                f"{_f(r['ratio_10'])} | {r['band_count']} | {_mm(r['band_width'])} | "
                f"{angles} | "
                f"{', '.join(_mm(w) for w in r.get('active_widths', [])) or '–'} | "
                f"{', '.join(f'{a:.0f}' for a in r.get('active_angles', [])) or '–'} | "
                f"{_f(r['iterations'], 1)} | {_f(r['time_s'], 0)} |")
        table = pd.DataFrame(results["dem"])
        lines += ["", "Mean ± standard deviation over the seeds:", "",
                  "| mesh | ℓ [mm] | σ1/σ3 at 5 % | σ1/σ3 at 10 % |", "|---|---|---|---|"]
        for (mesh, length), group in table.groupby(["mesh", "internal_length"], sort=False):
            lines.append(f"| {mesh} | {length * 1e3:g} | "
                         f"{_f(group['ratio_5'].mean())} ± {_f(group['ratio_5'].std())} | "
                         f"{_f(group['ratio_10'].mean())} ± {_f(group['ratio_10'].std())} |")
        lines += ["", "![DEM specimen](dem_ratios.png)", ""]
    if results.get("footing"):
        footing_figure(out, results["footing"])
        lines += ["## Footing", "",
                  "| material | mesh | ℓ [mm] | stepping | steps | settlement reached [mm] | "
                  "peak pressure [kPa] | at [mm] | pressure at the end [kPa] | "
                  "iterations / step | time [s] |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in results["footing"]:
            lines.append(
                f"| {r['material']} | {r['mesh']} | {r['internal_length'] * 1e3:g} | "
                f"{r.get('continuation', 'load')} | "
                f"{r['steps_completed']} | {_mm(r['settlement_reached'])} | "
                f"{_f(r['peak_pressure'] / 1e3, 0)} | {_mm(r['peak_settlement'])} | "
                f"{_f(r['final_pressure'] / 1e3, 0)} | {_f(r['iterations'], 1)} | "
                f"{_f(r['time_s'], 0)} |")
        lines += ["", "![footing](footing_curves.png)", ""]
    (out / "report.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
