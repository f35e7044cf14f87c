"""Pieces of ``benchmarks/gpu_check.sh`` that are Python: is a CUDA device there, does a
sheared batch on it agree with the CPU, does the condensed tangent's CG on it agree
with the LU on the host, and how fast are the two step paths (the two-kernel step and the
block path) on it.

Usage::

    python benchmarks/gpu_check.py require-cuda
    python benchmarks/gpu_check.py agreement --out DIR [--device cuda] [--reference cpu]
        [--batch 16] [--particles 400] [--strain 2e-3] [--dtypes float64,float32]
    python benchmarks/gpu_check.py condensed --out DIR [--device cuda] [--batch 8]
        [--particles 400] [--strain 2e-3] [--sliding free|stick]
    python benchmarks/gpu_check.py paths --out DIR [--device cuda]
        [--batches 1,64,1024,4096] [--particles 400] [--dtypes float64,float32]
        [--seconds 0.5]
    python benchmarks/gpu_check.py block-specimen -- BIAXIAL-OPTIONS...

``agreement`` prepares one packing (seed 1, 100 kPa, on the reference device, float64),
gives each of the B copies its own displacement gradient (simple and pure shear,
compression, a rotation among them, |∇u| up to ``--strain``), drives the copies on both
devices from the same file with ``drive_grad_u``, and compares the homogenised measures RVE
by RVE: ``agreement.csv`` (one row per float type and RVE) and ``agreement.json`` (the
largest differences and whether they are within the tolerance of ``tests/test_dem_cuda.py``,
rtol 1e-6 on stress for float64, 1e-3 for float32). The same device on both sides (a CPU
against itself) checks the piece itself: every difference is then zero.
``condensed`` drives B copies of one packing as ``agreement`` does (on the CPU), then
computes their condensed tangents by scipy's LU on the host and by the warp CG on
``--device`` (``granular_material.dem.condensed.cg``): ``condensed.json`` holds the largest
relative difference max|ΔC|/max|C| per RVE (tolerance 1e-8), the CG's iterations, both
paths' seconds (the CG's split into its assembly on the host and its solve, timed after a
first call has compiled the kernels), the same with the systems assembled on ``--device``
from the batch's own arrays (``granular_material.dem.condensed.device``; its difference to
the LU too) and, beside them, 200 DEM steps of the same batch on ``--device``.
``--sliding`` is the contacts at their Coulomb cap (``free``: no tangential stiffness,
``--tangent condensed``; ``stick``: kt, ``--tangent condensed-sticking``).
``paths`` times both step paths of the engine on ``--device``: for each float type and B
it prepares B copies of one packing (as ``agreement``), shears them at 1e-5 a step (as
``dem_throughput.py``), and from one snapshot steps them by the two-kernel step
(``contact_forces`` → ``integrate``, the engine's CUDA path) and by the block path
(``kernels_block``, one thread block an RVE), the same number of steps each (about
``--seconds`` of the two-kernel step), after a warm-up of each: ``paths.csv`` and
``paths.json`` hold the particle-steps/s of each, their ratio, the block path's launch
rounds, and the largest difference of their stresses against the tolerance above. Its
ratios are what ``solver_block.BLOCK_MIN_RVES`` (the engine's rule) waits for.
``block-specimen`` runs ``granular_material.cli`` with the given options in this process,
with the engine's rule set to take the block path for every batch whose discs fit it.
Measures; exit 1 only where an agreement is outside the tolerance.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from granular_material import verbose

#: relative tolerance on stress between devices (same kernels; the compilers' FMA choices)
TOLERANCE = {"float64": 1e-6, "float32": 1e-3}
#: relative tolerance of the CG's condensed tangent against the LU's (its residual is 1e-10)
CONDENSED_TOLERANCE = 1e-8
#: DEM steps timed beside the condensed tangent (about one evaluation's)
DEM_STEPS = 200


def require_cuda() -> str:
    """The name of CUDA device 0; exits 2 with a message where there is none."""
    import warp as wp

    verbose(False)  # warp >= 1.10 ignores config.quiet: its banner went into summary.json
    wp.init()
    if not wp.is_cuda_available():
        print("gpu_check: no CUDA device (warp sees none: no NVIDIA driver or GPU here); "
              "this check needs one. The CPU-only parts are tested by "
              "tests/test_cuda_compile.py and tests/test_gpu_check.py.", file=sys.stderr)
        raise SystemExit(2)
    return wp.get_device("cuda:0").name


def gradients(n_rve: int, strain: float) -> np.ndarray:
    """``n_rve`` displacement gradients (B, 2, 2), all of largest entry ``strain``: simple
    shear, pure shear, axial compression, dilation and a rotation with shear, in turn, their
    signs and sizes varied."""
    shapes = np.array([
        [[0.0, 1.0], [0.0, 0.0]],      # simple shear
        [[1.0, 0.0], [0.0, -1.0]],     # pure shear
        [[0.0, 0.0], [0.0, -1.0]],     # axial compression
        [[-0.5, 0.0], [0.0, -0.5]],    # isotropic compression
        [[0.2, 1.0], [-0.6, -0.4]],    # rotation and shear
    ])
    out = np.empty((n_rve, 2, 2))
    for b in range(n_rve):
        scale = (1.0 if b % 2 == 0 else -0.5) * (1.0 - 0.5 * b / max(n_rve, 1))
        out[b] = strain * scale * shapes[b % len(shapes)]
    return out


def agreement(out: Path, device: str = "cuda", reference: str = "cpu", n_rve: int = 16,
              particles: int = 400, strain: float = 2e-3,
              dtypes: tuple[str, ...] = ("float64", "float32")) -> dict:
    """Compare ``device`` with ``reference`` on a sheared batch; writes ``agreement.csv``
    and ``agreement.json`` under ``out`` and returns the summary."""
    verbose(False)
    from granular_material.dem import DEMBatch, load_rve, save_rve
    from granular_material.procedures import drive_grad_u, prepare_packing
    from granular_material.procedures.packing import DEFAULT_PRESSURE
    from granular_material.results import write_csv, write_json

    out.mkdir(parents=True, exist_ok=True)
    grad = gradients(n_rve, strain)
    rows, summary = [], {"device": device, "reference": reference, "n_rve": n_rve,
                         "particles": particles, "strain": strain, "dtypes": {}}
    with tempfile.TemporaryDirectory() as scratch:
        path = Path(scratch) / "rve.npz"
        save_rve(path, prepare_packing(n_disc=particles, seed=1, pressure=DEFAULT_PRESSURE,
                                       device=reference).to_data().select(0))
        data = load_rve(path).replicate(n_rve)
        for dtype in dtypes:
            measures, seconds = {}, {}
            for name in (reference, device) if device != reference else (reference, "again"):
                batch = DEMBatch(data, device=reference if name == "again" else name,
                                 dtype=dtype)
                t0 = time.perf_counter()
                steps = drive_grad_u(batch, grad)
                seconds[name] = time.perf_counter() - t0
                measures[name] = batch.homogenize()
            ref, dev = measures.values()
            pressure = np.abs(np.trace(ref.stress, axis1=1, axis2=2)) / 2
            stress_rel = np.abs(dev.stress - ref.stress).max(axis=(1, 2)) / pressure
            tangent_rel = (np.abs(dev.tangent - ref.tangent).max(axis=(1, 2, 3, 4))
                           / np.abs(ref.tangent).max(axis=(1, 2, 3, 4)))
            for b in range(n_rve):
                rows.append({"dtype": dtype, "rve": b, "grad_u_xx": grad[b, 0, 0],
                             "grad_u_xy": grad[b, 0, 1], "grad_u_yx": grad[b, 1, 0],
                             "grad_u_yy": grad[b, 1, 1],
                             "pressure_pa": pressure[b], "stress_rel_diff": stress_rel[b],
                             "tangent_rel_diff": tangent_rel[b],
                             "coordination_ref": ref.coordination[b],
                             "coordination_dev": dev.coordination[b]})
            summary["dtypes"][dtype] = {
                "dem_steps": int(steps), "seconds": seconds,
                "max_stress_rel_diff": float(stress_rel.max()),
                "max_tangent_rel_diff": float(tangent_rel.max()),
                "max_coordination_diff": float(np.abs(dev.coordination
                                                      - ref.coordination).max()),
                "tolerance": TOLERANCE[dtype],
                "within_tolerance": bool(stress_rel.max() <= TOLERANCE[dtype]),
            }
    write_csv(pd.DataFrame(rows), out / "agreement.csv")
    summary["within_tolerance"] = all(d["within_tolerance"] for d in summary["dtypes"].values())
    write_json(summary, out / "agreement.json")
    return summary


def condensed(out: Path, device: str = "cuda", n_rve: int = 8, particles: int = 400,
              strain: float = 2e-3, sliding: str = "free") -> dict:
    """The condensed tangents of a sheared batch by the warp CG on ``device`` against
    scipy's LU; writes ``condensed.json`` under ``out`` and returns it."""
    verbose(False)
    from granular_material.dem import DEMBatch
    from granular_material.dem.condensed.cg import condensed_tangent_cg
    from granular_material.dem.condensed.device import condensed_tangent_of_batch
    from granular_material.dem.condensed.tangent import condensed_tangent
    from granular_material.procedures import drive_grad_u, prepare_packing
    from granular_material.procedures.packing import DEFAULT_PRESSURE
    from granular_material.results import write_json

    out.mkdir(parents=True, exist_ok=True)
    one = prepare_packing(n_disc=particles, seed=1, pressure=DEFAULT_PRESSURE,
                          device="cpu").to_data().select(0)
    batch = DEMBatch(one.replicate(n_rve), device="cpu")
    drive_grad_u(batch, gradients(n_rve, strain))
    data = batch.to_data()
    t0 = time.perf_counter()
    lu = condensed_tangent(data, sliding=sliding)
    t1 = time.perf_counter()
    condensed_tangent_cg(data.select(0), device=device, sliding=sliding)  # compiled, loaded
    t2 = time.perf_counter()
    cg = condensed_tangent_cg(data, device=device, sliding=sliding)
    t3 = time.perf_counter()
    # the same, its systems assembled on the device from the batch's own arrays
    on_device = DEMBatch(data, device=device)
    condensed_tangent_of_batch(on_device, rves=np.array([0]), sliding=sliding)  # compiled
    t4 = time.perf_counter()
    assembled = condensed_tangent_of_batch(on_device, sliding=sliding)
    t5 = time.perf_counter()
    # beside them, what the DEM of one evaluation costs on the same device: DEM_STEPS steps
    # of the same batch (an evaluation of the paper's specimen takes 100–560)
    on_device.run(10)
    on_device.homogenize()
    t6 = time.perf_counter()
    on_device.run(DEM_STEPS)
    on_device.homogenize()
    t7 = time.perf_counter()
    scale = np.abs(lu.tangent).max(axis=(1, 2, 3, 4))
    rel = np.abs(cg.tangent - lu.tangent).max(axis=(1, 2, 3, 4)) / scale
    rel_assembled = np.abs(assembled.tangent - lu.tangent).max(axis=(1, 2, 3, 4)) / scale
    iterations = np.asarray(cg.iterations)
    summary = {"device": device, "n_rve": n_rve, "particles": particles, "strain": strain,
               "sliding": sliding,
               "max_rel_diff": float(rel.max()), "rel_diff": rel.tolist(),
               "cg_iterations": iterations.tolist(),
               "cg_iterations_median": float(np.median(iterations)),
               "seconds": {"lu_host": t1 - t0, "cg": t3 - t2,
                           "cg_assembly_host": cg.assembly_seconds,
                           "cg_solve": cg.solve_seconds, "cg_first_call": t2 - t1,
                           "device_assembly": t5 - t4,
                           "device_assembly_assembly": assembled.assembly_seconds,
                           "device_assembly_solve": assembled.solve_seconds,
                           f"dem_{DEM_STEPS}_steps": t7 - t6},
               "device_assembly_max_rel_diff": float(rel_assembled.max()),
               "tolerance": CONDENSED_TOLERANCE,
               "within_tolerance": bool(max(rel.max(), rel_assembled.max())
                                        <= CONDENSED_TOLERANCE)}
    write_json(summary, out / "condensed.json")
    return summary


def _use_block_path(batch, block: bool) -> None:
    """Step every shard of ``batch`` by the block path (True) or the two-kernel step."""
    for shard in batch.shards:
        shard.solver.serial = False
        shard.solver.block = block


def paths(out: Path, device: str = "cuda", batches: tuple[int, ...] = (1, 64, 1024, 4096),
          particles: int = 400, dtypes: tuple[str, ...] = ("float64", "float32"),
          seconds: float = 0.5) -> dict:
    """Time the two-kernel step and the block path from one snapshot per float type and
    B; writes ``paths.csv`` and ``paths.json`` under ``out`` and returns the summary."""
    verbose(False)
    from granular_material.dem import DEMBatch
    from granular_material.procedures import prepare_packing
    from granular_material.procedures.packing import DEFAULT_PRESSURE
    from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP
    from granular_material.results import write_csv, write_json

    out.mkdir(parents=True, exist_ok=True)
    one = prepare_packing(n_disc=particles, seed=1, pressure=DEFAULT_PRESSURE,
                          device=device).to_data().select(0)
    rows, summary = [], {"device": device, "particles": particles, "cases": []}
    for dtype in dtypes:
        for n_rve in batches:
            batch = DEMBatch(one.replicate(n_rve), device=device, dtype=dtype)
            shear = np.zeros((n_rve, 2, 2))
            shear[:, 0, 1] = DEFAULT_STRAIN_PER_STEP / batch.dt
            batch.set_affine(shear)
            _use_block_path(batch, False)
            batch.run(20)  # lists built, kernels loaded
            start = batch.snapshot()
            t0 = time.perf_counter()
            batch.run(20)
            steps = max(20, int(seconds / ((time.perf_counter() - t0) / 20)))
            rates, stress, rounds = {}, {}, 0
            for path in ("two_kernel", "block"):
                _use_block_path(batch, path == "block")
                batch.restore(start)
                batch.run(20)  # this path's module loaded, its launches recorded
                batch.restore(start)
                before = sum(s.solver.block_rounds for s in batch.shards)
                t0 = time.perf_counter()
                batch.run(steps, check_every=steps)  # ends reading the status back
                rates[path] = n_rve * batch.n_disc * steps / (time.perf_counter() - t0)
                stress[path] = batch.homogenize().stress
                rounds = sum(s.solver.block_rounds for s in batch.shards) - before
            pressure = np.abs(np.trace(stress["two_kernel"], axis1=1, axis2=2)) / 2
            diff = float((np.abs(stress["block"] - stress["two_kernel"]).max(axis=(1, 2))
                          / pressure).max())
            case = {"dtype": dtype, "n_rve": n_rve, "steps": steps,
                    "two_kernel_particle_steps_per_s": rates["two_kernel"],
                    "block_particle_steps_per_s": rates["block"],
                    "block_over_two_kernel": rates["block"] / rates["two_kernel"],
                    "block_rounds": rounds, "stress_rel_diff": diff,
                    "tolerance": TOLERANCE[dtype],
                    "within_tolerance": bool(diff <= TOLERANCE[dtype])}
            rows.append(case)
            summary["cases"].append(case)
            print(f"{dtype} B = {n_rve}: two-kernel {rates['two_kernel']:.3g}, block "
                  f"{rates['block']:.3g} particle-steps/s (x{case['block_over_two_kernel']:.2f}"
                  f"), {rounds} rounds for {steps} steps, stress rel. diff {diff:.2g}",
                  flush=True)
    write_csv(pd.DataFrame(rows), out / "paths.csv")
    summary["within_tolerance"] = all(c["within_tolerance"] for c in summary["cases"])
    write_json(summary, out / "paths.json")
    return summary


def block_specimen(cli_arguments: list[str]) -> int:
    """``granular_material.cli`` with ``cli_arguments``, the engine's rule set to take the
    block path for every batch whose discs fit it (on any device); its exit code, or 1
    where no solver took the block path."""
    verbose(False)
    from granular_material.cli import main as cli_main
    from granular_material.dem import solver
    from granular_material.dem.kernels.block import BLOCK_DISCS

    taken = []

    def rule(cuda: bool, n_rve: int, n_disc: int) -> bool:
        taken.append(n_disc <= BLOCK_DISCS)
        return taken[-1]

    solver.block_path_expected_to_pay = rule
    code = cli_main(cli_arguments)
    print(f"block-specimen: {sum(taken)} of {len(taken)} solvers took the block path",
          flush=True)
    return code if any(taken) else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("require-cuda", help="exit 2 with a message where there is no CUDA device")
    agree = sub.add_parser("agreement", help="a sheared batch on --device against --reference")
    agree.add_argument("--out", type=Path, required=True)
    agree.add_argument("--device", default="cuda")
    agree.add_argument("--reference", default="cpu")
    agree.add_argument("--batch", type=int, default=16)
    agree.add_argument("--particles", type=int, default=400)
    agree.add_argument("--strain", type=float, default=2e-3)
    agree.add_argument("--dtypes", default="float64,float32")
    tangent = sub.add_parser("condensed", help="the condensed tangent's CG on --device "
                                               "against the LU on the host")
    tangent.add_argument("--out", type=Path, required=True)
    tangent.add_argument("--device", default="cuda")
    tangent.add_argument("--batch", type=int, default=8)
    tangent.add_argument("--particles", type=int, default=400)
    tangent.add_argument("--strain", type=float, default=2e-3)
    tangent.add_argument("--sliding", choices=("free", "stick"), default="free",
                         help="contacts at their Coulomb cap: no tangential stiffness "
                              "(free) or kt (stick)")
    timing = sub.add_parser("paths", help="the two-kernel step against the block path")
    timing.add_argument("--out", type=Path, required=True)
    timing.add_argument("--device", default="cuda")
    timing.add_argument("--batches", default="1,64,1024,4096")
    timing.add_argument("--particles", type=int, default=400)
    timing.add_argument("--dtypes", default="float64,float32")
    timing.add_argument("--seconds", type=float, default=0.5)
    specimen = sub.add_parser("block-specimen", help="the command line, block path taken")
    specimen.add_argument("cli", nargs=argparse.REMAINDER,
                          help="the options of granular_material.cli (after --)")
    args = parser.parse_args(argv)
    if args.command == "block-specimen":
        cli = args.cli[1:] if args.cli[:1] == ["--"] else args.cli
        return block_specimen(cli)
    if args.command == "paths":
        if args.device.startswith("cuda"):
            require_cuda()
        summary = paths(args.out, args.device, tuple(int(b) for b in args.batches.split(",")),
                        args.particles, tuple(args.dtypes.split(",")), args.seconds)
        return 0 if summary["within_tolerance"] else 1
    if args.command == "require-cuda":
        print(require_cuda())
        return 0
    if args.command == "condensed":
        if args.device.startswith("cuda"):
            require_cuda()
        summary = condensed(args.out, args.device, args.batch, args.particles, args.strain,
                            args.sliding)
        sec = summary["seconds"]
        print(f"condensed tangent ({args.sliding}): CG on {args.device} against the LU, "
              f"{args.batch} RVEs: "
              f"rel. diff <= {summary['max_rel_diff']:.3g} (tolerance "
              f"{CONDENSED_TOLERANCE:g}: {'within' if summary['within_tolerance'] else 'OUTSIDE'}"
              f"); CG {sec['cg']:.3g} s (assembly on the host {sec['cg_assembly_host']:.3g} s, "
              f"solve {sec['cg_solve']:.3g} s, median {summary['cg_iterations_median']:g} "
              f"iterations), LU {sec['lu_host']:.3g} s; assembled on the device "
              f"{sec['device_assembly']:.3g} s (assembly {sec['device_assembly_assembly']:.3g}"
              f" s, rel. diff <= {summary['device_assembly_max_rel_diff']:.3g}); "
              f"{DEM_STEPS} DEM steps of the same batch {sec[f'dem_{DEM_STEPS}_steps']:.3g} s")
        return 0 if summary["within_tolerance"] else 1
    if args.device.startswith("cuda") or args.reference.startswith("cuda"):
        require_cuda()
    summary = agreement(args.out, args.device, args.reference, args.batch, args.particles,
                        args.strain, tuple(args.dtypes.split(",")))
    for dtype, d in summary["dtypes"].items():
        print(f"{dtype}: {args.device} against {args.reference}, {args.batch} RVEs, "
              f"{d['dem_steps']} steps: stress rel. diff <= {d['max_stress_rel_diff']:.3g}, "
              f"tangent <= {d['max_tangent_rel_diff']:.3g} (tolerance {d['tolerance']:g}: "
              f"{'within' if d['within_tolerance'] else 'OUTSIDE'})")
    return 0 if summary["within_tolerance"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
