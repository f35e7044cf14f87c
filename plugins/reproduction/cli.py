"""The ``reproduce`` command: ``granular-material reproduce wu2025 --scale smoke|cpu|paper
--out DIR``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from granular_material.cli.options import (
    UsageError,
    add_device,
    add_json,
    add_progress,
    check_output_dir,
    emit,
    positive,
    positive_int,
    progress_enabled,
)
from granular_material.cli.signals import interrupt_exit_code
from granular_material.results import write_json

from .scales import SCALES
from .study import PARTS

#: the studies this command reproduces
STUDIES = ("wu2025",)


def run(args: argparse.Namespace) -> int:
    """Run (or finish) the reproduction; print the headline table's verdicts."""
    from granular_material.dem import resolve_device

    from .report import headline
    from .study import run_reproduction

    check_output_dir(args.out)
    device = resolve_device(args.device)
    started = time.perf_counter()
    try:
        results = run_reproduction(args.scale, args.out, device=device,
                                   progress=progress_enabled(args), redo=tuple(args.redo),
                                   log=lambda line: print(line, file=sys.stderr))
    except KeyboardInterrupt as exc:
        print(f"granular-material reproduce: stopped; the parts done are kept. Continue with "
              f"`granular-material reproduce {args.study} --scale {args.scale} --out "
              f"{args.out}`", file=sys.stderr)
        return interrupt_exit_code(exc)
    table = headline(SCALES[args.scale], results)
    summary = {"scale": args.scale, "device": device,
               "verdicts": {f"Fig. {row.figure}": row.verdict for row in table.itertuples()},
               "wall_time_s": time.perf_counter() - started,
               "report": str(Path(args.out) / "report.md")}
    write_json(summary, Path(args.out) / "summary.json")
    emit(args, summary)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``reproduce`` command."""
    p = subparsers.add_parser(
        "reproduce", help="rerun a paper's study: each claim beside our measurement",
        description="Rerun Wu, Fu & Zhou (2025) (wu2025): RVE size from the pore spectra's "
                    "α0/D0 (Figs. 3–4) and from the stress–strain of RVEs of 10² to 30² "
                    "discs (Fig. 5), the single element (Fig. 6) and the specimen (Figs. "
                    "7–8) against pure DEM, D0 and α0 of three RVEs against their volumetric "
                    "strain (Figs. 9–10), the speed-up of the batched DEM (Fig. 11). Writes "
                    "report.md with a headline table (claim, ours, verdict), the tables and "
                    "figures of each part under OUT/<part>/. A rerun skips the parts done "
                    "and continues an interrupted one.",
    )
    p.add_argument("study", choices=STUDIES, help="the paper: wu2025")
    p.add_argument("--scale", choices=tuple(SCALES), default="cpu",
                   help="smoke: every part at a toy size (about a minute); cpu: the whole "
                        "study reduced for a 2-core workstation (specimen 5 × 10 elements "
                        "of 100-disc RVEs to 5 %%; 17 to 35 min on 2 cores); paper: Wu et "
                        "al.'s sizes, for a GPU (default cpu)")
    p.add_argument("--out", type=Path, default=Path("reproduction"),
                   help="output folder (default ./reproduction)")
    p.add_argument("--redo", nargs="+", default=[], choices=tuple(PARTS), metavar="PART",
                   help=f"run these parts again ({', '.join(PARTS)}), from their cached "
                        "packings, curves and FEM runs; speedup is timed again")
    add_device(p, "DEM device")
    add_progress(p)
    add_json(p, "the verdicts")
    p.set_defaults(func=run)


def run_size_study(args: argparse.Namespace) -> int:
    """The RVE-size study alone (Figs. 3–5 of the reproduction) at the sizes given."""
    from dataclasses import replace

    from granular_material.dem import resolve_device

    from .report import headline
    from .study import run_reproduction

    check_output_dir(args.out)
    if len(args.seeds) < 2 or sorted(set(args.seeds)) != list(
            range(min(args.seeds), min(args.seeds) + len(args.seeds))):
        raise UsageError(f"--seeds must be two or more consecutive seeds, got {args.seeds}")
    biaxial = tuple(args.biaxial_discs or args.discs)
    missing = set(biaxial) - set(args.discs)
    if missing:
        raise UsageError(f"--biaxial-discs {sorted(missing)} are not among --discs")
    if len(set(args.discs)) < 2:
        raise UsageError("--discs needs at least two sizes")
    device = resolve_device(args.device)
    sizes = tuple(sorted(set(args.discs)))
    scale = replace(SCALES["cpu"], name="rve-size-study", sizes=sizes,
                    resolution_discs=min(sizes, key=lambda n: (abs(n - 400), n)),
                    seeds=tuple(sorted(args.seeds)), biaxial_sizes=tuple(sorted(set(biaxial))),
                    dem_axial_strain=args.axial_strain,
                    dem_strain_per_step=args.strain_per_step,
                    void_ratio=args.target_void_ratio, pressure=args.pressure,
                    element_discs=min(args.discs), speedup_sizes=(min(args.discs),))
    started = time.perf_counter()
    try:
        results = run_reproduction(scale, args.out, device=device,
                                   progress=progress_enabled(args),
                                   log=lambda line: print(line, file=sys.stderr),
                                   parts=("rve-size", "size-biaxial"))
    except KeyboardInterrupt as exc:
        print("granular-material rve-size-study: stopped; what is done is kept: run the same "
              "command again to continue", file=sys.stderr)
        return interrupt_exit_code(exc)
    settle = results["rve-size"]["settle"]
    summary = {"settle_discs": settle["settle_discs"],
               **{k: v for k, v in settle.items() if k.startswith("within_")},
               "verdicts": {f"Fig. {row.figure}": row.verdict
                            for row in headline(scale, results).itertuples()},
               "wall_time_s": time.perf_counter() - started,
               "report": str(Path(args.out) / "report.md")}
    write_json(summary, Path(args.out) / "summary.json")
    emit(args, summary)
    return 0


def register_size_study(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``rve-size-study`` command."""
    p = subparsers.add_parser(
        "rve-size-study", help="how many discs an RVE needs: pore spectra and biaxial tests "
                               "by size",
        description="RVEs of each size in --discs × --seeds, compacted to "
                    "--target-void-ratio and consolidated at --pressure (the material of Wu "
                    "et al.'s Table 1); the multifractal spectrum of each one's pore space "
                    "and α0/D0 against size, with the size from which it settles; the drained "
                    "biaxial test of each RVE of --biaxial-discs. Writes report.md and the "
                    "tables and figures under OUT/rve-size and OUT/size-biaxial (the first "
                    "two parts of `reproduce wu2025`). A rerun continues where it stopped.",
    )
    cpu = SCALES["cpu"]  # the study is the cpu scale's, at the sizes given
    p.add_argument("--discs", type=positive_int, nargs="+", default=list(cpu.sizes),
                   help="RVE sizes [discs] (default 10², 12², …, 30²)")
    p.add_argument("--seeds", type=int, nargs="+", default=list(cpu.seeds),
                   help="consecutive seeds, one packing each per size (default "
                        f"{' '.join(map(str, cpu.seeds))})")
    p.add_argument("--biaxial-discs", type=positive_int, nargs="+", default=None,
                   help="sizes whose RVEs get a drained biaxial test (default: every size)")
    p.add_argument("--target-void-ratio", type=positive, default=cpu.void_ratio,
                   help="void ratio the random gas is compacted to (default "
                        f"{cpu.void_ratio:g}, Wu et al.)")
    p.add_argument("--pressure", type=positive, default=cpu.pressure,
                   help=f"consolidation and confining pressure [Pa] (default {cpu.pressure:g})")
    p.add_argument("--axial-strain", type=positive, default=cpu.dem_axial_strain,
                   help="final axial strain of the biaxial tests (default "
                        f"{cpu.dem_axial_strain:g})")
    p.add_argument("--strain-per-step", type=positive, default=cpu.dem_strain_per_step,
                   help="axial strain per DEM step of the biaxial tests (default "
                        f"{cpu.dem_strain_per_step:g})")
    p.add_argument("--out", type=Path, default=Path("rve-size-study"),
                   help="output folder (default ./rve-size-study)")
    add_device(p, "DEM device")
    add_progress(p)
    add_json(p, "the settling sizes and verdicts")
    p.set_defaults(func=run_size_study)
