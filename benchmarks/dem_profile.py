"""Where a particle-step goes: each kernel of the step timed on its own, on one thread.

Usage::

    python benchmarks/dem_profile.py [--batches 1,16,64] [--particles 400] [--steps 400]
        [--dtype float64] [--damping 0] [--ghz GHZ] [--repeats 3] [--out profile.csv]

The benchmark's packing (seed 1, 100 kPa, undamped by default as ``dem_throughput.py``),
replicated B times into one shard on one CPU thread and sheared at 1e-5 a step, is warmed
up; then ``--steps`` steps are launched kernel by kernel (the recorded launches of
``Solver.prepare``, the rebuild where due, exactly what the captured graph replays) with
the thread's CPU clock around each launch (CPU time, not wall time, so that on a shared
machine the time the thread waits for a core is left out; CPU kernels run in the launching
thread), ``--repeats`` times from the same snapshot. The table gives,
per kernel, nanoseconds and cycles (at ``--ghz``, default the clock the kernel reports in
/proc/cpuinfo) per particle-step, and its share; the whole step as the graph replays it is
timed beside (the launches' Python overhead, about a microsecond each, is in the
per-kernel times only). Also the lists: slots a disc, touching pairs a disc, rebuilds per
100 steps. Measures; never passes or fails.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd


def _ghz() -> float:
    """The CPU's clock [GHz] as /proc/cpuinfo reports it (NaN where it does not)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("cpu MHz"):
                return float(line.split(":")[1]) / 1000.0
    except OSError:
        pass
    return float("nan")


def profile(rve: Path, n_rve: int, steps: int, dtype: str, repeats: int) -> dict:
    """Per-kernel seconds of ``steps`` steps of ``n_rve`` copies of ``rve`` on one thread
    (medians over ``repeats``), the graph's seconds for the same steps, list statistics."""
    import warp as wp

    wp.config.quiet = True
    from granular_material.dem import DEMBatch, load_rve
    from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP

    batch = DEMBatch(load_rve(rve).replicate(n_rve), device="cpu", dtype=dtype, shards=1)
    shear = np.zeros((n_rve, 2, 2))
    shear[:, 0, 1] = DEFAULT_STRAIN_PER_STEP / batch.dt
    batch.set_affine(shear)
    batch.run(100)  # warm-up: kernels loaded, lists built, graph captured
    # a thread steps its shards (of at most CPU_SHARD_DISCS discs) one after the other
    shards = [(s, *s.solver.prepare(s.model, s.state, s.loading)) for s in batch.shards]
    start = batch.snapshot()
    names = [r.kernel.key for r in shards[0][3]] + ["rebuild (4 kernels)"]
    seconds: dict[str, list[float]] = {name: [] for name in names}
    graph_s, rebuilds = [], 0
    for _ in range(repeats):
        batch.restore(start)
        spent = dict.fromkeys(names, 0.0)
        rebuilds = 0
        for shard, _check, build, step in shards:
            flags = shard.solver._host_rebuild
            for _ in range(steps):
                if flags[0]:
                    rebuilds += 1
                    t0 = time.thread_time()
                    for recorded in build:
                        recorded.launch()
                    spent[names[-1]] += time.thread_time() - t0
                for name, recorded in zip(names, step, strict=False):
                    t0 = time.thread_time()
                    recorded.launch()
                    spent[name] += time.thread_time() - t0
        for name in names:
            seconds[name].append(spent[name])
        batch.restore(start)
        t0 = time.thread_time()
        batch.run(steps, check_every=steps)
        graph_s.append(time.thread_time() - t0)
    shard = batch.shards[0]
    solver, model, state, loading = shard.solver, shard.model, shard.state, shard.loading
    counts = state.contact_count.numpy()
    touching = float(np.mean(batch.homogenize().coordination))  # contacts a disc: Z
    return {"seconds": {name: float(np.median(v)) for name, v in seconds.items()},
            "graph_s": float(np.median(graph_s)), "rebuilds": rebuilds / len(shards),
            "slots_per_disc": float(counts.mean()), "touching_per_disc": float(touching),
            "features": solver.step_features(model, loading).tag}


def main(argv: list[str] | None = None) -> pd.DataFrame:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batches", default="1,16,64")
    parser.add_argument("--particles", type=int, default=400)
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--dtype", default="float64")
    parser.add_argument("--damping", type=float, default=0.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--ghz", type=float, default=None)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    import warp as wp

    wp.config.quiet = True
    from granular_material.dem import save_rve
    from granular_material.procedures import prepare_packing

    ghz = args.ghz or _ghz()
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        rve = Path(scratch) / "rve.npz"
        data = prepare_packing(n_disc=args.particles, seed=1, device="cpu").to_data().select(0)
        save_rve(rve, replace(data, meta=replace(data.meta, damping=args.damping)))
        for n_rve in (int(b) for b in args.batches.split(",")):
            result = profile(rve, n_rve, args.steps, args.dtype, args.repeats)
            work = n_rve * args.particles * args.steps  # particle-steps
            total = sum(result["seconds"].values())
            for name, s in [*result["seconds"].items(), ("sum of kernels", total),
                            ("graph replay (whole step)", result["graph_s"])]:
                rows.append({"batch": n_rve, "dtype": args.dtype,
                             "features": result["features"], "kernel": name,
                             "ns_per_particle_step": 1e9 * s / work,
                             "cycles_per_particle_step": 1e9 * s / work * ghz,
                             "share_of_kernels": s / total,
                             "slots_per_disc": result["slots_per_disc"],
                             "touching_per_disc": result["touching_per_disc"],
                             "rebuilds_per_100_steps": 100 * result["rebuilds"] / args.steps})
            print(f"B={n_rve} done", file=sys.stderr, flush=True)
    table = pd.DataFrame(rows)
    print(f"one thread, {args.dtype}, damping {args.damping:g}, cycles at {ghz:.2f} GHz")
    print(table.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        table.to_csv(args.out, index=False)
    return table


if __name__ == "__main__":
    main()
