"""DEM throughput: particle-steps per second for batches of RVEs, and YADE's in the same run.

Usage::

    python benchmarks/dem_throughput.py [--device cpu|cuda] [--batches 1,16,64,256,600]
        [--particles 400] [--seconds 2] [--out results.csv] [--no-yade]

One 400-disc packing is prepared (seed 1, 100 kPa) and replicated B times; each batch is
sheared at 1e-5 strain a step (so neighbour lists are rebuilt as in real runs) and timed after
a warm-up. When Debian's ``yade`` is installed, the same packing is stepped in YADE on one core
and every rate is also printed as a ratio to YADE's. Measures; never passes or fails.
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from granular_material.cli import quiet_warp
from granular_material.dem import DEMBatch, save_rve
from granular_material.procedures import prepare_packing


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True, cwd=Path(__file__).parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _yade_rate(rve_path: Path, steps: int) -> float | None:
    try:
        from granular_material_validation.yade_runner import yade_throughput
    except ImportError:
        return None
    try:
        return yade_throughput(rve_path, steps)
    except (RuntimeError, OSError, ValueError) as exc:
        print(f"YADE throughput not measured: {exc}", file=sys.stderr)
        return None


def measure(batch: DEMBatch, seconds: float) -> tuple[int, float]:
    """Steps run and wall time [s] of about ``seconds`` of shearing (after a warm-up)."""
    shear = np.zeros((batch.n_rve, 2, 2))
    shear[:, 0, 1] = 1e-5 / batch.dt  # 1e-5 strain a step
    batch.set_affine(shear)
    batch.run(20)  # warm-up: kernels loaded, lists built
    t0 = time.perf_counter()
    batch.run(20)
    per_step = (time.perf_counter() - t0) / 20
    steps = max(20, int(seconds / per_step))
    t0 = time.perf_counter()
    batch.run(steps, check_every=min(steps, 500))
    return steps, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> pd.DataFrame:
    """Run the benchmark; prints and returns the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default=None, help="cpu or cuda (default: CUDA if present)")
    parser.add_argument("--batches", default="1,16,64,256,600",
                        help="comma-separated batch sizes B")
    parser.add_argument("--particles", type=int, default=400, help="discs per RVE")
    parser.add_argument("--seconds", type=float, default=2.0, help="timed seconds per case")
    parser.add_argument("--dtype", default="float64", choices=["float64", "float32"])
    parser.add_argument("--shards", type=int, default=None,
                        help="CPU shards (threads); default: one per core")
    parser.add_argument("--yade-steps", type=int, default=2000, help="steps YADE is timed on")
    parser.add_argument("--no-yade", action="store_true", help="skip the YADE measurement")
    parser.add_argument("--out", type=Path, default=None, help="CSV of the table")
    args = parser.parse_args(argv)
    quiet_warp()

    base = prepare_packing(n_disc=args.particles, seed=1, device=args.device)
    one = base.to_data()
    rve_path = Path(args.out.parent if args.out else ".") / "benchmark_rve.npz"
    save_rve(rve_path, one.select(0))
    yade = None if args.no_yade else _yade_rate(rve_path, args.yade_steps)

    rows = []
    for b in (int(x) for x in args.batches.split(",")):
        batch = DEMBatch(one.replicate(b), device=args.device, dtype=args.dtype,
                         shards=args.shards)
        steps, wall = measure(batch, args.seconds)
        rate = b * args.particles * steps / wall
        rows.append({"device": batch.device, "dtype": args.dtype,
                     "shards": len(batch.shards), "batch": b,
                     "particles": b * args.particles, "steps": steps, "wall_s": wall,
                     "particle_steps_per_s": rate,
                     "ratio_to_yade": rate / yade if yade else math.nan})
        print(f"B={b:4d}  {rate:.3e} particle-steps/s", file=sys.stderr, flush=True)
    table = pd.DataFrame(rows)
    print(f"commit {_commit()}; one YADE core: "
          + (f"{yade:.3e} particle-steps/s" if yade else "not measured"))
    print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    if args.out:
        table.to_csv(args.out, index=False)
    return table


if __name__ == "__main__":
    main()
