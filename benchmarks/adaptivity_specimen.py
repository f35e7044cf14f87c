"""Adaptivity on the reduced biaxial specimen, where every point yields: the all-DEM run
against ``--adaptivity`` (the defaults), seed by seed.

``granular-material biaxial --scale reduced`` (5 × 10 quad4, 200 Gauss points of 64-disc
RVEs, 100 steps to 10 % axial strain at 100 kPa) runs once all-DEM and once adaptive for
each seed (one independent set of RVEs per seed: seed, seed + 1, …, seed + 199; seeds 1
and 1001, as the trade study's specimen rows). It reports, for each seed, the peak σ1/σ3 and
its axial strain, the RMS difference of σ1/σ3 and of εv over the steps, the DEM points over
the run, the particle-steps (the switches' own included) and the wall times, beside the
all-DEM runs' own scatter between the seeds, in ``specimen.json``, with the curves in
``specimen.png`` (``--publish DIR``: the figure there too; docs/validation/adaptivity's
specimen.md is written from them). A run whose ``summary.json`` exists is read, not
redone::

    python benchmarks/adaptivity_specimen.py --out out/specimen --publish docs/validation/adaptivity
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

SEEDS = (1, 1001)
VARIANTS = {"all-DEM": [], "adaptive": ["--adaptivity"]}


def run(out: Path, seed: int, variant: str) -> Path:
    """The folder of one run (run here unless its summary.json exists)."""
    folder = out / f"{variant}-seed{seed}"
    if not (folder / "summary.json").is_file():
        subprocess.run([sys.executable, "-m", "granular_material.cli", "biaxial", "--scale",
                        "reduced", "--device", "cpu", "--seed", str(seed), "--no-progress",
                        "--out", str(folder), *VARIANTS[variant]], check=True)
    return folder


def _read(folder: Path) -> tuple[pd.DataFrame, dict[str, Any]]:
    return (pd.read_csv(folder / "steps.csv"),
            json.loads((folder / "summary.json").read_text()))


def _cost(steps: pd.DataFrame) -> int:
    """DEM particle-steps of a run: its steps' and its switches'."""
    switches = steps["switch_particle_steps"].sum() if "switch_particle_steps" in steps else 0
    return int(steps["particle_steps"].sum() + switches)


def _rms(a: pd.Series, b: pd.Series) -> float:
    return float(np.sqrt(np.mean((a.to_numpy() - b.to_numpy()) ** 2)))


def measure(out: Path) -> dict[str, Any]:
    """Each seed's comparison and the all-DEM runs' scatter between the seeds."""
    rows: dict[str, Any] = {}
    for seed in SEEDS:
        dem, dem_summary = _read(out / f"all-DEM-seed{seed}")
        ada, ada_summary = _read(out / f"adaptive-seed{seed}")
        peak = dem_summary["peak_stress_ratio"]
        ev = float(dem["volumetric_strain"].abs().max())
        dem_points = ada["dem_points"].to_numpy()
        rows[str(seed)] = {
            "peak_dem": peak, "at_dem": dem_summary["axial_strain_at_peak"],
            "peak_adaptive": ada_summary["peak_stress_ratio"],
            "at_adaptive": ada_summary["axial_strain_at_peak"],
            "peak_difference_pct": 100 * (ada_summary["peak_stress_ratio"] / peak - 1),
            "rms_ratio_pct": 100 * _rms(ada["stress_ratio"], dem["stress_ratio"]) / peak,
            "rms_ev_pct": 100 * _rms(ada["volumetric_strain"], dem["volumetric_strain"]) / ev,
            "cost_dem": _cost(dem), "cost_adaptive": _cost(ada),
            "switch_cost": int(ada["switch_particle_steps"].sum()),
            "cost_ratio": _cost(ada) / _cost(dem),
            "wall_dem": dem_summary["timing_s"]["total"],
            "wall_adaptive": ada_summary["timing_s"]["total"],
            "calibration_s": ada_summary["adaptivity"]["twin"].get("seconds"),
            "first_dem_strain": float(ada["axial_strain"][dem_points > 0].min()),
            "all_dem_strain": float(ada["axial_strain"][dem_points == dem_points.max()].min()),
            "dem_points_final": int(dem_points[-1]), "gauss_points": dem_summary["gauss_points"],
            "twin": ada_summary["adaptivity"]["twin"]["parameters"],
        }
    a, b = (_read(out / f"all-DEM-seed{s}") for s in SEEDS)
    peaks = [a[1]["peak_stress_ratio"], b[1]["peak_stress_ratio"]]
    mean = float(np.mean(peaks))
    scatter = {"peak_pct": 100 * abs(peaks[0] - peaks[1]) / mean,
               "rms_ratio_pct": 100 * _rms(a[0]["stress_ratio"], b[0]["stress_ratio"]) / mean,
               "rms_ev_pct": 100 * _rms(a[0]["volumetric_strain"], b[0]["volumetric_strain"])
               / float(a[0]["volumetric_strain"].abs().max())}
    return {"seeds": rows, "scatter": scatter}


def figure(out: Path, path: Path) -> None:
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 7.0), sharex=True)
    for seed, colour in zip(SEEDS, ("C0", "C1"), strict=True):
        for variant, style in (("all-DEM", "-"), ("adaptive", "--")):
            steps, _ = _read(out / f"{variant}-seed{seed}")
            x = 100 * steps["axial_strain"]
            label = f"{variant}, seed {seed}"
            top.plot(x, steps["stress_ratio"], style, color=colour, label=label)
            bottom.plot(x, 100 * steps["volumetric_strain"], style, color=colour)
    top.set_ylabel("σ1/σ3")
    bottom.set_ylabel("εv [%] (compression negative)")
    bottom.set_xlabel("axial strain [%]")
    top.legend(fontsize=8)
    top.grid(alpha=0.3)
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="the runs' folder")
    parser.add_argument("--publish", type=Path, default=None,
                        help="write results.json and specimen.png there")
    args = parser.parse_args(argv)
    for seed in SEEDS:
        for variant in VARIANTS:
            run(args.out, seed, variant)
    results = measure(args.out)
    (args.out / "specimen.json").write_text(json.dumps(results, indent=2) + "\n")
    figure(args.out, args.out / "specimen.png")
    if args.publish is not None:
        figure(args.out, args.publish / "specimen.png")
    print(json.dumps(results, indent=2))
    return results


if __name__ == "__main__":
    main()
