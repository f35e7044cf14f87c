"""The ``single-element`` and ``biaxial`` commands (registered through entry points)."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.fem.localization import mohr_coulomb_inclination, shear_band
from granular_material.fem.material import Material, create_material
from granular_material.fem.newton import NewtonSettings
from granular_material.fem.output import write_outputs
from granular_material.fem.problems import BiaxialSetup
from granular_material.fem.runner import BiaxialResult, run_biaxial

__all__ = ["register", "run_biaxial_command", "run_single_element"]

#: reduced CPU scale of the biaxial specimen: elements (nx, ny) and discs per RVE; 5 × 10 is
#: the coarsest mesh on which a band showed (50 steps to 10 %: about 23 min on 2 CPU cores)
REDUCED_SCALE = ((5, 10), 64)
#: full scale (Wu et al. 2025): 10 × 15 Q4 elements, 600 Gauss points, 400-disc RVEs
FULL_SCALE = ((10, 15), 400)


def _newton_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("Newton solver")
    g.add_argument("--rtol", type=float, default=0.005,
                   help="relative residual tolerance ||R||/||R0|| (default 0.005, Wu et al.)")
    g.add_argument("--stress-tol", type=float, default=None,
                   help="absolute tolerance as a stress error [Pa] at the Gauss points, for "
                        "DEM noise (default 0.005 x confining for dem, 0 for linear-elastic)")
    g.add_argument("--stall-rtol", type=float, default=None,
                   help="accept an iterate with ||R||/||R0|| below this once the residual has "
                        "stopped falling for 8 iterations (DEM stress noise; default 2 x rtol "
                        "for dem, off for linear-elastic; 0: off)")
    g.add_argument("--max-iterations", type=int, default=25,
                   help="iterations per increment before it is halved (default 25)")
    g.add_argument("--max-cutbacks", type=int, default=6,
                   help="how often an increment may be halved (default 6)")
    g.add_argument("--predictor", choices=("tangent", "extrapolate"), default="extrapolate",
                   help="first guess of a step: committed-tangent solve or the last increment "
                        "scaled (default extrapolate)")
    g.add_argument("--tangent", choices=("kruyt-rothenburg", "perturbation"),
                   default="kruyt-rothenburg",
                   help="dem: tangent of the RVEs: Kruyt-Rothenburg (Wu et al. eq. 6, default) "
                        "or forward differences of each RVE's response (4 more DEM runs per "
                        "iteration)")
    g.add_argument("--perturbation", type=float, default=0.1,
                   help="dem, --tangent perturbation: perturbation of grad u relative to its "
                        "largest component (default 0.1)")
    g.add_argument("--relaxation", choices=("none", "aitken"), default="aitken",
                   help="relaxation of Newton corrections (default aitken: the DEM tangent "
                        "leaves out the discs' rearrangement and is too stiff)")
    g.add_argument("--tangent-update", choices=("none", "secant"), default="none",
                   help="none: the material's tangent at every iterate (default); secant: "
                        "each point's tangent corrected by Broyden updates from the stress "
                        "change its RVE gave (use with --relaxation none)")
    g.add_argument("--secant-min-change", type=float, default=1e-4,
                   help="--tangent-update secant: smallest change of a point's grad u that "
                        "updates its tangent (default 1e-4; smaller changes carry DEM noise)")


def _common_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--axial-strain", type=float, default=0.1,
                        help="final axial strain, compression positive (default 0.1)")
    parser.add_argument("--confining", type=float, default=100e3,
                        help="lateral confining pressure [Pa], compression positive "
                             "(default 100e3)")
    parser.add_argument("--steps", type=int, default=100, help="load steps (default 100)")
    parser.add_argument("--out", type=Path, default=None,
                        help="output folder: steps.csv, points.csv, fields.xdmf, figures")
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    parser.add_argument("--device", choices=("cpu", "cuda"), default=None,
                        help="DEM device (default: CUDA when present, else CPU)")
    parser.add_argument("--shards", type=int, default=None,
                        help="CPU threads (shards) of the DEM batch (default: one per core)")
    parser.add_argument("--map-strain", type=float, nargs="+", default=[0.02],
                        help="axial strain(s) of the displacement/shear-strain maps and of the "
                             "shear-band measures (default 0.02)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``single-element`` and ``biaxial`` commands."""
    p = subparsers.add_parser(
        "single-element",
        help="one Q4 element (4 Gauss points) in a drained biaxial test",
        description="One Q4 element with 2x2 Gauss points: sides under the confining "
                    "traction, bottom on rollers with one node pinned, top compressed by a "
                    "prescribed displacement. Stresses tension positive in tables; plots "
                    "compression positive.",
    )
    p.add_argument("--material", choices=("dem", "linear-elastic"), default="dem",
                   help="material at the Gauss points (default dem)")
    p.add_argument("--E", type=float, default=60e6, help="linear-elastic: Young's modulus [Pa]")
    p.add_argument("--nu", type=float, default=0.3, help="linear-elastic: Poisson's ratio")
    p.add_argument("--rve", type=Path, default=None,
                   help="dem: RVE file (one RVE, replicated to the 4 points, or four)")
    p.add_argument("--particles", type=int, default=400,
                   help="dem: discs per prepared RVE (default 400)")
    p.add_argument("--seed", type=int, default=1, help="dem: seed of the prepared RVE")
    p.add_argument("--independent", action="store_true",
                   help="dem: four independent RVEs (seeds seed..seed+3) instead of one "
                        "replicated")
    p.add_argument("--compare-dem", action="store_true",
                   help="dem: also run the pure-DEM drained biaxial of the same RVE")
    _common_arguments(p)
    _newton_arguments(p)
    p.set_defaults(func=run_single_element)

    b = subparsers.add_parser(
        "biaxial",
        help="biaxial specimen (50 mm x 100 mm) of DEM Gauss points",
        description="Drained biaxial test of a plane-strain specimen (smooth or rough "
                    "platens), one independently prepared DEM RVE per Gauss point (seed, "
                    "seed+1, ...). "
                    "--scale full is Wu et al.'s 10x15 elements with 400-disc RVEs; "
                    "--scale reduced (5x10 elements, 64 discs) runs on a CPU.",
    )
    b.add_argument("--scale", choices=("full", "reduced"), default=None,
                   help="preset mesh and RVE size (default: full on CUDA, reduced on CPU)")
    b.add_argument("--elements", type=int, nargs=2, metavar=("NX", "NY"), default=None,
                   help="elements across the width and along the height (overrides --scale)")
    b.add_argument("--particles", type=int, default=None,
                   help="discs per RVE (overrides --scale)")
    b.add_argument("--seed", type=int, default=1, help="seed of the first RVE")
    b.add_argument("--rve", type=Path, default=None,
                   help="RVE file with one RVE per Gauss point (or one, replicated)")
    b.add_argument("--width", type=float, default=0.05, help="specimen width [m]")
    b.add_argument("--height", type=float, default=0.10, help="specimen height [m]")
    b.add_argument("--platens", choices=("smooth", "rough"), default="smooth",
                   help="smooth: platen nodes slide freely, one bottom node pinned (default); "
                        "rough: no platen node moves sideways")
    _common_arguments(b)
    _newton_arguments(b)
    b.set_defaults(func=run_biaxial_command)


def _settings(args: argparse.Namespace) -> NewtonSettings:
    stall = args.stall_rtol
    if stall is None:
        stall = 0.0 if getattr(args, "material", "dem") == "linear-elastic" else 2 * args.rtol
    return NewtonSettings(rtol=args.rtol, stall_rtol=stall, max_iterations=args.max_iterations,
                          max_cutbacks=args.max_cutbacks, predictor=args.predictor,
                          relaxation=args.relaxation, tangent_update=args.tangent_update,
                          secant_min_change=args.secant_min_change)


def _stress_tol(args: argparse.Namespace) -> float:
    if args.stress_tol is not None:
        return args.stress_tol
    # Wu et al.'s 0.005, taken of the confining stress: the floor below which DEM stress
    # noise stalls Newton once a step's own load is small
    return 0.0 if getattr(args, "material", "dem") == "linear-elastic" else 5e-3 * args.confining


def _check(args: argparse.Namespace) -> None:
    if args.steps < 1:
        raise ValueError(f"--steps must be >= 1, got {args.steps}")
    if args.out is not None and args.out.exists() and not args.out.is_dir():
        raise ValueError(f"--out {args.out} exists and is not a folder")
    if args.rve is not None and not args.rve.exists():
        raise FileNotFoundError(f"--rve {args.rve} does not exist")


def _summary(result: BiaxialResult, wall: float) -> dict[str, Any]:
    steps = result.steps
    ratio = steps["stress_ratio"].to_numpy()
    peak = int(np.nanargmax(ratio))
    done = steps[steps["step"] > 0]
    return {
        "peak_stress_ratio": float(ratio[peak]),
        "axial_strain_at_peak": float(steps["axial_strain"].iloc[peak]),
        "newton_iterations_mean": float(done["iterations"].mean()) if len(done) else math.nan,
        "sxx": float(steps["sxx"].iloc[-1]),
        "syy": float(steps["syy"].iloc[-1]),
        "final_axial_strain": float(steps["axial_strain"].iloc[-1]),
        "steps_completed": len(done),
        "cutbacks": int(done["cutbacks"].sum()),
        "stalled_increments": int(done["stalled"].sum()),
        "dem_steps": int(done["work"].sum()),
        "wall_time_s": wall,
        "error": result.error,
    }


def _band_summary(result: BiaxialResult, map_strains: list[float],
                  peak_ratio: float) -> dict[str, Any]:
    """Shear-band measures at the map strains and at the last step (fem.localization)."""
    steps = result.steps
    if len(steps) < 2:
        return {}
    rows = sorted({result.row_nearest(e) for e in map_strains})
    return {
        "shear_bands": [shear_band(result.points, int(steps["step"].iloc[r])).as_dict()
                        for r in rows],
        "shear_band_final": shear_band(result.points).as_dict(),
        "mohr_coulomb_inclination_deg": mohr_coulomb_inclination(max(peak_ratio, 1.0)),
    }


def _report(args: argparse.Namespace, summary: dict[str, Any]) -> int:
    if args.json:
        print(json.dumps(summary, indent=2, default=str))
    else:
        for key, value in summary.items():
            print(f"{key:>24}: {value}")
    if summary["error"]:
        print(f"error: {summary['error']}", file=sys.stderr)
        return 1
    return 0


def run_single_element(args: argparse.Namespace) -> int:
    """The ``single-element`` command; returns the exit code."""
    _check(args)
    setup = BiaxialSetup(width=1.0, height=1.0, nx=1, ny=1, confining=args.confining,
                         axial_strain=args.axial_strain)
    progress = not args.no_progress
    material: Material
    if args.material == "linear-elastic":
        material = create_material("linear-elastic", young=args.E, poisson=args.nu,
                                   initial_stress=-args.confining)
    else:
        material = create_material("dem", rve=args.rve, particles=args.particles,
                                   seed=args.seed, pressure=args.confining,
                                   replicate=not args.independent, device=args.device,
                                   shards=args.shards, progress=progress,
                                   tangent=args.tangent, perturbation=args.perturbation)
        material.allocate(setup.n_points)
    reference = None
    if args.material == "dem" and args.compare_dem:
        reference = _pure_dem(material, args, progress)
    t0 = time.perf_counter()
    result = run_biaxial(setup, material, args.steps, _settings(args), progress=progress,
                         out_dir=args.out, stress_tol=_stress_tol(args))
    summary = _summary(result, time.perf_counter() - t0)
    if reference is not None:
        peak = int(reference["stress_ratio"].idxmax())
        summary["dem_peak_stress_ratio"] = float(reference["stress_ratio"][peak])
        summary["dem_axial_strain_at_peak"] = float(reference["axial_strain"][peak])
    if args.out is not None:
        write_outputs(result, args.out, map_strain=args.map_strain, reference=reference)
        if reference is not None:
            reference.to_csv(Path(args.out) / "pure_dem.csv", index=False)
        summary["out"] = str(args.out)
    return _report(args, summary)


def _pure_dem(material: Material, args: argparse.Namespace, progress: bool) -> pd.DataFrame:
    """Drained biaxial test of RVE 0 of the DEM material (its committed state)."""
    from granular_material.dem import DEMBatch
    from granular_material.procedures import biaxial_test

    batch = DEMBatch(material.batch.to_data().replicate(1), device=args.device, shards=1)
    curve = biaxial_test(batch, axial_strain=args.axial_strain, confining=args.confining,
                         progress=progress)
    return curve[curve["rve"] == 0].reset_index(drop=True)


def run_biaxial_command(args: argparse.Namespace) -> int:
    """The ``biaxial`` command; returns the exit code."""
    _check(args)
    from granular_material.dem.model import resolve_device

    device = resolve_device(args.device)
    scale = args.scale or ("full" if device.startswith("cuda") else "reduced")
    (nx, ny), particles = FULL_SCALE if scale == "full" else REDUCED_SCALE
    if args.elements is not None:
        nx, ny = args.elements
    particles = args.particles or particles
    setup = BiaxialSetup(width=args.width, height=args.height, nx=nx, ny=ny,
                         confining=args.confining, axial_strain=args.axial_strain,
                         platens=args.platens)
    progress = not args.no_progress
    material = create_material("dem", rve=args.rve, particles=particles, seed=args.seed,
                               pressure=args.confining, device=device, shards=args.shards,
                               progress=progress, tangent=args.tangent,
                               perturbation=args.perturbation)
    material.allocate(setup.n_points)
    t0 = time.perf_counter()
    result = run_biaxial(setup, material, args.steps, _settings(args), progress=progress,
                         out_dir=args.out, stress_tol=_stress_tol(args))
    summary = _summary(result, time.perf_counter() - t0)
    summary.update(scale=scale, elements=[nx, ny], gauss_points=setup.n_points,
                   particles=particles, device=device)
    summary.update(_band_summary(result, args.map_strain, summary["peak_stress_ratio"]))
    if args.out is not None:
        write_outputs(result, args.out, map_strain=args.map_strain)
        summary["out"] = str(args.out)
    return _report(args, summary)
