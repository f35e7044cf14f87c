"""The ``trade-study`` command: the speed/accuracy trade study
(:mod:`granular_material.studies.trade`)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from granular_material.cli.options import (
    add_device,
    add_json,
    add_progress,
    check_output_dir,
    emit,
    positive_int,
    progress_enabled,
)


def run_trade_study_command(args: argparse.Namespace) -> int:
    """Run (or finish) the study; report where it is and the recommended settings."""
    from granular_material.dem import resolve_device
    from granular_material.studies import run_trade_study
    from granular_material.studies.trade import accuracy

    check_output_dir(args.out)
    device = resolve_device(args.device)
    started = time.perf_counter()
    table = run_trade_study(args.scale, args.out, device=device,
                            progress=progress_enabled(args),
                            log=lambda line: print(line, file=sys.stderr), jobs=args.jobs)
    presets = table[table["knob"] == "preset"].assign(accuracy=accuracy)
    report: dict[str, Any] = {
        "scale": args.scale, "device": device, "rows": len(table),
        "failed_runs": int((table["error"] != "").sum()),
        "presets": {name: {f"{row.test}_accuracy_pct": float(row.accuracy)
                           for row in group.itertuples()}
                    | {f"{row.test}_wall_s": float(row.wall_s) for row in group.itertuples()}
                    for name, group in presets.groupby("value", sort=False)},
        "wall_time_s": time.perf_counter() - started,
        "out": str(args.out), "report": str(Path(args.out) / "report.md"),
    }
    emit(args, report)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``trade-study`` command."""
    p = subparsers.add_parser(
        "trade-study", help="speed against accuracy: every knob against a reference run",
        description="Each knob (discs per RVE, strain per DEM step, time-step safety, "
                    "damping, float32, Newton tolerance and stress floor, tangent, predictor "
                    "and relaxation, reuse of undisturbed RVEs, mesh) varied alone against a "
                    "high-fidelity reference from the same RVEs, and the band rows: the "
                    "reduced specimen past its peak (the shear band's onset and place, "
                    "softening, dilatancy) against the commands' defaults, and the footing "
                    "rows: Guo & Zhao's reduced footing (bearing pressure, mechanism) beside "
                    "its Mohr-Coulomb twin; writes trade.csv, band.csv, footing.csv, Pareto "
                    "figures, a figure per knob, presets.json and report.md "
                    "with three recommended settings, measured. A restarted study skips the "
                    "runs it has done.",
    )
    p.add_argument("--scale", choices=("smoke", "cpu", "gpu"), default="cpu",
                   help="smoke: a few minutes, checks the machinery; cpu: the study for 2 CPU "
                        "cores (about 2 h of runs here with --jobs 2, the band and footing "
                        "rows most of it); gpu: 5 seeds, 400-disc elements, the "
                        "10 x 15 mesh (default cpu)")
    p.add_argument("--out", type=Path, default=Path("out/trade-study"),
                   help="output folder (default out/trade-study); an existing one is "
                        "continued")
    p.add_argument("--jobs", type=positive_int, default=1,
                   help="band rows run at once, each in its own process (default 1)")
    add_device(p)
    add_progress(p)
    add_json(p)
    p.set_defaults(func=run_trade_study_command)
