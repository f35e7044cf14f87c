"""The ``reproduce`` command: ``granular-material reproduce wu2025 --scale smoke|cpu|paper
--out DIR``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from granular_material.cli.options import (
    add_device,
    add_json,
    add_progress,
    check_output_dir,
    emit,
    interrupt_exit_code,
    progress_enabled,
)

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
    emit(args, {"scale": args.scale, "device": device,
                "verdicts": {f"Fig. {row.figure}": row.verdict for row in table.itertuples()},
                "wall_time_s": time.perf_counter() - started,
                "report": str(Path(args.out) / "report.md")})
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
                        "of 100-disc RVEs to 5 %%; about an hour); paper: Wu et al.'s sizes, "
                        "for a GPU (default cpu)")
    p.add_argument("--out", type=Path, default=Path("reproduction"),
                   help="output folder (default ./reproduction)")
    p.add_argument("--redo", nargs="+", default=[], choices=tuple(PARTS), metavar="PART",
                   help=f"run these parts again: {', '.join(PARTS)}")
    add_device(p, "DEM device")
    add_progress(p)
    add_json(p, "the verdicts")
    p.set_defaults(func=run)
