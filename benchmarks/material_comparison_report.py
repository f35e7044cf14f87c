"""Figures, ``results.json`` and ``report.md`` of ``benchmarks/material_comparison.py``
(the runs' folders in ``out``; pressures Pa, strains compression positive in the figures)."""

from __future__ import annotations

import json
import math
import shutil
import statistics
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from material_comparison_measures import (
    LOCALISED,
    band_angles,
    bearing_curve,
    localisation_series,
    material_file,
    onset_strain,
    prandtl_nq,
    quadrant_angles,
)

from granular_material.results import read_points

#: the footing scene's half-width B [m] and surcharge q [Pa]
HALF_WIDTH, SURCHARGE = 0.05, 20e3


def _steps(folder: Path) -> pd.DataFrame | None:
    path = folder / "steps.csv"
    return pd.read_csv(path) if path.is_file() else None


def _summary(folder: Path) -> dict[str, Any]:
    path = folder / "summary.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def _median(costs: dict, name: str, key: str = "run_median_s") -> float | None:
    c = costs.get(name) or {}
    return c.get(key)


def element_results(out: Path, rves: int) -> dict[str, Any]:
    """Peaks and curves of the single elements; the figure ``element.png``."""
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    res: dict[str, Any] = {"dem": []}
    for i in range(rves):
        s = _steps(out / f"element-dem-{i}")
        if s is None:
            continue
        k = int(s["stress_ratio"].idxmax())
        res["dem"].append({"rve": i, "peak_ratio": float(s["stress_ratio"].max()),
                           "strain_at_peak": float(s["axial_strain"][k]),
                           "final_ratio": float(s["stress_ratio"].iloc[-1]),
                           "final_volumetric": float(s["volumetric_strain"].iloc[-1]),
                           "iterations": float(s["iterations"][1:].mean())})
        for a, y in zip(ax, (s["stress_ratio"], -s["volumetric_strain"] * 100), strict=True):
            a.plot(s["axial_strain"] * 100, y, lw=0.9, alpha=0.7, label=f"DEM, RVE {i}")
    s = _steps(out / "element-mc")
    if s is not None:
        k = int(s["stress_ratio"].idxmax())
        res["mc"] = {"peak_ratio": float(s["stress_ratio"].max()),
                     "strain_at_peak": float(s["axial_strain"][k]),
                     "final_ratio": float(s["stress_ratio"].iloc[-1]),
                     "final_volumetric": float(s["volumetric_strain"].iloc[-1]),
                     "iterations": float(s["iterations"][1:].mean())}
        for a, y in zip(ax, (s["stress_ratio"], -s["volumetric_strain"] * 100), strict=True):
            a.plot(s["axial_strain"] * 100, y, "k--", lw=2, label="Mohr–Coulomb (calibrated)")
    ax[0].set_ylabel("σyy/σxx [-]")
    ax[1].set_ylabel("volumetric strain εv [%] (contraction positive)")
    for a in ax:
        a.set_xlabel("axial strain ε1 [%]")
        a.grid(alpha=0.3)
    ax[0].legend(fontsize=8)
    fig.suptitle("single element (Q4, 2 × 2 points) at σ3 = 100 kPa: DEM RVEs against "
                 "their calibrated Mohr–Coulomb", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "element.png", dpi=110)
    plt.close(fig)
    return res


def _map(ax: Any, points: pd.DataFrame, step: int, title: str) -> None:
    at = points[points["step"] == step]
    top = max(float(at["shear_strain"].max()), 1e-12)
    tc = ax.tricontourf(at["x"], at["y"], at["shear_strain"], cmap="viridis",
                        levels=np.linspace(0.0, top * 1.0001, 15))  # from 0: a uniform
    # field is one colour
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    plt.colorbar(tc, ax=ax, shrink=0.8, label="γ [-]")


#: axial strains [-] at which the band is measured
BAND_STRAINS = (0.02, 0.05, 0.1)


def _step_at(points: pd.DataFrame, strain: float) -> int:
    """The step of ``points`` whose axial strain is nearest ``strain``."""
    g = points.groupby("step")["axial_strain"].first()
    return int((g - strain).abs().idxmin())


#: the specimens: folder suffix, line style, label
SPECIMENS = (("dem", "C0-", "DEM, smooth"), ("mc", "k--", "Mohr–Coulomb, smooth"),
             ("dem-rough", "C3-", "DEM, rough"), ("mc-rough", "C1--", "Mohr–Coulomb, rough"))
_LABEL = {name: label for name, _, label in SPECIMENS}


def specimen_results(out: Path, phi: float, psi: float) -> dict[str, Any]:
    """Curves, localisation and band angles of the two specimens; ``specimen.png``."""
    from granular_material.results.localization import shear_band

    res: dict[str, Any] = {"references_deg": band_angles(phi, psi)}
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    tables = {}
    for name, style, label in SPECIMENS:
        s = _steps(out / f"specimen-{name}")
        if s is None:
            continue
        try:
            points = read_points(out / f"specimen-{name}")
        except FileNotFoundError:
            continue
        tables[name] = points
        loc = localisation_series(points)
        last = int(points["step"].max())
        band = shear_band(points, last)
        k = int(s["stress_ratio"].idxmax())
        res[name] = {"peak_ratio": float(s["stress_ratio"].max()),
                     "strain_at_peak": float(s["axial_strain"][k]),
                     "final_ratio": float(s["stress_ratio"].iloc[-1]),
                     "final_strain": float(s["axial_strain"].iloc[-1]),
                     "onset_strain": onset_strain(loc),
                     "ratio_final": float(loc["ratio"].iloc[-1]),
                     "band_final": band.as_dict(),
                     "bands": {f"{e:g}": shear_band(points, _step_at(points, e)).as_dict()
                               for e in BAND_STRAINS if e <= loc["axial_strain"].max() + 1e-9},
                     "quadrant_angles": {f"{e:g}": quadrant_angles(points, _step_at(points, e))
                                         for e in BAND_STRAINS
                                         if e <= loc["axial_strain"].max() + 1e-9},
                     "iterations": float(s["iterations"][1:].mean()),
                     "cutbacks": int(s["cutbacks"].sum()),
                     "error": _summary(out / f"specimen-{name}").get("error")}
        ax[0].plot(s["axial_strain"] * 100, s["stress_ratio"], style, label=label)
        ax[1].plot(s["axial_strain"] * 100, -s["volumetric_strain"] * 100, style, label=label)
        ax[2].plot(loc["axial_strain"] * 100, loc["ratio"], style, label=label)
    ax[2].axhline(LOCALISED, color="grey", ls=":", lw=1, label=f"{LOCALISED:g}: localised")
    for a, y in zip(ax, ("σyy/σxx [-]", "εv [%] (contraction positive)", "γmax/γmean [-]"),
                    strict=True):
        a.set_xlabel("axial strain [%]")
        a.set_ylabel(y)
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle("biaxial specimen, reduced scale (5 × 10 Q4, 200 points), σ3 = 100 kPa",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "specimen.png", dpi=110)
    plt.close(fig)
    if tables:
        fig, ax = plt.subplots(1, len(tables), figsize=(3.6 * len(tables), 5.5))
        ax = np.atleast_1d(ax)
        for a, (name, points) in zip(ax, tables.items(), strict=True):
            last = int(points["step"].max())
            strain = float(points[points["step"] == last]["axial_strain"].iloc[0])
            b = res[name]["band_final"]
            _map(a, points, last, f"{_LABEL[name]}, {strain:.1%}\nband "
                 f"{abs(b['inclination_deg']):.0f}°, γ in/out {b['localization']:.2f}")
        fig.tight_layout()
        fig.savefig(out / "specimen_maps.png", dpi=110)
        plt.close(fig)
    return res


def footing_results(out: Path, parameters: dict[str, float]) -> dict[str, Any]:
    """Bearing curves, Prandtl's q·N_q and the mechanisms; ``footing.png``."""
    phi = parameters["friction_angle"]
    phi_cs = parameters.get("critical_friction_angle", phi)
    res: dict[str, Any] = {"prandtl_kpa": {"phi": SURCHARGE * prandtl_nq(phi) / 1e3,
                                           "phi_cs": SURCHARGE * prandtl_nq(phi_cs) / 1e3}}
    fig, ax = plt.subplots(figsize=(7, 4.5))
    runs = {"dem": ("DEM (64-disc RVEs)", "C0-")}
    runs |= {"mc": ("MC as calibrated (softening)", "k--"),
             "mc-peak": ("MC perfectly plastic at φ", "C1-."),
             "mc-cs": ("MC perfectly plastic at φcs", "C2:"),
             "mc-peak-ul": ("MC at φ, updated-Lagrangian", "C4-")}
    top = 0.0
    for name, (label, style) in runs.items():
        s = _steps(out / f"footing-{name}")
        if s is None:
            continue
        c = bearing_curve(s, HALF_WIDTH)
        res[name] = {"steps": int(s["step"].max()), "max_pressure_kpa":
                     float(c["pressure"].max() / 1e3), "final_pressure_kpa":
                     float(c["pressure"].iloc[-1] / 1e3), "final_settlement_mm":
                     float(c["settlement"].iloc[-1] * 1e3),
                     "iterations": float(s["iterations"][1:].mean()),
                     "error": _summary(out / f"footing-{name}").get("error")}
        if name in PLOTTED:
            ax.plot(c["settlement"] * 1e3, c["pressure"] / 1e3, style, label=label, lw=1.2)
            top = max(top, float(c["pressure"].max() / 1e3))
    for key, ls, label in (("phi", "--", "φ"), ("phi_cs", ":", "φcs")):
        ax.axhline(res["prandtl_kpa"][key], color="grey", ls=ls, lw=1,
                   label=f"Prandtl q·N_q, {label}")
    ax.set_ylim(0, 1.15 * max(top, res["prandtl_kpa"]["phi"]))
    ax.set_xlabel("settlement [mm]")
    ax.set_ylabel("bearing pressure [kPa]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"strip footing, B/2 = {HALF_WIDTH * 1e3:.0f} mm, q = "
                 f"{SURCHARGE / 1e3:g} kPa (Guo & Zhao's RVE material)", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "footing.png", dpi=110)
    plt.close(fig)
    _footing_maps(out, res)
    return res


#: the footing runs in the figure: all (the softening twin's curve ends at its limit point)
PLOTTED = ("dem", "mc", "mc-peak", "mc-cs", "mc-peak-ul")


def _footing_maps(out: Path, res: dict[str, Any]) -> None:
    """γ of the DEM footing at its last step beside the Mohr–Coulomb runs' at the nearest
    settlement they reached: ``footing_maps.png``."""
    names = {"dem": "DEM", "mc-peak": "MC perfectly plastic at φ",
             "mc-cs": "MC perfectly plastic at φcs"}
    tables = {}
    for name in names:
        st = _steps(out / f"footing-{name}")
        if st is None:
            continue
        try:
            tables[name] = (read_points(out / f"footing-{name}"), st)
        except FileNotFoundError:
            continue
    if "dem" not in tables or len(tables) < 2:
        return
    dem_points, dem_steps = tables["dem"]
    settle = float(dem_steps["footing_settlement"].iloc[int(dem_points["step"].max())])
    fig, ax = plt.subplots(len(tables), 1, figsize=(7, 3.2 * len(tables)))
    for a, (name, (points, steps)) in zip(ax, tables.items(), strict=True):
        have = sorted(points["step"].unique())
        step = min(have, key=lambda k: abs(steps["footing_settlement"].iloc[k] - settle))
        _map(a, points, step, f"{names[name]}: γ at "
             f"{steps['footing_settlement'].iloc[step] * 1e3:.2f} mm settlement")
    res["maps_settlement_mm"] = settle * 1e3
    fig.tight_layout()
    fig.savefig(out / "footing_maps.png", dpi=110)
    plt.close(fig)


#: what ``--publish`` copies: the report, its numbers and its figures
PUBLISHED = ("report.md", "results.json", "element.png", "specimen.png", "specimen_maps.png",
             "footing.png", "footing_maps.png", "calibration-100k.png",
             "calibration-gz20k.png", "calibration-100k-400.png")


def publish(out: Path, target: Path) -> list[Path]:
    """Copy the report, ``results.json`` and the figures of ``out`` into ``target``."""
    target.mkdir(parents=True, exist_ok=True)
    done = []
    for name in PUBLISHED:
        if (out / name).is_file():
            shutil.copyfile(out / name, target / name)
            done.append(target / name)
    return done


def _fmt(x: float | None, f: str = ".3g") -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, f)


def write_report(out: Path, scale: dict[str, Any], costs: dict[str, Any]) -> dict[str, Any]:
    """All figures, ``results.json`` and ``report.md`` of the runs in ``out``."""
    cal = {}
    for tag in ("100k", "gz20k", f"100k-{scale.get('large_discs')}"):
        path = out / f"calibration-{tag}" / "calibration.json"
        if path.is_file():
            cal[tag] = json.loads(path.read_text())
            shutil.copyfile(path.with_name("calibration.png"), out / f"calibration-{tag}.png")
    p100 = material_file(out / "calibration-100k" / "mohr-coulomb.toml")
    p20 = material_file(out / "calibration-gz20k" / "mohr-coulomb.toml")
    results = {"scale": scale, "calibration": {k: {n: {"value": r["value"], "std": r["std"],
                                                       "min": r["min"], "max": r["max"]}
                                                   for n, r in v["readings"].items()}
                                               for k, v in cal.items()},
               "element": element_results(out, int(scale["rves"])),
               "specimen": specimen_results(out, p100["friction_angle"],
                                                        p100["dilation_angle"]),
               "footing": footing_results(out, p20), "costs": costs}
    (out / "results.json").write_text(json.dumps(results, indent=1, default=float) + "\n")
    (out / "report.md").write_text(_markdown(results), encoding="utf-8")
    return results


def _markdown(r: dict[str, Any]) -> str:
    lines = ["# DEM material against its calibrated Mohr–Coulomb: the numbers", "",
             "Written by `python benchmarks/material_comparison.py`; every time is the "
             "command's own (its `summary.json`), CPU, on the machine as it was shared.", "",
             "## Calibration (mean ± standard deviation across the RVEs [min, max])", "",
             "| RVEs | E [MPa] | ν | φ [°] | ψ [°] | φcs [°] | softening strain |",
             "|---|---|---|---|---|---|---|"]
    for tag, c in r["calibration"].items():
        def cell(n: str, k: float = 1.0, c: dict = c) -> str:
            x = c[n]
            return (f"{x['value'] * k:.3g} ± {x['std'] * k:.2g} "
                    f"[{x['min'] * k:.3g}, {x['max'] * k:.3g}]")
        lines.append(f"| {tag} | {cell('young', 1e-6)} | {cell('poisson')} | "
                     f"{cell('friction_angle')} | {cell('dilation_angle')} | "
                     f"{cell('critical_friction_angle')} | {cell('softening_strain')} |")
    e = r["element"]
    lines += ["", "## Single element (100 kPa)", "",
              "| run | peak σyy/σxx | ε1 at peak | σyy/σxx at the end | εv at the end | "
              "Newton iterations a step |", "|---|---|---|---|---|---|"]
    for d in e.get("dem", []):
        lines.append(f"| DEM RVE {d['rve']} | {d['peak_ratio']:.3f} | "
                     f"{d['strain_at_peak']:.2%} | {d['final_ratio']:.3f} | "
                     f"{d['final_volumetric']:.2%} | {d['iterations']:.2f} |")
    if "mc" in e:
        d = e["mc"]
        lines.append(f"| Mohr–Coulomb | {d['peak_ratio']:.3f} | {d['strain_at_peak']:.2%} | "
                     f"{d['final_ratio']:.3f} | {d['final_volumetric']:.2%} | "
                     f"{d['iterations']:.2f} |")
    s = r["specimen"]
    ref = s["references_deg"]
    lines += ["", "## Biaxial specimen (reduced scale, 100 kPa)", "",
              f"References for the calibrated φ, ψ: Coulomb {ref['coulomb']:.1f}°, Roscoe "
              f"{ref['roscoe']:.1f}°, Arthur {ref['arthur']:.1f}° (to the horizontal, the "
              "minor principal direction). Localised: γmax/γmean ≥ "
              f"{LOCALISED:g}.", "",
              "| run | peak σyy/σxx | at | end σyy/σxx | localised from | γmax/γmean at the "
              "end | band angle at 2 / 5 / 10 % | γ in/out at the end | elongation | "
              "iterations | cut-backs |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    quadrants = ["", "The band's angle in each quadrant about the centre (the arms of an X "
                 "of conjugate bands; elongation well below 1 says the specimen has no "
                 "single band), median [min, max]:", "",
                 "| run | " + " | ".join(f"{e:g}" for e in BAND_STRAINS) + " |",
                 "|---|" + "---|" * len(BAND_STRAINS)]
    for name, _, label in SPECIMENS:
        if name in s:
            d, b = s[name], s[name]["band_final"]
            lines.append(f"| {label} | {d['peak_ratio']:.3f} | {d['strain_at_peak']:.2%} | "
                         f"{d['final_ratio']:.3f} | {_fmt(d['onset_strain'], '.2%')} | "
                         f"{d['ratio_final']:.2f} | "
                         + " / ".join(f"{abs(x['inclination_deg']):.1f}°"
                                      for x in d["bands"].values()) + " | "
                         f"{b['localization']:.2f} | {b['elongation']:.2f} | "
                         f"{d['iterations']:.2f} | {d['cutbacks']} |")
            quadrants.append(f"| {label} | " + " | ".join(
                f"{statistics.median(a):.0f}° [{min(a):.0f}, {max(a):.0f}]" if a else "–"
                for a in d["quadrant_angles"].values()) + " |")
    lines += quadrants
    f = r["footing"]
    lines += ["", "## Footing (Guo & Zhao's material, q = 20 kPa)", "",
              f"Prandtl q·N_q: {f['prandtl_kpa']['phi']:.0f} kPa at φ, "
              f"{f['prandtl_kpa']['phi_cs']:.0f} kPa at φcs.", "",
              "| run | steps | largest pressure [kPa] | final pressure [kPa] | settlement [mm] "
              "| iterations | stopped by |", "|---|---|---|---|---|---|---|"]
    for name in ("dem", "mc", "mc-peak", "mc-cs", "mc-peak-ul"):
        if name in f:
            d = f[name]
            lines.append(f"| {name} | {d['steps']} | {d['max_pressure_kpa']:.0f} | "
                         f"{d['final_pressure_kpa']:.0f} | {d['final_settlement_mm']:.2f} | "
                         f"{d['iterations']:.2f} | {(d['error'] or '–')[:90]} |")
    lines += ["", "## Cost", "", "| run | its own time [s] (median) | process [s] (median) "
              "| repeats |", "|---|---|---|---|"]
    for name, c in r["costs"].items():
        lines.append(f"| {name} | {_fmt(c.get('run_median_s'))} | "
                     f"{_fmt(c.get('process_median_s'))} | {len(c.get('process_s', []))} |")
    pairs = [("single element (the 4 RVEs' median)", "element-dem-", "element-mc"),
             ("specimen, smooth", "specimen-dem", "specimen-mc"),
             ("specimen, rough", "specimen-dem-rough", "specimen-mc-rough"),
             ("footing (Mohr–Coulomb at φ, small strain)", "footing-dem", "footing-mc-peak")]
    lines += ["", "| problem | DEM / Mohr–Coulomb time |", "|---|---|"]
    for label, a, b in pairs:
        da = [c["run_median_s"] for k, c in r["costs"].items()
              if (k.startswith(a) if a.endswith("-") else k == a) and c.get("run_median_s")]
        mb = _median(r["costs"], b)
        if da and mb:
            lines.append(f"| {label} | {statistics.median(da) / mb:.0f} |")
    return "\n".join(lines) + "\n"
