"""The report section of a ``femxdem`` case: curves overlaid, acceptance, cost, fields."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from granular_material_validation import metrics

from granular_material.results import pyplot

__all__ = ["plot_femxdem", "section_lines"]

_STYLE = {"guo-zhao": ("k", "-"), "guo-zhao-perturbed": ("0.6", ":"),
          "ours-defaults": ("C0", "--"), "ours-as-gz": ("C3", "-."),
          "ours-q9": ("C2", "--"), "ours-small-strain": ("C1", ":"), "ours-fine": ("C4", "--")}
_RULES = ("pre_peak", "peak_ratio", "strain_at_peak", "post_peak")


def _f(value: Any, spec: str = ".3g") -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return format(value, spec)


def _p(value: Any, digits: int = 2) -> str:
    return "–" if value is None else f"{100 * value:.{digits}f} %"


def _curves(run: Any) -> dict[str, Any]:
    out = {"guo-zhao": run.yade, "guo-zhao-perturbed": run.baseline}
    out.update(run.curves)
    return out


def plot_femxdem(run: Any, path: Path) -> Path:
    """σ1/σ3, εv, Newton iterations and DEM steps a load step of every run of one seed."""
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(11, 8), constrained_layout=True)
    points = run.extra["points"]
    particles = run.extra["packing"].get("particles") or 400
    for name, frame in _curves(run).items():
        colour, style = _STYLE.get(name, ("C5", "--"))
        x = 100 * frame["axial_strain"].to_numpy()
        axes[0, 0].plot(x, metrics.stress_ratio(frame), style, color=colour, lw=1.2,
                        label=name)
        axes[0, 1].plot(x, -100 * frame["volumetric_strain"], style, color=colour, lw=1.2,
                        label=name)
        rows = frame["step"] > 0
        axes[1, 0].plot(x[rows], frame.loc[rows, "iterations"], style, color=colour,
                        marker=".", lw=1, label=name)
        if "dem_steps" in frame.columns and name.startswith("guo-zhao"):
            dem = frame.loc[rows, "dem_steps"] / points
        else:
            dem = frame.loc[rows, "particle_steps"] / (particles * points)
        axes[1, 1].plot(x[rows], dem, style, color=colour, marker=".", lw=1, label=name)
    axes[0, 0].set_ylabel("σ1/σ3 of the volume-average stress [-] (compression positive)")
    axes[0, 1].set_ylabel("volumetric strain εv [%] (compression positive)")
    axes[1, 0].set_ylabel("Newton iterations a load step")
    axes[1, 1].set_ylabel("DEM steps a load step, per Gauss point")
    for ax in axes.flat:
        ax.set_xlabel("axial strain εa [%] (compression positive)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"seed {run.seed}: Guo & Zhao's FEM × DEM code (solid) against ours")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _curve_rows(e: dict[str, Any]) -> list[str]:
    lines = ["| run | peak σ1/σ3 | εa at peak (plateau centre; largest value) | ",
             "|---|---|---|"]
    seed = e["per_seed"][0]
    strains = seed["ratios_at"]["strains"]
    lines[0] += "".join(f"σ1/σ3 at {100 * s:.0f} % | " for s in strains)
    lines[0] += "largest contraction −εv (at εa) | −εv at the end (εa) |"
    lines[1] += "---|" * (len(strains) + 2)
    runs = e["_runs"][0]
    for name, frame in _curves(runs).items():
        c = metrics.compare_curves(frame, frame)
        at = seed["ratios_at"].get(name, [None] * len(strains))
        ev = -frame["volumetric_strain"].to_numpy(dtype=float)
        ea = frame["axial_strain"].to_numpy(dtype=float)
        k = int(ev.argmax())
        lines.append(f"| {name} | {c.peak_ratio_ref:.3f} | {_p(c.strain_at_peak_ref)}; "
                     f"{_p(c.strain_at_peak_argmax_ref)} | "
                     + "".join(f"{_f(v, '.3f')} | " for v in at)
                     + f"{_p(ev[k], 3)} ({_p(ea[k], 1)}) | {_p(ev[-1], 3)} ({_p(ea[-1], 1)}) |")
    return lines


def _acceptance_rows(e: dict[str, Any]) -> list[str]:
    seed = e["per_seed"][0]
    lines = ["| against Guo & Zhao | pre-peak Δσ | peak σ1/σ3 Δ | εa at peak Δ (plateau "
             "centre) | former: εa of the largest value Δ | post-peak Δσ | max Δεv | "
             "rules failed |", "|---|---|---|---|---|---|---|---|"]
    items = [(name, c) for name, c in seed["comparisons"].items()]
    items.append(("guo-zhao-perturbed (chaos baseline)", seed["guo_zhao_perturbed_vs_guo_zhao"]))
    for name, c in items:
        failed = [r for r in _RULES if not c["checks"][r]]
        lines.append(f"| {name} | {_p(c['pre_peak_diff'])} | {_p(c['peak_ratio_diff'])} | "
                     f"{_p(c['strain_at_peak_diff'])} | "
                     f"{_p(c.get('strain_at_peak_argmax_diff'))} | {_p(c['post_peak_diff'])} | "
                     f"{_p(c['volumetric_strain_diff'], 3)} | "
                     f"{', '.join(failed) or 'none'} |")
    return lines


def _cost_rows(e: dict[str, Any]) -> list[str]:
    cost = e["per_seed"][0]["cost"]
    lines = ["| run | Newton iterations a step: to peak / after / all | DEM steps a step per "
             "point: to peak / after / all | stepping [s] (steps) | stepping speed-up | "
             "whole run: wall [s] | cores | core-s | CPU [s] | speed-up wall / per core / "
             "CPU |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, c in cost.items():
        speed = (f"{_f(c.get('speedup_wall'), '.2f')}× / "
                 f"{_f(c.get('speedup_per_core'), '.2f')}× / "
                 f"{_f(c.get('speedup_cpu'), '.2f')}×" if "speedup_wall" in c else "1")
        step_speed = (f"{_f(c.get('stepping_speedup'), '.1f')}×" if "stepping_speedup" in c
                      else "1")
        lines.append(
            f"| {name} | {_f(c['iterations_pre_peak'], '.2f')} / "
            f"{_f(c['iterations_post_peak'], '.2f')} / {_f(c['iterations_all'], '.2f')} | "
            f"{_f(c['dem_steps_per_point_pre_peak'], '.0f')} / "
            f"{_f(c['dem_steps_per_point_post_peak'], '.0f')} / "
            f"{_f(c['dem_steps_per_point_all'], '.0f')} | {_f(c['stepping_s'], '.1f')} "
            f"(1–{c['last_step']}) | {step_speed} | {c['wall_s']:.1f} | {c['threads']} | "
            f"{c['core_s']:.1f} | "
            f"{_f(c.get('cpu_s'), '.1f')} | {speed} |")
    return lines


def _band_rows(e: dict[str, Any]) -> list[str]:
    """The shear band of every run (theirs first): σ1/σ3 at the band strains, σyy spread and
    γmax/γmean at the first and last, Newton iterations a step before and after the peak."""
    seed = e["per_seed"][0]
    bands, cost = seed.get("bands", {}), seed["cost"]
    if not bands:
        return []
    strains = next(iter(bands.values()))["strains"]
    pick = [0, len(strains) - 1]
    head = (" / ".join(_p(s, 1) for s in strains[1:]), " / ".join(_p(strains[i], 1)
                                                                    for i in pick))
    lines = [f"| run | options | σ1/σ3 at {head[0]} | σyy s.d. at {head[1]} [kPa] | "
             f"γmax/γmean at {head[1]} | Newton it/step before / after peak |",
             "|---|---|---|---|---|---|"]
    options = seed.get("options", {})
    for name, b in bands.items():
        c = cost.get(name, {})
        opts = ("their biaxialSmooth.py" if name == "guo-zhao"
                else _as_options(options.get(name, {})) or "defaults")
        lines.append(
            f"| {name} | {opts} | "
            + " / ".join(_f(v, ".3f") for v in b["ratio"][1:]) + " | "
            + " / ".join(_f(b["syy_sd_kpa"][i], ".2f") for i in pick) + " | "
            + " / ".join(_f(b["localisation"][i], ".3f") for i in pick) + " | "
            f"{_f(c.get('iterations_pre_peak'), '.1f')} / "
            f"{_f(c.get('iterations_post_peak'), '.1f')} |")
    return lines


def _field_rows(e: dict[str, Any]) -> list[str]:
    seed = e["per_seed"][0]
    lines = ["| run | step | σyy mean ± s.d. [kPa] theirs / ours | γ mean theirs / ours | "
             "γmax/γmean theirs / ours | RMS / max Δσyy [kPa] | RMS Δe | corr(γ) |",
             "|---|---|---|---|---|---|---|---|"]
    for name, steps in seed["fields"].items():
        for f in steps:
            t, o, d = f["theirs"], f["ours"], f["diff"]
            lines.append(
                f"| {name} | {f['step']} | {t['syy_mean_kpa']:.1f} ± {t['syy_sd_kpa']:.1f} / "
                f"{o['syy_mean_kpa']:.1f} ± {o['syy_sd_kpa']:.1f} | "
                f"{_p(t['gamma_mean'])} / {_p(o['gamma_mean'])} | "
                f"{_f(t['localisation'], '.2f')} / {_f(o['localisation'], '.2f')} | "
                f"{d['syy_rms_kpa']:.1f} / {d['syy_max_kpa']:.1f} | "
                f"{d['void_ratio_rms']:.4f} | {_f(d['gamma_correlation'], '.2f')} |")
    return lines


def _as_options(fields: dict[str, Any] | list[str]) -> str:
    """A run's spec fields (flat names) as the command-line options that set them (a list:
    the options themselves, as older summaries hold them)."""
    if isinstance(fields, list):
        return " ".join(fields)
    words = []
    for name, value in fields.items():
        values = value if isinstance(value, list) else [value]
        words += [f"--{name.replace('_', '-')}", *(f"{v:g}" if isinstance(v, float) else str(v)
                                                    for v in values)]
    return " ".join(words)


def section_lines(e: dict[str, Any], out: Path) -> list[str]:
    """Markdown lines of a femxdem case's section; its plots go to ``out/plots``."""
    name = e["case"]["name"]
    seed = e["per_seed"][0]
    lines = [f"### {name}", "", e["case"]["description"], "",
             "In the tables above, \"YADE\" is Guo & Zhao's own FEM × DEM code (YADE's "
             f"FEMxDEM on esys-escript) and \"ours\" is {seed['judged']}. "
             f"{seed['points']} Gauss points, "
             f"{seed['elements'][0]} × {seed['elements'][1]} elements, "
             f"{100 * seed['strain_per_step']:.2g} % axial strain a load step. σ1/σ3 is that "
             "of the volume-average stress over the Gauss points (the platen force over the "
             "platen width is in the CSV files, `platen_stress`).", ""]
    for run in e["_runs"]:
        plot = plot_femxdem(run, out / "plots" / f"{name}_seed{run.seed}.png")
        lines += [f"![{name} seed {run.seed}]({plot.relative_to(out).as_posix()})", ""]
    band = _band_rows(e)
    if band:
        lines += ["The shear band (σ1/σ3 of the volume-average stress; σyy spread over the "
                  "Gauss points; γ = √(2 e:e) of the strain deviator, γmax/γmean 1 for a "
                  "uniform field; the peak is theirs for every run):", "", *band, ""]
    lines += ["Global curve:", "", *_curve_rows(e), "", "Acceptance rules on the global "
              "curve (the same rules for the chaos baseline):", "", *_acceptance_rows(e), "",
              "Cost (same machine, same run; their pool of processes and our CPU shards "
              "counted as cores; speed-up = theirs / ours; per core = their wall × their "
              "processes over our wall × our threads; CPU = their CPU time (main process and "
              "pool) over ours; wall times include each program's start-up, stepping is the "
              "load steps alone, over the steps both codes did; a whole run of ours covers "
              "all the case's steps, so where theirs stopped early the whole-run ratios "
              "understate ours; on a machine shared with other jobs the CPU ratio is the "
              "least distorted):", "", *_cost_rows(e), "",
              "Gauss-point fields (γ = √(2 e:e) of the strain deviator; γmax/γmean is 1 for "
              "a uniform field):", "", *_field_rows(e), "",
              "Their code ran as shipped in Debian's yade 2023.02a except for these patches "
              "(applied at run time to copies in the work folder): "
              + "; ".join(seed["guo_zhao_patches"]) + ".", ""]
    if seed["guo_zhao_steps_done"] < seed["steps"] or (
            seed["guo_zhao_perturbed_steps_done"] < seed["steps"]):
        lines.append(f"- **their runs were stopped at the time limit** "
                     f"({seed['time_limit_s']:.0f} s each): Guo & Zhao "
                     f"{seed['guo_zhao_steps_done']} of {seed['steps']} load steps, the chaos "
                     f"baseline {seed['guo_zhao_perturbed_steps_done']}; the curves are "
                     "compared on the strain range both reached, the cost figures are those "
                     "of the steps done")
    st = seed["guo_zhao_rve_state"]
    lines.append(f"- their RVE state as loaded (0.yade.gz): σxx, σyy = "
                 f"{-st['stress'][0] / 1e3:.2f}, {-st['stress'][1] / 1e3:.2f} kPa, "
                 f"e = {st['void_ratio']:.4f}, Z = {st['coordination']:.3f}; the chaos "
                 f"baseline's run took {seed['baseline_wall_s']:.1f} s")
    lines.append("")
    return lines
