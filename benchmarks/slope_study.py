"""Factors of safety of the shipped slopes against Bishop's simplified method, and whether
they move with the number of cut-backs.

For each slope scene of examples/scenes (the homogeneous embankment and its two-layer
version, 929 tri6, Mohr–Coulomb, small strain), with 6 and with 12 cut-backs allowed:

1. strength reduction after the weight is switched on (``[strength_reduction]``, followed by
   arc length to its plateau);
2. the gravity increase followed by arc length (``[newton] continuation = "arc-length"``);
3. the same gravity increase stepped by load, which stops where Newton fails (today's way of
   reading a collapse, for comparison);

and Bishop's simplified factor and gravity-increase factor of the same ground
(:mod:`granular_material.limit_equilibrium`). Writes ``results.json``, ``report.md`` and
``slope_paths.png`` into ``--out``; ``--publish DIR`` copies them there
(docs/validation/slopes)::

    python benchmarks/slope_study.py --out out/slopes --publish docs/validation/slopes
    python benchmarks/slope_study.py --smoke --out /tmp/slopes-smoke    # seconds
"""

from __future__ import annotations

import argparse
import json
import math
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd

from granular_material.limit_equilibrium import (
    Ground,
    Layer,
    critical_circle,
    gravity_increase_factor,
)

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "examples" / "scenes"
#: the ground of the embankment scenes (crest, face, toe [m]) and each slope's soils
SURFACE = ((0.0, 10.0), (15.0, 10.0), (30.0, 0.0), (50.0, 0.0))
SLOPES = {
    "homogeneous": {"scene": "slope-embankment-mc.toml",
                    "layers": ((0.0, 10e3, 20.0), (-5.0, 10e3, 20.0))},
    "two-layer": {"scene": "slope-two-layer-mc.toml",
                  "layers": ((0.0, 12e3, 22.0), (-5.0, 8e3, 18.0))},
}
UNIT_WEIGHT = 20e3  # [N/m³], both soils
METHODS = ("strength-reduction", "gravity-arc-length", "gravity-load")
#: the gravity factor's end for the gravity increase (beyond each slope's collapse)
GRAVITY_END = {"homogeneous": 2.0, "two-layer": 3.0}


def ground(slope: str) -> Ground:
    """The slope's ground for Bishop's method: its layers from the top down, a fixed base."""
    return Ground(surface=SURFACE, layers=tuple(
        Layer(bottom=b, cohesion=c, friction_angle=phi, unit_weight=UNIT_WEIGHT)
        for b, c, phi in SLOPES[slope]["layers"]))


def scene_text(slope: str, method: str, cutbacks: int) -> str:
    """The slope's scene for ``method`` with ``cutbacks`` allowed (the mesh path made
    absolute)."""
    text = (SCENES / SLOPES[slope]["scene"]).read_text(encoding="utf-8")
    text = text.replace('file = "meshes/', f'file = "{SCENES.as_posix()}/meshes/')
    text = text.replace('formulation = "small-strain"',
                        f'formulation = "small-strain"\nmax_cutbacks = {cutbacks}')
    if method != "strength-reduction":
        text = text[:text.index("[strength_reduction]")].rstrip() + "\n"
        end = GRAVITY_END[slope]
        text = re.sub(r"^steps = \d+", f"steps = {int(20 * end)}", text, count=1, flags=re.M)
        text = re.sub(r"^factor = \[0\.0, 1\.0\].*$", f"factor = [0.0, {end!r}]", text,
                      count=1, flags=re.M)
        if method == "gravity-arc-length":
            text = text.replace('formulation = "small-strain"',
                                'formulation = "small-strain"\ncontinuation = "arc-length"')
    return text


def run(out: Path, slope: str, method: str, cutbacks: int, force: bool) -> dict[str, Any]:
    """One run (skipped where its summary exists): what it found and what it cost."""
    name = f"{slope}-{method}-cut{cutbacks}"
    folder = out / name
    summary_file = folder / "summary.json"
    if force or not summary_file.exists():
        if folder.exists():
            shutil.rmtree(folder)
        scene = out / f"{name}.toml"
        scene.write_text(scene_text(slope, method, cutbacks), encoding="utf-8")
        command = [sys.executable, "-m", "granular_material.cli", "run", str(scene), "--out",
                   str(folder)]
        print("$", " ".join(command[2:]), flush=True)
        t0 = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True)
        if not summary_file.exists():
            raise RuntimeError(f"{name} wrote no summary (exit {done.returncode}):\n"
                               f"{done.stderr[-2000:]}")
        summary = json.loads(summary_file.read_text(encoding="utf-8"))
        summary["process_wall_s"] = time.perf_counter() - t0
        summary_file.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    summary = json.loads(summary_file.read_text(encoding="utf-8"))
    steps = pd.read_csv(folder / "steps.csv")
    if method == "strength-reduction":
        found = summary["strength_reduction"]
        value, stopped = found["factor_of_safety"], found["stopped_by"]
    elif method == "gravity-arc-length":
        found = summary["continuation"]
        value, stopped = found["gravity_factor_at_collapse"], found["stopped_by"]
    else:  # by load: the last committed step's gravity factor, where Newton failed
        value = GRAVITY_END[slope] * float(steps["load_factor"].iloc[-1])
        stopped = "newton failed" if summary["error"] else "completed"
    return {"slope": slope, "method": method, "cutbacks": cutbacks, "folder": name,
            "value": value, "stopped_by": stopped, "steps": int(summary["steps"]),
            "wall_s": float(summary.get("wall_s", math.nan))}


def bishop(slope: str, grid: int) -> dict[str, Any]:
    """Bishop's simplified factor of safety and gravity-increase factor, their circles."""
    g = ground(slope)
    found = critical_circle(g, grid=grid).result
    factor, at = gravity_increase_factor(g, grid=grid)
    return {"factor_of_safety": found.factor, "circle": [*found.centre, found.radius],
            "gravity_factor": factor, "gravity_circle": [*at.result.centre, at.result.radius]}


def figure(out: Path, rows: list[dict[str, Any]], references: dict[str, Any]) -> str:
    """F (strength reduction) and g (gravity by arc length) against the largest
    displacement, Bishop's values as lines."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, method, label in zip(axes, ("strength-reduction", "gravity-arc-length"),
                                 ("strength reduction factor F", "gravity factor g"),
                                 strict=True):
        for k, slope in enumerate(SLOPES):
            chosen = [r for r in rows if r["slope"] == slope and r["method"] == method
                      and r["cutbacks"] == 6]
            if not chosen:
                continue
            steps = pd.read_csv(out / chosen[0]["folder"] / "steps.csv")
            if method == "strength-reduction":
                steps = steps[steps["strength_factor"] > 1.0]
                x, y = steps["max_displacement"], steps["strength_factor"]
                ref = references[slope]["factor_of_safety"]
            else:
                u = steps.filter(regex=r"_displacement_[xy]$").abs().max(axis=1)
                x, y = u, GRAVITY_END[slope] * steps["load_factor"]
                ref = references[slope]["gravity_factor"]
            ax.plot(x, y, "o-", ms=2, color=f"C{k}", label=f"{slope}")
            ax.axhline(ref, color=f"C{k}", ls="--", lw=0.8, label=f"{slope}: Bishop {ref:.3f}")
        ax.set_xlabel("largest displacement [m]" if method == "strength-reduction"
                      else "largest mean boundary displacement [m]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "slope_paths.png", dpi=110)
    plt.close(fig)
    return "slope_paths.png"


def report(out: Path, rows: list[dict[str, Any]], references: dict[str, Any]) -> None:
    """report.md: every run against Bishop, 6 against 12 cut-backs."""
    lines = ["# Factors of safety against Bishop's simplified method", "",
             "Written by `benchmarks/slope_study.py` (the embankment of examples/scenes, "
             "929 tri6, Mohr–Coulomb, ψ = 0, small strain).", "",
             "| slope | Bishop F | its circle (centre, radius) [m] | Bishop g | its circle |",
             "|---|---|---|---|---|"]
    for slope, ref in references.items():
        c, gc = ref["circle"], ref["gravity_circle"]
        lines.append(f"| {slope} | {ref['factor_of_safety']:.3f} | ({c[0]:.2f}, {c[1]:.2f}), "
                     f"{c[2]:.2f} | {ref['gravity_factor']:.3f} | ({gc[0]:.2f}, "
                     f"{gc[1]:.2f}), {gc[2]:.2f} |")
    lines += ["", "| slope | method | found (6 cut-backs) | found (12) | 12 against 6 | "
                  "Bishop | against Bishop | stopped by | steps | wall time [s] |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for slope in SLOPES:
        for method in METHODS:
            by_cut = {r["cutbacks"]: r for r in rows
                      if r["slope"] == slope and r["method"] == method}
            if 6 not in by_cut:
                continue
            six, twelve = by_cut[6], by_cut.get(12)
            ref = references[slope]["factor_of_safety" if method == "strength-reduction"
                                   else "gravity_factor"]
            value = six["value"]
            apart = "—" if value is None else f"{100 * (value / ref - 1):+.1f} %"
            moved = ("—" if twelve is None or value is None or twelve["value"] is None
                     else f"{100 * (twelve['value'] / value - 1):+.2f} %")
            lines.append(
                f"| {slope} | {method} | {_f(value)} | "
                f"{_f(None if twelve is None else twelve['value'])} | {moved} | {ref:.3f} | "
                f"{apart} | {six['stopped_by']} | {six['steps']} | {six['wall_s']:.0f} |")
    lines += ["", "![paths](slope_paths.png)", ""]
    (out / "report.md").write_text("\n".join(lines), encoding="utf-8")


def _f(value: float | None) -> str:
    return "—" if value is None else f"{value:.3f}"


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the study; return (and write) its results."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "slopes")
    ap.add_argument("--smoke", action="store_true",
                    help="the homogeneous slope's strength reduction only (a test)")
    ap.add_argument("--force", action="store_true", help="redo runs whose summary exists")
    ap.add_argument("--publish", type=Path, default=None, metavar="DIR",
                    help="copy the report, results and figure there (docs/validation/slopes)")
    args = ap.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    runs = ([("homogeneous", "strength-reduction", 6)] if args.smoke else
            [(s, m, c) for s in SLOPES for m in METHODS for c in (6, 12)])
    rows = [run(out, s, m, c, args.force) for s, m, c in runs]
    references = {s: bishop(s, grid=8 if args.smoke else 16)
                  for s in dict.fromkeys(r["slope"] for r in rows)}
    results = {"runs": rows, "bishop": references}
    (out / "results.json").write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    figure(out, rows, references)
    report(out, rows, references)
    if args.publish is not None:
        args.publish.mkdir(parents=True, exist_ok=True)
        for name in ("report.md", "results.json", "slope_paths.png"):
            shutil.copy2(out / name, args.publish / name)
    return results


if __name__ == "__main__":
    main()
