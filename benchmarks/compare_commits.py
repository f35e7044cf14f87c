"""Two or more commits of the DEM engine timed against each other in one run, by CPU time.

Usage::

    python benchmarks/compare_commits.py REV [REV ...] [--batches 1,16,64,256]
        [--particles 400] [--steps 2000] [--dtype float64] [--damping 0]
        [--repeats 5] [--out compare.csv]

Each REV is a git revision of this repository (checked out into a temporary worktree) or
``.``, this working tree. The benchmark's packing (seed 1, 100 kPa, undamped by default, as
``dem_throughput.py``) is prepared once, replicated B times into one shard on one thread and
sheared at 1e-5 a step; every case runs in a fresh process per revision, the revisions
taking turns ``--repeats`` times so that a drifting load hits them alike. Each run is
timed by the thread's CPU clock (``time.thread_time``, so that on a shared machine the time
spent waiting for a core is left out: CPU kernels run in the launching thread) and by the
wall clock. The table gives per case and revision the median rate [particle-steps/s] by CPU
time and its spread, and the ratio to the first revision: the median of the repeats' ratios
(each repeat's runs taken in turn) with their smallest and largest. Measures; never passes
or fails.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]


def measure(rve: Path, n_rve: int, steps: int, dtype: str) -> dict:
    """CPU and wall seconds of ``steps`` steps of ``n_rve`` copies of ``rve`` on one thread
    (after a warm-up), with whichever engine this process imports."""
    import warp as wp

    wp.config.quiet = True
    from granular_material.dem import DEMBatch, load_rve

    batch = DEMBatch(load_rve(rve).replicate(n_rve), device="cpu", dtype=dtype, shards=1)
    shear = np.zeros((batch.n_rve, 2, 2))
    shear[:, 0, 1] = 1e-5 / batch.dt  # 1e-5 strain a step
    batch.set_affine(shear)
    batch.run(100)  # warm-up: kernels loaded, lists built, graph captured
    cpu0, wall0 = time.thread_time(), time.perf_counter()
    batch.run(steps, check_every=steps)
    cpu, wall = time.thread_time() - cpu0, time.perf_counter() - wall0
    work = n_rve * batch.n_disc * steps
    return {"cpu_s": cpu, "wall_s": wall, "rate_cpu": work / cpu, "rate_wall": work / wall}


def _run(source: Path, rve: Path, n_rve: int, steps: int, dtype: str) -> dict:
    """One measurement in a fresh process importing the engine found at ``source``."""
    command = [sys.executable, str(Path(__file__).resolve()), "--worker", str(n_rve),
               "--rve", str(rve), "--steps", str(steps), "--dtype", dtype]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(source), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run(command, capture_output=True, text=True, env=env, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"worker for B={n_rve} ({source}) failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _label(rev: str) -> str:
    """A revision's short commit (``.``: HEAD's, with ``+dirty`` where the tree differs)."""
    from granular_material.provenance import code_commit

    return code_commit() if rev == "." else code_commit(rev).removesuffix("+dirty")


def _spread(values: list[float]) -> float:
    """(max − min)/median [-]."""
    v = np.asarray(values)
    return float((v.max() - v.min()) / np.median(v))


def main(argv: list[str] | None = None) -> pd.DataFrame | None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("revs", nargs="*", help="git revisions, or . for this working tree")
    parser.add_argument("--batches", default="1,16,64,256")
    parser.add_argument("--particles", type=int, default=400)
    parser.add_argument("--steps", type=int, default=2000, help="timed steps at B = 1 "
                        "(fewer at larger B: the same particle-steps, at least 100)")
    parser.add_argument("--dtype", default="float64")
    parser.add_argument("--damping", type=float, default=0.0)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--rve", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker is not None:
        print(json.dumps(measure(args.rve, args.worker, args.steps, args.dtype)))
        return None
    if len(args.revs) < 2:
        parser.error("give at least two revisions (. is this working tree)")
    import warp as wp

    wp.config.quiet = True
    from granular_material.dem import save_rve
    from granular_material.procedures import prepare_packing

    labels = [_label(rev) for rev in args.revs]
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        rve = scratch / "rve.npz"
        data = prepare_packing(n_disc=args.particles, seed=1, device="cpu").to_data().select(0)
        save_rve(rve, replace(data, meta=replace(data.meta, damping=args.damping)))
        sources = []
        for index, rev in enumerate(args.revs):
            if rev == ".":
                sources.append(REPO)
                continue
            path = scratch / f"rev{index}"
            subprocess.run(["git", "worktree", "add", "--detach", "-q", str(path), rev],
                           cwd=REPO, check=True)
            sources.append(path)
        try:
            for n_rve in (int(b) for b in args.batches.split(",")):
                steps = max(100, args.steps // n_rve)
                runs: list[list[dict]] = [[] for _ in sources]
                for _ in range(args.repeats):  # the revisions take turns
                    for index, source in enumerate(sources):
                        runs[index].append(_run(source, rve, n_rve, steps, args.dtype))
                first = np.array([r["rate_cpu"] for r in runs[0]])
                for label, rev, result in zip(labels, args.revs, runs, strict=True):
                    rates = np.array([r["rate_cpu"] for r in result])
                    ratios = rates / first
                    rows.append({
                        "batch": n_rve, "dtype": args.dtype, "rev": rev, "commit": label,
                        "steps": steps, "repeats": args.repeats,
                        "rate_cpu": float(np.median(rates)), "spread": _spread(list(rates)),
                        "rate_wall": float(np.median([r["rate_wall"] for r in result])),
                        "ratio": float(np.median(ratios)), "ratio_min": float(ratios.min()),
                        "ratio_max": float(ratios.max()),
                    })
                print(f"B={n_rve} done", file=sys.stderr, flush=True)
        finally:
            for rev, source in zip(args.revs, sources, strict=True):
                if rev != ".":
                    subprocess.run(["git", "worktree", "remove", "--force", str(source)],
                                   cwd=REPO, check=False)
    table = pd.DataFrame(rows)
    print(f"one thread, {args.dtype}, damping {args.damping:g}; rates by CPU time, ratios "
          f"to {labels[0]} (median of the repeats, with their extremes)")
    print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        table.to_csv(args.out, index=False)
    return table


if __name__ == "__main__":
    main()
