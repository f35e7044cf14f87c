"""The DEM material against its calibrated Mohr–Coulomb twin, side by side (issue 45).

Every run is a ``granular-material`` command on the same RVE material, in this order:

1. ``calibrate``: drained biaxial DEM tests of ``--rves`` RVEs (seeds 1, 2, …) of the RVE
   material the specimen prepares (Wu et al.'s constant contact law) at P = 100 kPa, and of
   Guo & Zhao's RVE material (the footing scene's) at 20 kPa: the two material files;
2. ``element``: ``single-element`` with each RVE alone (replicated to its 4 Gauss points)
   against ``--material mohr-coulomb --material-file`` (100 kPa);
3. ``specimen``: ``biaxial --scale reduced`` (5 × 10 Q4, one RVE per Gauss point) with the
   DEM and with the calibrated material, same mesh and platens;
4. ``footing``: the footing scene with its DEM material (the scene's updated-Lagrangian
   kinematics), and with the calibrated Mohr–Coulomb (as calibrated, and perfectly plastic
   at φ and at φcs) on the same mesh with small-strain kinematics, the classical reference;
   the perfectly plastic one also with the DEM run's kinematics (``mc-peak-ul``);
5. ``report``: figures, ``results.json`` and ``report.md`` in ``--out``.

The cheap (Mohr–Coulomb) runs are repeated ``--repeats`` times and their median time is
quoted; each run's time is the command's own (``summary.json``), beside the process's wall
time. A stage whose outputs exist is not rerun (``--force`` reruns it)::

    python benchmarks/material_comparison.py --out out/material-comparison
    python benchmarks/material_comparison.py --smoke --out /tmp/mc-smoke   # seconds

The report of record is ``docs/validation/mohr-coulomb/report.md``.
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from material_comparison_measures import material_file  # beside this script

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
FOOTING_SCENE = ROOT / "examples" / "scenes" / "footing-gz2016-cpu.toml"
#: Guo & Zhao's RVE material (the footing scene's), as ``prepare`` options
GZ_MATERIAL = ("--law", "frictmat", "--contact-young", "6e8", "--kt-over-kn", "0.8",
               "--radius-min", "3e-3", "--radius-max", "7e-3", "--contact-friction-angle", "0.5",
               "--damping", "0.1")


@dataclass(frozen=True)
class Scale:
    """Sizes of one study: discs and RVEs of the calibration, steps, mesh overrides."""

    discs: int = 64
    rves: int = 4
    axial_strain: float = 0.1
    element_steps: int = 100
    specimen_steps: int = 100
    specimen_elements: tuple[int, int] | None = None   # None: --scale reduced
    specimen_particles: int | None = None
    footing_steps: int | None = None                   # None: the scene's
    footing_elements: tuple[int, int] | None = None
    footing_settlement: float | None = None            # [m]; None: the scene's
    footing_particles: int | None = None
    large_discs: int | None = None                     # a second calibration (e.g. 400)


FULL = Scale(large_discs=400)
SMOKE = Scale(discs=16, rves=2, axial_strain=0.03, element_steps=6, specimen_steps=6,
              specimen_elements=(2, 4), specimen_particles=16, footing_steps=3,
              footing_elements=(4, 3), footing_settlement=0.0015, footing_particles=16)


def scene_with(text: str, material: str, parameters: dict[str, Any],
               overrides: dict[str, str] | None = None) -> str:
    """A scene's TOML text with its ``[material]`` tables replaced by ``material`` and its
    ``parameters``; ``overrides`` maps a top-level-or-table key line's regex (``^key =``) to
    its new right-hand side (e.g. ``{"steps": "3"}``)."""
    lines, out, skipping = text.splitlines(), [], False
    for line in lines:
        header = re.match(r"^\s*\[\[?([^\]]+)\]\]?", line)
        if header:
            skipping = header.group(1).strip() in ("material", "material.parameters")
        if not skipping:
            out.append(line)
    body = "\n".join(out) + "\n"
    for key, value in (overrides or {}).items():
        body, n = re.subn(rf"(?m)^({re.escape(key)}\s*=\s*)([^#\n]*?)(\s*(#.*)?)$",
                          lambda m, v=value: m.group(1) + v + m.group(3), body, count=1)
        if n == 0:
            raise KeyError(f"no line {key} = ... in the scene")
    table = [f'[material]\nname = "{material}"', "[material.parameters]"]
    table += [f"{k} = {json.dumps(v)}" for k, v in parameters.items()]
    return body.rstrip() + "\n\n" + "\n".join(table) + "\n"


# -- running the commands ------------------------------------------------------------------
def gm(args: list[str], log: Path) -> float:
    """Run ``granular-material ARGS``, its output in ``log``; the process's wall time [s]."""
    start = time.perf_counter()
    with log.open("w") as f:
        done = subprocess.run([sys.executable, "-m", "granular_material.cli", *map(str, args)],
                              stdout=f, stderr=subprocess.STDOUT, cwd=ROOT, check=False)
    wall = time.perf_counter() - start
    if done.returncode not in (0,):
        print(f"  ! exit {done.returncode}: see {log}", file=sys.stderr)
    return wall


def run_time(folder: Path) -> float | None:
    """A run's own time [s] from its summary.json (None when it has none)."""
    path = folder / "summary.json"
    if not path.is_file():
        return None
    s = json.loads(path.read_text())
    for key in ("wall_time_s", "wall_s"):
        if s.get(key) is not None:
            return float(s[key])
    return None


def timed(folder: Path, args: list[str], repeats: int, force: bool,
          costs: dict[str, Any], name: str) -> None:
    """Run a command (into ``folder``) ``repeats`` times; its times into ``costs[name]``."""
    if (folder / "summary.json").is_file() and not force and name in costs:
        return
    inner, outer = [], []
    for i in range(repeats):
        target = folder if i == 0 else folder.with_name(folder.name + f"-r{i}")
        outer.append(gm([*args, "--out", target], folder.parent / f"{target.name}.log"))
        inner.append(run_time(target))
    costs[name] = {"run_s": inner, "process_s": outer,
                   "run_median_s": statistics.median([t for t in inner if t is not None])
                   if any(t is not None for t in inner) else None,
                   "process_median_s": statistics.median(outer)}


def stage_calibrate(out: Path, scale: Scale, force: bool, costs: dict) -> None:
    """RVE files and material files: 100 kPa (specimen material) and 20 kPa (footing's)."""
    sets = [("100k", 100e3, scale.discs, ()), ("gz20k", 20e3, scale.discs, GZ_MATERIAL)]
    if scale.large_discs:
        sets.append((f"100k-{scale.large_discs}", 100e3, scale.large_discs, ()))
    for tag, p, discs, extra in sets:
        rve = out / f"rve-{tag}.npz"
        if force or not rve.is_file():
            gm(["prepare", "--particles", discs, "--batch", scale.rves, "--seed", 1,
                "--pressure", p, "--device", "cpu", *extra, "--out", rve],
               out / f"prepare-{tag}.log")
        cal = out / f"calibration-{tag}"
        if force or not (cal / "mohr-coulomb.toml").is_file():
            wall = gm(["calibrate", rve, "--confining", p, "--axial-strain", scale.axial_strain,
                       "--device", "cpu", "--no-progress", "--out", cal],
                      out / f"calibrate-{tag}.log")
            costs[f"calibrate-{tag}"] = {"process_s": [wall], "process_median_s": wall}
    from granular_material.dem import load_rve, save_rve

    data = load_rve(out / "rve-100k.npz")
    for i in range(data.n_rve):
        path = out / f"rve-100k-{i}.npz"
        if force or not path.is_file():
            save_rve(path, data.take(slice(i, i + 1)))


def stage_element(out: Path, scale: Scale, repeats: int, force: bool, costs: dict) -> None:
    """The single element: every RVE alone, and the calibrated Mohr–Coulomb."""
    common = ["single-element", "--axial-strain", scale.axial_strain, "--confining", 100e3,
              "--steps", scale.element_steps, "--device", "cpu", "--no-progress"]
    for i in range(scale.rves):
        timed(out / f"element-dem-{i}", [*common, "--material", "dem", "--rve",
                                         out / f"rve-100k-{i}.npz"], 1, force, costs,
              f"element-dem-{i}")
    timed(out / "element-mc", [*common, "--material", "mohr-coulomb", "--material-file",
                               out / "calibration-100k" / "mohr-coulomb.toml"],
          repeats, force, costs, "element-mc")


def stage_specimen(out: Path, scale: Scale, repeats: int, force: bool, costs: dict) -> None:
    """The biaxial specimen, reduced scale, both materials on the same mesh, with smooth
    platens (one node pinned) and with rough ones."""
    size = (["--scale", "reduced"] if scale.specimen_elements is None else
            ["--elements", *scale.specimen_elements, "--particles", scale.specimen_particles])
    maps = [s for s in (0.02, 0.05, 0.1) if s <= scale.axial_strain] or [scale.axial_strain]
    common = ["biaxial", *size, "--axial-strain", scale.axial_strain, "--confining", 100e3,
              "--steps", scale.specimen_steps, "--map-strain", *maps, "--device", "cpu",
              "--no-progress"]
    for platens in ("smooth", "rough"):
        tag = "" if platens == "smooth" else "-rough"
        timed(out / f"specimen-dem{tag}", [*common, "--platens", platens, "--material", "dem"],
              1, force, costs, f"specimen-dem{tag}")
        timed(out / f"specimen-mc{tag}", [*common, "--platens", platens, "--material",
                                          "mohr-coulomb", "--material-file",
                                          out / "calibration-100k" / "mohr-coulomb.toml"],
              repeats, force, costs, f"specimen-mc{tag}")


def footing_variants(parameters: dict[str, float]) -> dict[str, dict[str, float]]:
    """The footing's Mohr–Coulomb materials: as calibrated, perfectly plastic at φ, at φcs."""
    phi, phi_cs = "friction_angle", "critical_friction_angle"
    base = {k: parameters[k] for k in ("young", "poisson", phi, "dilation_angle", "cohesion")}
    variants = {"mc": dict(parameters)}
    variants["mc-peak"] = base
    variants["mc-cs"] = base | {phi: parameters.get(phi_cs, parameters[phi]),
                                "dilation_angle": min(parameters["dilation_angle"],
                                                      parameters.get(phi_cs, parameters[phi]))}
    return variants


def stage_footing(out: Path, scale: Scale, repeats: int, force: bool, costs: dict) -> None:
    """The footing scene: its DEM material, then the calibrated Mohr–Coulomb variants."""
    text = FOOTING_SCENE.read_text(encoding="utf-8")
    over: dict[str, str] = {}
    if scale.footing_steps:
        over["steps"] = str(scale.footing_steps)
    if scale.footing_elements:
        over["elements"] = json.dumps(list(scale.footing_elements))
    if scale.footing_settlement:
        over["displacement"] = f"[0.0, {-scale.footing_settlement!r}]"
    dem_parameters = _dem_parameters(text)
    if scale.footing_particles:
        dem_parameters["particles"] = scale.footing_particles
    dem_scene = out / "footing-dem.toml"
    dem_scene.write_text(scene_with(text, "dem", dem_parameters, over), encoding="utf-8")
    timed(out / "footing-dem", ["run", dem_scene], 1, force, costs, "footing-dem")
    parameters = material_file(out / "calibration-gz20k" / "mohr-coulomb.toml")
    variants = footing_variants(parameters)
    variants["mc-peak-ul"] = variants["mc-peak"]
    for name, params in variants.items():
        scene = out / f"footing-{name}.toml"
        body = scene_with(text, "mohr-coulomb", params, over)
        if not name.endswith("-ul"):  # the classical reference: small-strain kinematics
            body += '\n[newton]\nformulation = "small-strain"\n'
        scene.write_text(body, encoding="utf-8")
        timed(out / f"footing-{name}", ["run", scene], repeats, force, costs, f"footing-{name}")


def _dem_parameters(text: str) -> dict[str, Any]:
    """The scene's own ``[material.parameters]`` (its DEM material)."""
    return dict(tomllib.loads(text)["material"]["parameters"])


STAGES = ("calibrate", "element", "specimen", "footing", "report")


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the stages asked for; return the results (also ``OUT/results.json``)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "material-comparison")
    ap.add_argument("--stages", nargs="+", choices=STAGES, default=list(STAGES))
    ap.add_argument("--repeats", type=int, default=3, help="runs of each cheap command (3)")
    ap.add_argument("--smoke", action="store_true", help="tiny sizes (a test)")
    ap.add_argument("--force", action="store_true", help="rerun stages whose outputs exist")
    ap.add_argument("--publish", type=Path, default=None, metavar="DIR",
                    help="copy the report and figures there (docs/validation/mohr-coulomb)")
    args = ap.parse_args(argv)
    scale = SMOKE if args.smoke else FULL
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    costs_path = out / "costs.json"
    costs = json.loads(costs_path.read_text()) if costs_path.is_file() else {}
    for stage in args.stages:
        print(f"-- {stage} ({time.strftime('%H:%M:%S')})", flush=True)
        if stage == "calibrate":
            stage_calibrate(out, scale, args.force, costs)
        elif stage == "element":
            stage_element(out, scale, args.repeats, args.force, costs)
        elif stage == "specimen":
            stage_specimen(out, scale, args.repeats, args.force, costs)
        elif stage == "footing":
            stage_footing(out, scale, args.repeats, args.force, costs)
        costs_path.write_text(json.dumps(costs, indent=1) + "\n")
    if "report" in args.stages:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from material_comparison_report import write_report  # beside this script

        results = write_report(out, asdict(scale), costs)
        if args.publish:
            from material_comparison_report import publish

            publish(out, args.publish)
        return results
    return {"costs": costs}


if __name__ == "__main__":
    main()
