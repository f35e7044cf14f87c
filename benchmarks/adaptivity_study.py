"""Adaptivity measured, not assumed: Guo & Zhao's reduced footing and walls all-DEM against
the same scenes with ``[adaptivity]`` (the Mohr–Coulomb twin calibrated from the scene's RVE
at every point, a DEM RVE where the twin is no longer trusted).

Each scene of examples/scenes runs once per variant:

- ``all-DEM``: the scene as written, the reference;
- ``f=0.7`` (the default threshold), ``f=0.9`` (loose) and, on the footing, ``f=0.5``
  (tight): a point is DEM from the step in which its mobilised friction reaches that
  fraction of the twin's peak friction angle, its element's points with it, its RVE driven
  through the point's deformation (the defaults: ``start = "strain"``,
  ``switch = "in-step"``);
- on the footing also ``f=0.7, point`` (no neighbours), ``γ=0.5 %`` (the shear-strain
  threshold), ``f=0.7, after-step`` (DEM from the step after), ``f=0.7, E over 0.1 %`` (the
  twin's E and ν read as calibrate reads them) and ``f=0.7, stress`` (the RVE brought by
  the servo to the twin's stress).

``--scenes footing-full`` runs Guo & Zhao's footing at their size (``footing-gz2016.toml``:
7500 RVEs of 400 discs, an hour or more on a 2-core CPU) with the defaults only, against the
all-DEM run committed in docs/validation/footing-cost (``full_steps.csv``), which it does not
run again; a stopped run continues with ``--resume`` when the study is run again, and an
unfinished one is measured over the steps it has.

It reports every run's load at each step against the reference's (the error at every step
up to the reference's peak and after it), the DEM points over the run, the particle-steps
(the switches' own included) and the wall time, in ``results.json``, ``report.md`` and
``adaptivity.png`` in ``--out``; ``--publish DIR`` copies them there
(docs/validation/adaptivity). A run whose ``summary.json`` exists is read, not redone::

    python benchmarks/adaptivity_study.py --out out/adaptivity --publish docs/validation/adaptivity
    python benchmarks/adaptivity_study.py --smoke --out /tmp/adaptivity-smoke    # a minute
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from granular_material.runs.run_folder import ended_summary, resumable

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "examples" / "scenes"
#: each scene: its file, its load and displacement columns, the load's scale (the bearing
#: pressure q = −F/b of the footing's half model, b = 0.05 m; the wall's force per metre);
#: ``peak`` False: no peak to measure up to (the active wall's thrust falls to its limit),
#: the error over every step
STUDIED = {
    "footing": {"scene": "footing-gz2016-cpu.toml", "force": "footing_force_y",
                "displacement": "footing_settlement", "scale": -1.0 / 0.05,
                "label": "q [kPa]", "unit": 1e-3},
    "wall-passive": {"scene": "retaining-wall-gz2016-cpu.toml", "force": "wall_force_x",
                     "displacement": "wall_displacement", "scale": 1.0,
                     "label": "wall force [kN/m]", "unit": 1e-3},
    "wall-active": {"scene": "retaining-wall-gz2016-active-cpu.toml", "force": "wall_force_x",
                    "displacement": "wall_displacement", "scale": 1.0,
                    "label": "wall force [kN/m]", "unit": 1e-3, "peak": False},
    "footing-full": {"scene": "footing-gz2016.toml", "force": "footing_force_y",
                     "displacement": "footing_settlement", "scale": -1.0 / 0.05,
                     "label": "q [kPa]", "unit": 1e-3, "window_mm": (1.0, 5.0),
                     "reference": ROOT / "docs" / "validation" / "footing-cost"
                     / "full_steps.csv"},
}
#: the variants: their [adaptivity] table (None: all-DEM)
VARIANTS: dict[str, dict[str, Any] | None] = {
    "all-DEM": None,
    "f=0.7": {"mobilised_fraction": 0.7},
    "f=0.5": {"mobilised_fraction": 0.5},
    "f=0.9": {"mobilised_fraction": 0.9},
    "f=0.7, point": {"mobilised_fraction": 0.7, "neighbours": "point"},
    "γ=0.5 %": {"shear_strain": 0.005},
    "f=0.7, after-step": {"mobilised_fraction": 0.7, "switch": "after-step"},
    "f=0.7, E over 0.1 %": {"mobilised_fraction": 0.7, "elastic_window": 1e-3},
    "f=0.7, stress": {"mobilised_fraction": 0.7, "start": "stress"},
}
#: which variants each scene runs
PLAN = {"footing": list(VARIANTS),
        "wall-passive": ["all-DEM", "f=0.7", "f=0.9"],
        "wall-active": ["all-DEM", "f=0.7", "f=0.9"]}
#: scenes run only when asked for (``--scenes``): their all-DEM reference is a committed
#: table of steps, not a run of the study
ON_REQUEST = {"footing-full": ["f=0.7"]}
#: the smoke study: the footing on a 3 × 2 mesh of 16-disc RVEs, 3 steps
SMOKE = {"footing": ["all-DEM", "f=0.7"]}


def _toml(value: Any) -> str:
    return f'"{value}"' if isinstance(value, str) else repr(value)


def scene_text(scene: str, variant: str, smoke: bool = False) -> str:
    """The scene's text with the variant's [adaptivity] table (and, for the smoke study, a
    3 × 2 mesh of 16-disc RVEs and 3 steps of its loading), progress off."""
    text = (SCENES / STUDIED[scene]["scene"]).read_text(encoding="utf-8")
    text = text.replace("progress = true", "progress = false")
    if smoke:
        text = (text.replace("steps = 58", "steps = 3")
                .replace("elements = [12, 8]", "elements = [3, 2]")
                .replace("particles = 64", "particles = 16")
                .replace("displacement = [0.0, -0.0145]", "displacement = [0.0, -0.0015]"))
    table = VARIANTS[variant]
    if table:
        text += "\n[adaptivity]\n" + "".join(f"{k} = {_toml(v)}\n" for k, v in table.items())
    return text


def _folder_name(scene: str, variant: str) -> str:
    return f"{scene}-{variant}".replace("=", "").replace(",", "").replace(" ", "-") \
        .replace("%", "pct").replace("γ", "gamma")


def run(out: Path, scene: str, variant: str, smoke: bool, force: bool,
        measure_only: bool = False) -> Path:
    """The run's folder (run where it has no summary, or with ``force``; a stopped run of a
    scene run on request continues from its checkpoint; ``measure_only``: nothing is run,
    the folder's run is read as it stands)."""
    folder = out / _folder_name(scene, variant)
    if measure_only:
        if not (folder / "summary.json").is_file():
            raise FileNotFoundError(f"{folder} has no summary.json to measure")
        return folder
    resume = (scene in ON_REQUEST and not force and resumable(folder)
              and ended_summary(folder) is None)
    if force or resume or not (folder / "summary.json").exists():
        if folder.exists() and not resume:
            shutil.rmtree(folder)
        path = out / f"{folder.name}.toml"
        path.write_text(scene_text(scene, variant, smoke), encoding="utf-8")
        command = [sys.executable, "-m", "granular_material.cli", "run", str(path), "--out",
                   str(folder), *(["--resume"] if resume else [])]
        print("$", " ".join(command[2:]), flush=True)
        t0 = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True)
        if not (folder / "summary.json").exists():
            raise RuntimeError(f"{folder.name} wrote no summary (exit {done.returncode}):\n"
                               f"{done.stderr[-2000:]}")
        print(f"  {time.perf_counter() - t0:.0f} s", flush=True)
    return folder


def measure(folder: Path, scene: str, reference: pd.DataFrame | None) -> dict[str, Any]:
    """A run's curve, costs and (against ``reference``, the all-DEM run's steps) errors."""
    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    return measure_steps(pd.read_csv(folder / "steps.csv"), summary, folder.name, scene,
                         reference)


def measure_steps(steps: pd.DataFrame, summary: dict[str, Any], name: str, scene: str,
                  reference: pd.DataFrame | None) -> dict[str, Any]:
    """:func:`measure` of a table of steps and its run's summary (``error``,
    ``gauss_points``, ``adaptivity``)."""
    spec = STUDIED[scene]
    load = spec["scale"] * steps[spec["force"]].to_numpy()
    switching = (int(steps["switch_particle_steps"].sum())
                 if "switch_particle_steps" in steps else 0)
    row: dict[str, Any] = {
        "folder": name, "steps": int(len(steps) - 1), "error": summary["error"],
        "displacement": steps[spec["displacement"]].abs().tolist(), "load": load.tolist(),
        "particle_steps": int(steps["particle_steps"].sum()),
        "switch_particle_steps": switching,
        "dem_points": (steps["dem_points"].tolist() if "dem_points" in steps
                       else [int(summary["gauss_points"])] * len(steps)),
        "gauss_points": int(summary["gauss_points"]),
        "iterations": int(steps["iterations"].sum()),
        "load_steps_s": float(steps["wall_time"].sum()),
        "twin": (summary.get("adaptivity") or {}).get("twin"),
        "wall_s": float(summary.get("wall_s") or math.nan),
    }
    if reference is not None:
        ref = spec["scale"] * reference[spec["force"]].to_numpy()
        n = min(len(ref), len(load))
        # the reference's largest load after its start, or its last step (no peak); a run
        # that stopped before it is measured to its own last step
        peak = (1 + int(np.argmax(np.abs(ref[1:]))) if spec.get("peak", True)
                else len(ref) - 1)
        error = (load[:n] - ref[:n]) / np.abs(ref[:n]).clip(1e-300)
        row["error_by_step"] = [None, *error[1:].tolist()]
        row["peak_step"] = peak
        upto = min(peak, n - 1)
        row["reached_peak"] = upto == peak
        row["largest_error_to_peak"] = float(np.abs(error[1:upto + 1]).max())
        row["largest_error_step"] = int(np.argmax(np.abs(error[1:upto + 1]))) + 1
        row["median_error_to_peak"] = float(np.median(np.abs(error[1:upto + 1])))
        if "window_mm" in spec:
            low, high = spec["window_mm"]
            d = 1e3 * np.abs(reference[spec["displacement"]].to_numpy()[:n])
            inside = (d >= low - 1e-9) & (d <= high + 1e-9)
            inside[0] = False
            row["window_mm"] = [low, high]
            row["window_steps"] = int(inside.sum())
            row["largest_error_in_window"] = (float(np.abs(error[inside]).max())
                                              if inside.any() else None)
        after = np.abs(error[peak + 1:n])
        row["largest_error_after_peak"] = float(after.max()) if after.size else None
        row["median_error_after_peak"] = float(np.median(after)) if after.size else None
        row["dem_points_at_peak"] = int(row["dem_points"][min(peak, len(load) - 1)])
        total_ref = int(reference["particle_steps"][:n].sum())
        row["cost_ratio"] = (row["particle_steps"] + switching) / max(total_ref, 1)
        row["switch_ratio"] = switching / max(total_ref, 1)
        row["reference_load_steps_s"] = float(reference["wall_time"][:n].sum())
        # a step's DEM work per Newton iteration over the reference's: what the DEM points
        # cost beside all of them, whatever the iterations each run needed
        ours = steps["particle_steps"].to_numpy(float)[:n] / steps["iterations"].to_numpy(
            float)[:n].clip(1)
        theirs = (reference["particle_steps"].to_numpy(float)[:n]
                  / reference["iterations"].to_numpy(float)[:n].clip(1))
        row["work_per_iteration_ratio"] = [None, *(ours[1:] / theirs[1:].clip(1)).tolist()]
    return row


def figure(out: Path, results: dict[str, dict[str, Any]]) -> str:
    """Load against displacement, the error against the reference, and the DEM points, of
    every run of every scene."""
    scenes = list(results)
    fig, axes = plt.subplots(3, len(scenes), figsize=(5.2 * len(scenes), 10), squeeze=False)
    for j, scene in enumerate(scenes):
        spec = STUDIED[scene]
        for variant, row in results[scene].items():
            d = 1e3 * np.asarray(row["displacement"])
            style = {"color": "k", "lw": 2.0} if variant == "all-DEM" else {"lw": 1.0}
            axes[0, j].plot(d, spec["unit"] * np.asarray(row["load"]), label=variant, **style)
            if "error_by_step" in row and variant != "all-DEM":
                e = [np.nan if v is None else 100 * v for v in row["error_by_step"]]
                axes[1, j].plot(d[:len(e)], e, label=variant, lw=1.0)
            axes[2, j].plot(d, 100 * np.asarray(row["dem_points"]) / row["gauss_points"],
                            label=variant, **style)
        axes[0, j].set_title(scene)
        axes[0, j].set_ylabel(spec["label"])
        axes[1, j].axhline(3, color="0.6", ls=":")
        axes[1, j].axhline(-3, color="0.6", ls=":")
        axes[1, j].set_ylabel("error against all-DEM [%]")
        axes[2, j].set_ylabel("DEM points [% of all]")
        axes[2, j].set_xlabel("displacement [mm]")
        axes[0, j].legend(fontsize=7)
    fig.tight_layout()
    name = "adaptivity.png"
    fig.savefig(out / name, dpi=110)
    plt.close(fig)
    return name


def _pct(value: float | None) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{100 * value:.1f} %"


def report(out: Path, results: dict[str, dict[str, Any]], commit: str) -> None:
    """report.md: per scene, every variant against all-DEM."""
    lines = ["# Adaptivity against all-DEM", "",
             f"Written by `benchmarks/adaptivity_study.py` at {commit} on this machine "
             "(runs on a shared 2-core CPU: the wall times depend on the load; the "
             "particle-steps are counted).", ""]
    for scene, rows in results.items():
        ref = rows["all-DEM"]
        peak = ref["peak_step"]
        unit = STUDIED[scene]["label"].split("[")[1].rstrip("]")
        where = (f"peaks at step {peak} ({1e3 * ref['displacement'][peak]:.2f} mm, "
                 f"{STUDIED[scene]['unit'] * ref['load'][peak]:.1f} {unit})"
                 if STUDIED[scene].get("peak", True) else
                 "has no peak (the thrust falls to its limit): the errors are of every step")
        lines += [f"## {scene}", "",
                  f"The all-DEM reference {where}; its particle-steps "
                  f"{ref['particle_steps']:.3g}.", "",
                  "| run | steps | error to the peak: largest (at) / median | after it: "
                  "largest / median | DEM points at the peak / end | particle-steps / all-DEM "
                  "(switches) | load steps [s] |",
                  "|---|---|---|---|---|---|---|"]
        for variant, row in rows.items():
            switch = row.get("switch_ratio",
                             row["switch_particle_steps"] / max(ref["particle_steps"], 1))
            stopped = f" ({row['error'][:40]})" if row["error"] else ""
            at = 1e3 * ref["displacement"][row.get("largest_error_step", 0)]
            lines.append(
                f"| {variant} | {row['steps']}{stopped}"
                f" | {_pct(row.get('largest_error_to_peak'))} ({at:.2f} mm) / "
                f"{_pct(row.get('median_error_to_peak'))} | "
                f"{_pct(row.get('largest_error_after_peak'))} / "
                f"{_pct(row.get('median_error_after_peak'))} | "
                f"{row.get('dem_points_at_peak', row['dem_points'][-1])} / "
                f"{row['dem_points'][-1]} of {row['gauss_points']} | "
                f"{row.get('cost_ratio', 1.0):.3f} ({switch:.3f}) | "
                f"{row['load_steps_s']:.0f} |")
        lines.append("")
        for variant, row in rows.items():
            if row.get("window_mm") is not None and variant != "all-DEM":
                low, high = row["window_mm"]
                lines.append(f"- {variant}: the largest error from {low:g} to {high:g} mm "
                             f"({row['window_steps']} steps): "
                             f"{_pct(row.get('largest_error_in_window'))}.")
            if row["steps"] < ref["steps"]:
                before = ("" if row.get("reached_peak", True) else
                          ", before the reference's peak: its errors 'to the peak' are to "
                          "its last step")
                lines.append(f"- {variant} has {row['steps']} of the reference's "
                             f"{ref['steps']} steps (to "
                             f"{1e3 * row['displacement'][-1]:.2f} mm){before}; its "
                             "particle-steps are over the reference's to that step, whose "
                             f"load steps took {row['reference_load_steps_s']:.0f} s.")
        if lines[-1] != "":
            lines.append("")
        if scene in ON_REQUEST:
            lines += _work_table(rows)
    (out / "report.md").write_text("\n".join(lines) + "\n", encoding="utf-8")


def _gauss_points(folders: dict[str, Path]) -> int:
    """The Gauss points of a scene's runs (their summaries agree)."""
    summary = json.loads((next(iter(folders.values())) / "summary.json").read_text(
        encoding="utf-8"))
    return int(summary["gauss_points"])


def _work_table(rows: dict[str, dict[str, Any]]) -> list[str]:
    """Where the DEM work is: at each whole millimetre, each adaptive run's DEM points (of
    all) and its DEM work per Newton iteration over the reference's."""
    lines = ["| run | displacement [mm] | DEM points | DEM work per iteration / all-DEM's |",
             "|---|---|---|---|"]
    for variant, row in rows.items():
        if variant == "all-DEM" or "work_per_iteration_ratio" not in row:
            continue
        d = 1e3 * np.asarray(row["displacement"])
        for mm in range(1, int(d.max() + 1e-9) + 1):
            k = int(np.argmin(np.abs(d - mm)))
            lines.append(f"| {variant} | {d[k]:.2f} | "
                         f"{100 * row['dem_points'][k] / row['gauss_points']:.0f} % | "
                         f"{row['work_per_iteration_ratio'][k]:.2f} |")
    return [*lines, ""]


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the study; return (and write) its results."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "adaptivity")
    ap.add_argument("--smoke", action="store_true",
                    help="the footing on a 3 x 2 mesh of 16-disc RVEs, 3 steps (a test)")
    ap.add_argument("--scenes", nargs="+", choices=list(STUDIED), default=None,
                    help="only these scenes")
    ap.add_argument("--force", action="store_true", help="redo runs whose summary exists")
    ap.add_argument("--measure-only", action="store_true",
                    help="run nothing: measure the runs in --out as they stand (a stopped "
                         "run over the steps it has)")
    ap.add_argument("--publish", type=Path, default=None, metavar="DIR",
                    help="copy the report, results and figure there (docs/validation/adaptivity)")
    args = ap.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    plan = SMOKE if args.smoke else {s: v for s, v in {**PLAN, **ON_REQUEST}.items()
                                     if (args.scenes is None and s in PLAN)
                                     or (args.scenes is not None and s in args.scenes)}
    results: dict[str, dict[str, Any]] = {}
    for scene, variants in plan.items():
        folders = {v: run(out, scene, v, args.smoke, args.force, args.measure_only)
                   for v in variants}
        results[scene] = {}
        if "reference" in STUDIED[scene]:
            reference = pd.read_csv(STUDIED[scene]["reference"])
            results[scene]["all-DEM"] = measure_steps(
                reference, {"error": None, "gauss_points": _gauss_points(folders)},
                str(STUDIED[scene]["reference"].relative_to(ROOT)), scene, reference)
        else:
            reference = pd.read_csv(folders["all-DEM"] / "steps.csv")
        results[scene].update({v: measure(f, scene, reference) for v, f in folders.items()})
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip() or "unknown"
    (out / "results.json").write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    figure(out, results)
    report(out, results, commit)
    if args.publish is not None:
        args.publish.mkdir(parents=True, exist_ok=True)
        for name in ("report.md", "results.json", "adaptivity.png"):
            shutil.copy2(out / name, args.publish / name)
    return results


if __name__ == "__main__":
    main()
