"""Where a footing's DEM work goes, and what the far field's savings do to its curve.

Runs a boundary-value footing scene (default Guo & Zhao's reduced footing,
``examples/scenes/footing-gz2016-cpu.toml``) in several variants, each with the work of
every RVE counted at every material evaluation (the DEM steps its path was planned for),
and writes for each variant its bearing curve and for all of them one table:

- how the particle-steps divide between the RVEs: the share taken by the busiest 5, 10, 25
  and 50 % of the RVEs, and by the RVEs within one and two half-widths b of the footing's
  edge;
- what each variant costs (particle-steps, evaluations, Newton iterations, wall time) and
  how far its bearing pressure q = −F_y/b (b the half-width of the half model) lies from the
  first variant's at s/B = 0.05 and 0.1 (B = 2b, the footing's width) and at the peak (the
  same run, the same RVEs).

A variant is a name and ``key=value`` settings of the scene's ``[material.parameters]``
and ``[newton]`` tables, e.g. ``reuse-1e-5:material.reuse_tol=1e-5,newton.convergence=force``.

    python benchmarks/footing_cost.py --out out/footing-cost             # the study
    python benchmarks/footing_cost.py --steps 2 --particles 16 --elements 6 4 --out /tmp/fc

The table goes to ``OUT/footing_cost.md`` and ``OUT/footing_cost.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "examples" / "scenes" / "footing-gz2016-cpu.toml"
#: the study's variants: the scene as it is, the force test (what reuse needs), reuse of
#: RVEs whose ∇u moved by less than 1e-5 and 1e-4 between evaluations
VARIANTS = (
    "scene:",
    "force:newton.convergence=force",
    "reuse-1e-5:newton.convergence=force,material.reuse_tol=1e-5",
    "reuse-1e-4:newton.convergence=force,material.reuse_tol=1e-4",
)
#: shares of the busiest RVEs reported [-]
TOP = (0.05, 0.10, 0.25, 0.50)


@dataclass
class WorkLog:
    """DEM steps planned for each RVE, summed over the evaluations of a run."""

    steps: np.ndarray | None = None
    evaluations: int = 0
    per_evaluation: list[int] = field(default_factory=list)

    def add(self, planned: np.ndarray) -> None:
        planned = np.asarray(planned, dtype=np.int64)
        self.steps = planned.copy() if self.steps is None else self.steps + planned
        self.evaluations += 1
        self.per_evaluation.append(int(planned.sum()))


def counting(log: WorkLog) -> Any:
    """Wrap the backend's drive planner so that every plan's steps are added to ``log``."""
    import granular_material.multiscale.backend as backend

    original = backend.plan_drive

    def planned(*args: Any, **kwargs: Any) -> Any:
        plan = original(*args, **kwargs)
        log.add(np.where(plan.driven, plan.steps, 0))
        return plan

    backend.plan_drive = planned
    return original


def parse_variant(text: str) -> tuple[str, dict[str, dict[str, Any]]]:
    """``name:table.key=value,...`` → (name, {table: {key: value}}); values read as TOML."""
    name, _, body = text.partition(":")
    tables: dict[str, dict[str, Any]] = {}
    for item in filter(None, body.split(",")):
        path, _, value = item.partition("=")
        table, _, key = path.strip().partition(".")
        if table not in ("material", "newton") or not key:
            raise SystemExit(f"variant {name}: {path!r} is not material.KEY or newton.KEY")
        tables.setdefault(table, {})[key] = _value(value.strip())
    return name, tables


def _value(text: str) -> Any:
    """A TOML value, or the text itself as a string (``force`` for ``"force"``)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def scene_data(scene: Path, steps: int | None, particles: int | None,
               tables: dict[str, dict[str, Any]],
               elements: tuple[int, int] | None = None) -> dict[str, Any]:
    """The scene as a dict, cut to ``steps`` (the footing's displacement scaled with them),
    with the variant's settings (and a generated mesh's ``elements``)."""
    data = tomllib.loads(scene.read_text(encoding="utf-8"))
    if elements is not None:
        data["mesh"]["elements"] = list(elements)
    if steps is not None:
        scale = steps / data["steps"]
        data["steps"] = steps
        for c in data.get("conditions", []):
            if "displacement" in c:
                c["displacement"] = [scale * v for v in c["displacement"]]
    params = data.setdefault("material", {}).setdefault("parameters", {})
    if particles is not None:
        params["particles"] = particles
    params.update(tables.get("material", {}))
    data.setdefault("newton", {}).update(tables.get("newton", {}))
    data.setdefault("output", {}).update(progress=False, fields=False)
    return data


def half_width(data: dict[str, Any]) -> float:
    """The footing's half-width b [m] from its boundary predicate (``x <= b``)."""
    predicate = data["boundaries"]["footing"]
    return float(predicate.split("<=")[-1])


def bearing(steps: pd.DataFrame, b: float) -> pd.DataFrame:
    """Settlement s [m] (``footing_settlement``, positive down) and bearing pressure
    q = −F_y / b [Pa] of each committed step."""
    return pd.DataFrame({"settlement": steps["footing_settlement"].to_numpy(float),
                         "q": -steps["footing_force_y"].to_numpy(float) / b})


def q_at(curve: pd.DataFrame, s: float) -> float | None:
    """q [Pa] at settlement ``s`` [m], linearly interpolated; None beyond the curve."""
    if curve.empty or curve["settlement"].max() < s - 1e-12:
        return None
    return float(np.interp(s, curve["settlement"], curve["q"]))


def work_division(steps: np.ndarray, xy: np.ndarray, b: float) -> dict[str, float]:
    """Shares [-] of the particle-steps taken by the busiest RVEs and by those within one and
    two half-widths ``b`` [m] of the footing's edge (x = b, on the surface)."""
    total = float(steps.sum()) or 1.0
    ranked = np.sort(steps)[::-1]
    out = {f"top_{int(100 * f)}%": float(ranked[:max(1, round(f * len(ranked)))].sum()) / total
           for f in TOP}
    top = xy[:, 1].max()
    distance = np.hypot(xy[:, 0] - b, xy[:, 1] - top)
    for k in (1, 2):
        near = distance <= k * b
        out[f"within_{k}b"] = float(steps[near].sum()) / total
        out[f"rves_within_{k}b"] = float(near.mean())
    return out


def run_variant(scene: Path, name: str, tables: dict[str, dict[str, Any]], steps: int | None,
                particles: int | None, out: Path,
                elements: tuple[int, int] | None = None) -> dict[str, Any]:
    """One variant: run it with its work counted; its results (and ``OUT/NAME/``)."""
    from granular_material.runs.boundary_value.runner import run_boundary_value
    from granular_material.runs.boundary_value.spec import bvp_from_dict

    data = scene_data(scene, steps, particles, tables, elements)
    spec = bvp_from_dict(data, scene.parent)
    log = WorkLog()
    original = counting(log)
    t0 = time.perf_counter()
    try:
        outcome = run_boundary_value(spec, out / name)
    finally:
        import granular_material.multiscale.backend as backend

        backend.plan_drive = original
    wall = time.perf_counter() - t0
    b = half_width(data)
    points = outcome.points
    xy = points[["x", "y"]].to_numpy() if len(points) else np.zeros((0, 2))
    discs = int(data["material"]["parameters"].get("particles", 400))
    work = log.steps if log.steps is not None else np.zeros(len(xy), dtype=np.int64)
    np.save(out / name / "rve_steps.npy", work)
    return {"name": name, "settings": tables, "error": outcome.error,
            "steps_done": int(len(outcome.steps) - 1),
            "iterations": int(outcome.steps["iterations"].sum()),
            "evaluations": log.evaluations, "particle_steps": int(work.sum()) * discs,
            "wall_s": wall, "timing_s": outcome.summary.get("timing_s", {}),
            "division": work_division(work, xy, b) if len(xy) else {},
            "curve": bearing(outcome.steps.iloc[1:], b).to_dict(orient="list"),
            "half_width": b}


def table(results: list[dict[str, Any]]) -> str:
    """The study's markdown tables."""
    base = pd.DataFrame(results[0]["curve"])
    b = results[0]["half_width"]
    lines = ["| variant | steps | iterations | evaluations | particle-steps | vs first | "
             "wall [s] | q at s/B 0.05 [kPa] | at 0.1 | peak | peak vs first |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        curve = pd.DataFrame(r["curve"])
        cells = []
        for s in (0.05 * 2 * b, 0.1 * 2 * b):  # s/B with B = 2b, the footing's width
            q, q0 = q_at(curve, s), q_at(base, s)
            cells.append("–" if q is None else f"{q / 1e3:.1f}" + (
                "" if q0 is None or r is results[0] else f" ({100 * (q / q0 - 1):+.1f} %)"))
        peak = curve["q"].max() if len(curve) else float("nan")
        peak0 = base["q"].max() if len(base) else float("nan")
        lines.append(
            f"| {r['name']} | {r['steps_done']} | {r['iterations']} | {r['evaluations']} | "
            f"{r['particle_steps']:.3g} | {r['particle_steps'] / results[0]['particle_steps']:.2f} "
            f"| {r['wall_s']:.0f} | {cells[0]} | {cells[1]} | {peak / 1e3:.1f} | "
            f"{100 * (peak / peak0 - 1):+.1f} % |")
    lines += ["", "Share of the particle-steps:", "",
              "| variant | busiest 5 % of RVEs | 10 % | 25 % | 50 % | within b of the edge "
              "(RVEs) | within 2b (RVEs) |", "|---|---|---|---|---|---|---|"]
    for r in results:
        d = r["division"]
        if not d:
            continue
        lines.append(
            f"| {r['name']} | {d['top_5%']:.2f} | {d['top_10%']:.2f} | {d['top_25%']:.2f} | "
            f"{d['top_50%']:.2f} | {d['within_1b']:.2f} ({d['rves_within_1b']:.2f}) | "
            f"{d['within_2b']:.2f} ({d['rves_within_2b']:.2f}) |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    """Run the variants; write and return their results."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", type=Path, default=SCENE)
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "footing-cost")
    ap.add_argument("--steps", type=int, default=None, help="cut the scene to these steps")
    ap.add_argument("--particles", type=int, default=None, help="discs per RVE (the scene's)")
    ap.add_argument("--elements", type=int, nargs=2, default=None, metavar=("NX", "NY"),
                    help="elements of a generated mesh (the scene's)")
    ap.add_argument("--variant", action="append", default=None, metavar="NAME:SETTINGS",
                    help="a variant (repeatable; default the study's four)")
    ap.add_argument("--report-only", action="store_true",
                    help="rewrite the tables from OUT/footing_cost.json and each variant's "
                         "steps.csv, running nothing")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.report_only:
        results = json.loads((args.out / "footing_cost.json").read_text())
        for r in results:
            steps = pd.read_csv(args.out / r["name"] / "steps.csv").iloc[1:]
            r["curve"] = bearing(steps, r["half_width"]).to_dict(orient="list")
        report = table(results)
        (args.out / "footing_cost.md").write_text(report, encoding="utf-8")
        print(report)
        return results
    results = []
    for text in args.variant or VARIANTS:
        name, tables = parse_variant(text)
        print(f"-- {name} ({time.strftime('%H:%M:%S')})", flush=True)
        results.append(run_variant(args.scene, name, tables, args.steps, args.particles,
                                   args.out, None if args.elements is None
                                   else tuple(args.elements)))
        (args.out / "footing_cost.json").write_text(json.dumps(results, indent=1) + "\n")
    report = table(results)
    (args.out / "footing_cost.md").write_text(report, encoding="utf-8")
    print(report)
    return results


if __name__ == "__main__":
    main()
