"""Past the peak with and without the second gradient: does the answer still depend on the
mesh? (docs/validation/regularisation)

Every run is a ``granular-material`` command; the stages, in order:

1. ``specimen``: the Mohr–Coulomb softening specimen (φ 35° → 28° over a plastic shear
   strain of 0.02, ψ = 5°, rough platens, 5 % in 50 steps, quad8) on 4 × 8, 8 × 16 and
   16 × 32 elements, without regularisation and with the second gradient at two internal
   lengths;
2. ``dem``: the FEM × DEM reduced specimen (64-disc RVEs, one per Gauss point, quad8, rough
   platens) on two meshes × three seeds, without and with the second gradient;
3. ``footing``: Guo & Zhao's reduced footing scene with the softening Mohr–Coulomb twin
   calibrated from its RVEs (docs/validation/mohr-coulomb) on three meshes, without and with
   the second gradient, and with its DEM material on two meshes with it;
4. ``report``: figures, ``results.json`` and ``report.md`` in ``--out``.

A run whose ``summary.json`` exists is not redone (``--force`` redoes it)::

    python benchmarks/regularisation_study.py --out out/regularisation
    python benchmarks/regularisation_study.py --smoke --out /tmp/reg-smoke    # seconds

The report of record is ``docs/validation/regularisation/report.md`` (``--publish``).
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
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.results.band_measures import value_at
from granular_material.results.writers import read_points

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
FOOTING_SCENE = ROOT / "examples" / "scenes" / "footing-gz2016-cpu.toml"
CALIBRATION = ROOT / "docs" / "validation" / "mohr-coulomb" / "results.json"
#: the softening Mohr–Coulomb specimen of the issue that asked for a regularisation
MC_SPECIMEN = ("--material", "mohr-coulomb", "--friction-angle", "35",
               "--critical-friction-angle", "28", "--softening-strain", "0.02",
               "--dilation-angle", "5", "--platens", "rough", "--element", "quad8")
#: the band search's thresholds for the study's wide, regularised bands (its defaults,
#: contrast 1.5 and aspect 3, are made for bands a few elements wide, in a specimen many
#: times wider): a zone 20–30 mm wide across a 50 mm specimen is no longer than 1.5 times
#: its width, so each band's length is reported beside its width
WIDE_BANDS = {"contrast": 1.1, "aspect": 1.2}
#: the axial strains [-] at which the active bands are also measured (each over the last
#: fifth of its strain, as at the last step): how the width evolves
ACTIVE_STRAINS = (0.03, 0.04)


@dataclass(frozen=True)
class Scale:
    """The sizes of one study."""

    specimen_meshes: tuple[tuple[int, int], ...] = ((4, 8), (8, 16), (16, 32))
    specimen_lengths: tuple[float, ...] = (0.0, 0.005, 0.01)
    #: further (elements, ℓ) runs: shorter lengths on the finer meshes (32 × 64 at 2.5 mm
    #: took a minute a step on the loaded 2-core CPU: left out)
    specimen_extra: tuple[tuple[int, int, float], ...] = ((8, 16, 0.0025), (16, 32, 0.0025),
                                                          (16, 32, 0.00125))
    specimen_steps: int = 50
    specimen_strain: float = 0.05
    dem_meshes: tuple[tuple[int, int], ...] = ((3, 6), (6, 12))
    dem_seeds: tuple[int, ...] = (1, 2, 3)
    dem_lengths: tuple[float, ...] = (0.0, 0.005)
    dem_particles: int = 64
    dem_steps: int = 50
    dem_strain: float = 0.10
    footing_meshes: tuple[tuple[int, int], ...] = ((6, 4), (12, 8), (24, 16))
    footing_lengths: tuple[float, ...] = (0.0, 0.005, 0.01)
    footing_dem_meshes: tuple[tuple[int, int], ...] = ((6, 4), (12, 8))
    footing_dem_lengths: tuple[float, ...] = (0.0, 0.01)
    #: the twin's footing by arc length ([newton] continuation), on footing_meshes: past
    #: the snap-back that stops load control (ℓ = 5 mm on 24 × 16 at 8.25 mm), and without
    #: regularisation, where it does not help
    footing_arc_lengths: tuple[float, ...] = (0.0, 0.005)
    footing_steps: int | None = None        # None: the scene's 58
    footing_settlement: float | None = None  # [m]; None: the scene's 14.5 mm
    footing_particles: int | None = None     # None: the scene's 64
    extra: dict[str, Any] = field(default_factory=dict)


FULL = Scale()
SMOKE = Scale(specimen_meshes=((2, 4),), specimen_lengths=(0.0, 0.01), specimen_extra=(),
              specimen_steps=4, specimen_strain=0.01, dem_meshes=((1, 2),), dem_seeds=(1,),
              dem_lengths=(0.0, 0.01), dem_particles=16, dem_steps=2, dem_strain=0.004,
              footing_meshes=((4, 3),), footing_lengths=(0.0, 0.02), footing_dem_meshes=(),
              footing_arc_lengths=(0.02,), footing_steps=3, footing_settlement=0.0015)


def _tag(length: float) -> str:
    return "none" if length == 0 else f"l{length * 1e3:g}mm"


def run_command(folder: Path, words: list[Any], force: bool) -> dict[str, Any]:
    """``granular-material WORDS --out FOLDER``, unless its summary exists; its summary with
    the process's wall time [s] and exit code added."""
    summary_file = folder / "summary.json"
    if summary_file.exists() and not force:
        return json.loads(summary_file.read_text(encoding="utf-8"))
    if folder.exists():
        shutil.rmtree(folder)
    command = [sys.executable, "-m", "granular_material.cli", *map(str, words), "--out",
               str(folder)]
    print("$", " ".join(command[2:]), flush=True)
    t0 = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if not summary_file.exists():
        raise RuntimeError(f"{' '.join(command)} wrote no summary (exit {done.returncode}):\n"
                           f"{done.stderr[-2000:]}")
    summary = json.loads(summary_file.read_text(encoding="utf-8"))
    summary.update(process_wall_s=wall, exit_code=done.returncode)
    summary_file.write_text(json.dumps(summary, indent=2, default=str) + "\n",
                            encoding="utf-8")
    return summary


def _regularised(length: float) -> list[Any]:
    return [] if length == 0 else ["--regularisation", "second-gradient",
                                   "--internal-length", length]


def bands_of(folder: Path, step: int | None = None,
             points: pd.DataFrame | None = None) -> list[dict[str, float]]:
    """The bands of a run's points table (None: read from ``folder``) at ``step`` (None: its
    last), searched with the study's thresholds (:data:`WIDE_BANDS`)."""
    from granular_material.results.bands import find_bands

    points = read_points(folder) if points is None else points
    return [b.as_dict() for b in find_bands(points, step, **WIDE_BANDS)]


def active_of(points: pd.DataFrame, strains: tuple[float, ...] = ACTIVE_STRAINS
              ) -> dict[str, Any]:
    """The bands active at the last step of a run's ``points`` (Gaussian ridges fitted to
    the shear strain of the increment over the last fifth of the axial strain,
    :func:`~granular_material.results.active_bands.active_bands`), and their mean width at
    the steps nearest ``strains`` that the run reached."""
    from granular_material.results.active_bands import active_bands

    bands = active_bands(points)
    by_step = points.groupby("step")["axial_strain"].first()
    evolution = {}
    for e in strains:
        if e >= by_step.max() * (1 - 1e-9):
            continue  # the last step's is the run's own; past it, none
        step = int((by_step - e).abs().idxmin())
        at = active_bands(points, step)
        evolution[f"{100 * e:g}"] = (float(np.mean([b.width for b in at])) if at
                                     else math.nan)
    return {"active_band_count": len(bands),
            "active_band_width": (float(np.mean([b.width for b in bands])) if bands
                                  else math.nan),
            "active_widths": [b.width for b in bands],
            "active_angles": [b.inclination_deg for b in bands],
            "active_residual": bands[0].residual if bands else math.nan,
            "active_window": ([bands[0].start_axial_strain, bands[0].axial_strain] if bands
                              else []),
            "active_width_at": evolution}


def specimen_row(folder: Path, summary: dict[str, Any]) -> dict[str, Any]:
    """The measures of one biaxial run."""
    steps = pd.read_csv(folder / "steps.csv")
    strain = steps["axial_strain"].to_numpy(dtype=float)
    ratio = steps["stress_ratio"].to_numpy(dtype=float)
    points = read_points(folder)
    bands = bands_of(folder, points=points)
    widest = max(bands, key=lambda b: b["strength"]) if bands else None
    return {
        "steps_completed": int(summary.get("steps_completed", len(steps) - 1)),
        "peak_ratio": float(np.nanmax(ratio[1:])) if len(ratio) > 1 else math.nan,
        "peak_strain": float(strain[int(np.nanargmax(ratio[1:])) + 1]) if len(ratio) > 1
        else math.nan,
        "ratio_5": value_at(strain, ratio, 0.05), "ratio_10": value_at(strain, ratio, 0.10),
        "iterations": float(summary.get("newton_iterations_mean", math.nan)),
        "cutbacks": int(summary.get("cutbacks", 0)),
        "time_s": float(summary.get("timing_s", {}).get("total", math.nan)),
        "linear_solve_s": float(summary.get("timing_s", {}).get("linear_solve", math.nan)),
        "band_count": len(bands),
        "band_width": widest["width"] if widest else math.nan,
        "band_widths": [b["width"] for b in bands],
        "band_lengths": [b["length"] for b in bands],
        "band_angles": [b["inclination_deg"] for b in bands],
        **active_of(points),
        "error": summary.get("error"),
    }


def stage_specimen(out: Path, scale: Scale, force: bool) -> list[dict[str, Any]]:
    rows = []
    runs = [(nx, ny, length) for nx, ny in scale.specimen_meshes
            for length in scale.specimen_lengths]
    for nx, ny, length in [*runs, *scale.specimen_extra]:
        folder = out / f"specimen-{nx}x{ny}-{_tag(length)}"
        summary = run_command(folder, ["biaxial", *MC_SPECIMEN, "--elements", nx, ny,
                                       "--axial-strain", scale.specimen_strain,
                                       "--steps", scale.specimen_steps,
                                       "--no-progress", *_regularised(length)], force)
        rows.append({"mesh": f"{nx}x{ny}", "element_size": 0.05 / nx,
                     "internal_length": length, "folder": folder.name,
                     **specimen_row(folder, summary)})
    return rows


def stage_dem(out: Path, scale: Scale, force: bool) -> list[dict[str, Any]]:
    rows = []
    for nx, ny in scale.dem_meshes:
        for seed in scale.dem_seeds:
            for length in scale.dem_lengths:
                folder = out / f"dem-{nx}x{ny}-seed{seed}-{_tag(length)}"
                summary = run_command(folder, [
                    "biaxial", "--element", "quad8", "--elements", nx, ny, "--particles",
                    scale.dem_particles, "--seed", seed, "--platens", "rough",
                    "--axial-strain", scale.dem_strain, "--steps", scale.dem_steps,
                    "--device", "cpu", "--no-progress", *_regularised(length)], force)
                rows.append({"mesh": f"{nx}x{ny}", "seed": seed, "internal_length": length,
                             "folder": folder.name, **specimen_row(folder, summary)})
    return rows


def _calibrated() -> dict[str, float]:
    """The softening Mohr–Coulomb twin of the footing's RVEs (Guo & Zhao's material at
    20 kPa, docs/validation/mohr-coulomb/results.json)."""
    c = json.loads(CALIBRATION.read_text(encoding="utf-8"))["calibration"]["gz20k"]
    return {"young": c["E"]["value"], "poisson": c["nu"]["value"],
            "friction_angle": c["phi"]["value"], "dilation_angle": c["psi"]["value"],
            "critical_friction_angle": c["phi_cs"]["value"],
            "softening_strain": c["softening_strain"]["value"], "cohesion": 0.0}


def footing_scene(text: str, elements: tuple[int, int], length: float, scale: Scale,
                  material: dict[str, Any] | None, continuation: str = "load") -> str:
    """The footing scene on ``elements``, with the second gradient of ``length`` (0: none),
    with the Mohr–Coulomb ``material`` (small strain, stepped by ``continuation``) or,
    None, its own DEM material."""
    text = re.sub(r"^elements = \[[^\]]*\]", f"elements = [{elements[0]}, {elements[1]}]",
                  text, count=1, flags=re.M)
    if scale.footing_steps is not None:
        text = re.sub(r"^steps = \d+", f"steps = {scale.footing_steps}", text, count=1,
                      flags=re.M)
    if scale.footing_settlement is not None:
        text = re.sub(r"^displacement = \[0\.0, -0\.0145\]",
                      f"displacement = [0.0, {-scale.footing_settlement!r}]", text, count=1,
                      flags=re.M)
    if material is not None:
        head = text[:text.index("[material]")]
        values = "\n".join(f"{k} = {v!r}" for k, v in material.items())
        text = (head + '[material]\nname = "mohr-coulomb"\n\n[material.parameters]\n'
                + values + '\n\n[newton]\nformulation = "small-strain"\n'
                + ("" if continuation == "load" else f'continuation = "{continuation}"\n'))
    elif scale.footing_particles is not None:
        text = re.sub(r"^particles = \d+", f"particles = {scale.footing_particles}", text,
                      count=1, flags=re.M)
    if length:
        text += (f'\n[regularisation]\nmodel = "second-gradient"\n'
                 f"internal_length = {length!r}\n")
    tomllib.loads(text)  # a scene that reads
    return text


def footing_row(folder: Path, summary: dict[str, Any], width: float = 0.05
                ) -> dict[str, Any]:
    steps = pd.read_csv(folder / "steps.csv")
    settlement = -steps["footing_displacement_y"].to_numpy(dtype=float)
    pressure = -steps["footing_force_y"].to_numpy(dtype=float) / width
    return {"steps_completed": len(steps) - 1,
            "settlement_reached": float(settlement.max()),
            "peak_pressure": float(pressure.max()),
            "peak_settlement": float(settlement[int(pressure.argmax())]),
            "final_pressure": float(pressure[-1]),
            "iterations": float(steps["iterations"].iloc[1:].mean()) if len(steps) > 1
            else math.nan,
            "time_s": float(summary.get("wall_s", math.nan)),
            "error": summary.get("error")}


def stage_footing(out: Path, scale: Scale, force: bool) -> list[dict[str, Any]]:
    text = FOOTING_SCENE.read_text(encoding="utf-8")
    material = _calibrated()
    rows = []
    runs = [(m, length, material, "load") for m in scale.footing_meshes
            for length in scale.footing_lengths]
    runs += [(m, length, None, "load") for m in scale.footing_dem_meshes
             for length in scale.footing_dem_lengths]
    runs += [(m, length, material, "arc-length") for m in scale.footing_meshes
             for length in scale.footing_arc_lengths]
    for elements, length, mat, continuation in runs:
        kind = "mc" if mat is not None else "dem"
        name = (f"footing-{kind}-{elements[0]}x{elements[1]}-{_tag(length)}"
                + ("" if continuation == "load" else "-arc"))
        scene = out / f"{name}.toml"
        scene.write_text(footing_scene(text, elements, length, scale, mat, continuation),
                         encoding="utf-8")
        summary = run_command(out / name, ["run", scene], force)
        rows.append({"material": kind, "mesh": f"{elements[0]}x{elements[1]}",
                     "internal_length": length, "continuation": continuation,
                     "folder": name, **footing_row(out / name, summary)})
    return rows


STAGES = ("specimen", "dem", "footing", "report")


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the stages asked for; return the results (also ``OUT/results.json``)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "regularisation")
    ap.add_argument("--stages", nargs="+", choices=STAGES, default=list(STAGES))
    ap.add_argument("--smoke", action="store_true", help="tiny sizes (a test)")
    ap.add_argument("--force", action="store_true", help="redo runs whose summary exists")
    ap.add_argument("--publish", type=Path, default=None, metavar="DIR",
                    help="copy the report and figures there (docs/validation/regularisation)")
    args = ap.parse_args(argv)
    scale = SMOKE if args.smoke else FULL
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    results_file = out / "results.json"
    results: dict[str, Any] = (json.loads(results_file.read_text(encoding="utf-8"))
                               if results_file.exists() else {})
    results["scale"] = {k: v for k, v in asdict(scale).items() if k != "extra"}
    stages = {"specimen": stage_specimen, "dem": stage_dem, "footing": stage_footing}
    for name in args.stages:
        if name in stages:
            results[name] = stages[name](out, scale, args.force)
            results_file.write_text(json.dumps(results, indent=2, default=str) + "\n",
                                    encoding="utf-8")
    if "report" in args.stages:
        from regularisation_report import write_report  # beside this script

        write_report(out, results)
        if args.publish is not None:
            args.publish.mkdir(parents=True, exist_ok=True)
            for path in [out / "report.md", out / "results.json", *out.glob("*.png")]:
                shutil.copy2(path, args.publish / path.name)
    return results


if __name__ == "__main__":
    main()
