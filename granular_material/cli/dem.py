"""The DEM commands: ``prepare``, ``biaxial-dem`` and ``dem-drive``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from granular_material.cli.options import (
    DISC_BYTES,
    UsageError,
    add_device,
    add_dtype,
    add_json,
    add_max_dem_steps,
    add_out,
    add_progress,
    add_rve_material_options,
    check_figure_file,
    check_memory,
    check_output_file,
    emit,
    make_parents,
    packing_parameters,
    positive,
    positive_int,
    progress_enabled,
    scalar_or_list,
    warn,
)
from granular_material.cli.signals import interrupt_exit_code
from granular_material.procedures.element_tests import (
    DEFAULT_AXIAL_STRAIN,
    DEFAULT_RECORD_EVERY,
)
from granular_material.procedures.packing import (
    DEFAULT_DISCS,
    DEFAULT_PRESSURE,
    DEFAULT_RADIUS_RANGE,
    MAX_OVERLAP,
    VOID_RATIO_TOLERANCE,
    min_discs,
)
from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP

if TYPE_CHECKING:
    from granular_material.dem import DEMBatch as DEMBatchType

__all__ = ["register"]

#: |σxx/(−confining) − 1| of biaxial-dem: above SERVO_WARN at some record a warning; above
#: SERVO_FAIL over half the records (the median) the servo did not hold it: exit 1
SERVO_WARN = 0.02
SERVO_FAIL = 0.05


def _grad_u(text: str) -> np.ndarray:
    parts = text.split(",")
    if len(parts) != 4:
        raise argparse.ArgumentTypeError(
            f"--grad-u takes four comma-separated numbers Gxx,Gxy,Gyx,Gyy, got {text!r}"
        )
    try:
        values = np.array([float(p) for p in parts])
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--grad-u has a value that is not a number: {text!r}"
        ) from None
    if not np.isfinite(values).all():
        raise argparse.ArgumentTypeError(f"--grad-u must be finite, got {text!r}")
    return values.reshape(2, 2)


def _add_run_options(parser: argparse.ArgumentParser) -> None:
    add_device(parser)
    add_dtype(parser)
    add_progress(parser)
    add_json(parser)


def _device(args: argparse.Namespace) -> str:
    """The command's DEM device, chosen here once: ``--device``, else CUDA when present."""
    from granular_material.dem import resolve_device

    return resolve_device(args.device)


def _load_batch(args: argparse.Namespace) -> DEMBatchType:
    from granular_material.dem import DEMBatch, load_rve

    data = load_rve(args.rve)
    return DEMBatch(data, device=_device(args), dtype=args.dtype)


def _finish(args: argparse.Namespace, report: dict[str, Any], error: str | None,
            interrupt: KeyboardInterrupt | None = None) -> int:
    """Emit ``report`` with its ``error``; exit code 1 (said on stderr) when there is one,
    130/143 when Ctrl-C/SIGTERM (``interrupt``) stopped the run after what it wrote."""
    report["error"] = error
    emit(args, report)
    if interrupt is not None:
        print(f"granular-material {args.command}: {error}", file=sys.stderr)
        return interrupt_exit_code(interrupt)
    if error is not None:
        print(f"granular-material {args.command}: failed: {error}", file=sys.stderr)
        return 1
    return 0


def _rve_list(indices: np.ndarray, values: np.ndarray, fmt: str) -> str:
    """``RVE 0: …, RVE 3: …`` of the first five ``indices`` with their ``values``."""
    shown = ", ".join(f"RVE {i}: {format(values[i], fmt)}" for i in indices[:5])
    return shown + (f" and {len(indices) - 5} more" if len(indices) > 5 else "")


# -- prepare -------------------------------------------------------------------------------
def _run_prepare(args: argparse.Namespace) -> int:
    from granular_material.dem import save_rve
    from granular_material.procedures import prepare_packing
    check_output_file(args.out)
    packing = packing_parameters(args, args.particles, args.pressure)
    check_memory(float(args.batch) * args.particles * DISC_BYTES,
                 f"--batch {args.batch} RVEs of --particles {args.particles} discs")
    batch = prepare_packing(
        n_disc=args.particles, n_rve=args.batch, seed=args.seed, pressure=args.pressure,
        meta=packing.meta, target_void_ratio=packing.target_void_ratio,
        radius_range=packing.radius_range, device=_device(args), dtype=args.dtype,
        progress=progress_enabled(args),
    )
    h = batch.homogenize()
    report: dict[str, Any] = batch.summary(h)
    warnings: list[str] = []
    error = None
    target = args.target_void_ratio
    if target is not None and (h.void_ratio > target).any():
        missed = np.flatnonzero(h.void_ratio > target)
        reached = _rve_list(missed, h.void_ratio, ".4g")
        text = (f"--target-void-ratio {target:g} not reached under --pressure "
                f"{args.pressure:g} Pa: void ratio of {reached} (frictionless compaction "
                "reached the pressure first; a denser packing "
                "needs a higher --pressure)")
        if (h.void_ratio > target + VOID_RATIO_TOLERANCE).any():
            error = text + "; no RVE file written"
        else:
            warnings.append(warn(args, text))
    report["warnings"] = warnings
    if error is None:
        make_parents(args.out)
        save_rve(args.out, batch.to_data())
        report["out"] = str(args.out)
    return _finish(args, report, error)


# -- biaxial-dem ---------------------------------------------------------------------------
#: how the checks of biaxial_test name its values: by the command's options
_BIAXIAL_OPTIONS = {"axial_strain": "--axial-strain", "confining": "--confining",
                    "strain_per_step": "--strain-per-step", "max_steps": "--max-dem-steps"}


def _run_biaxial(args: argparse.Namespace) -> int:
    from granular_material.procedures import biaxial_test
    from granular_material.procedures.element_tests import (
        BiaxialInterrupted,
        check_biaxial,
        lateral_stress_error,
    )
    from granular_material.results import plot_biaxial_curves, summarize_biaxial, write_csv

    check_output_file(args.out)
    check_figure_file(args.plot, "--plot", {"--out": args.out})
    try:
        check_biaxial(args.axial_strain, args.confining, args.strain_per_step,
                      args.max_dem_steps, names=_BIAXIAL_OPTIONS)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    batch = _load_batch(args)
    interrupt = None
    try:
        curve = biaxial_test(batch, axial_strain=args.axial_strain, confining=args.confining,
                             strain_per_step=args.strain_per_step,
                             record_every=args.record_every, progress=progress_enabled(args),
                             max_steps=args.max_dem_steps)
    except BiaxialInterrupted as exc:  # keep and write the records made before it
        curve, interrupt = exc.curve, exc
    summaries = [summarize_biaxial(g) for _, g in curve.groupby("rve")]
    if args.out:
        make_parents(args.out)
        write_csv(curve, args.out)
    if args.plot:
        make_parents(args.plot)
        plot_biaxial_curves(curve, args.plot)
    keys = ("peak_stress_ratio", "axial_strain_at_peak", "max_contraction", "final_void_ratio")
    report: dict[str, Any] = {key: scalar_or_list(np.array([getattr(s, key) for s in summaries]))
                              for key in keys}
    held = lateral_stress_error(curve, args.confining)
    report |= {"steps": int(curve["step"].max()),
               "final_sxx": scalar_or_list(held["final_sxx"].to_numpy()),
               "max_confining_error": scalar_or_list(held["max_error"].to_numpy())}
    warnings: list[str] = []
    error = None
    lost = np.flatnonzero(held["median_error"].to_numpy() > SERVO_FAIL)
    loose = np.flatnonzero(held["max_error"].to_numpy() > SERVO_WARN)
    final = held["final_sxx"].to_numpy()
    if lost.size:
        error = (f"the servo did not hold σxx at −{args.confining:g} Pa (--confining), off "
                 f"by more than {SERVO_FAIL:.0%} in most records: final σxx [Pa] of "
                 f"{_rve_list(lost, final, '.4g')}; not a drained test at this confining "
                 "pressure (a smaller --strain-per-step, or a packing prepared near "
                 "--confining, lets the servo follow)")
    elif loose.size:
        worst = held["max_error"].to_numpy()
        warnings.append(warn(args, (
            f"σxx strayed from −{args.confining:g} Pa (--confining) by more than "
            f"{SERVO_WARN:.0%} in some records: largest error [%] of "
            f"{_rve_list(loose, 100 * worst, '.3g')}")))
    report["warnings"] = warnings
    if args.out:
        report["out"] = str(args.out)
    if interrupt is not None:
        error = (f"{interrupt}: the curve to axial strain "
                 f"{curve['axial_strain'].max():.4g} is kept")
    return _finish(args, report, error, interrupt)


# -- dem-drive -----------------------------------------------------------------------------
#: how the checks of a path name its values: by the command's options
_PATH_OPTIONS = {"grad_u": "--grad-u", "increments": "--increments",
                 "max_strain_per_step": "--max-strain-per-step", "max_steps": "--max-dem-steps"}
#: the increments of dem-drive by default
_INCREMENTS = 10


def _drive_plan(args: argparse.Namespace) -> list[int]:
    """DEM steps of each increment of ``dem-drive``, checked against --max-dem-steps before
    any work (UsageError naming the options)."""
    from granular_material.procedures import plan_path

    try:
        return plan_path(args.grad_u, args.increments, args.max_strain_per_step,
                         args.max_dem_steps, names=_PATH_OPTIONS)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _run_drive(args: argparse.Namespace) -> int:
    from granular_material.procedures import drive_path, progress_bar
    from granular_material.results import write_csv

    check_output_file(args.out)
    plan = _drive_plan(args)
    batch = _load_batch(args)
    # the bar counts DEM steps (what takes the time), moved at the end of each increment
    with progress_bar(sum(plan), "dem-drive", progress_enabled(args)) as bar:
        def advance(increment: int, steps: int) -> None:
            bar.update(steps)
            bar.set_postfix(increment=f"{increment}/{args.increments}")

        path = drive_path(batch, args.grad_u, args.increments,
                          max_strain_per_step=args.max_strain_per_step,
                          max_steps=args.max_dem_steps, after_increment=advance)
    if args.out:
        make_parents(args.out)
        write_csv(path.table, args.out)
    report: dict[str, Any] = {**path.summary(), "warnings": []}
    if args.out:
        report["out"] = str(args.out)
    error = path.failure_message(args.increments)
    finished, interrupt = path.finished, path.interrupt
    if interrupt is not None:
        error = (f"interrupted after increment {finished} of {args.increments}: the path to "
                 "it is kept")
    report["increments_completed"] = finished
    return _finish(args, report, error, interrupt)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``prepare``, ``biaxial-dem`` and ``dem-drive`` to the command line."""
    p = subparsers.add_parser(
        "prepare", help="generate and consolidate periodic RVE packings",
        description="Random discs in a periodic cell, frictionless isotropic consolidation "
        "to --pressure, then friction set and re-equilibrated; written as an RVE file. "
        f"Exit code 1 (no file) when the void ratio ends more than {VOID_RATIO_TOLERANCE:g} above "
        "--target-void-ratio; a warning when it ends above it by less.",
    )
    r_min, r_max = DEFAULT_RADIUS_RANGE
    p.add_argument("--particles", type=positive_int, default=DEFAULT_DISCS,
                   help=f"discs per RVE ({DEFAULT_DISCS}; at least {min_discs()} for "
                        f"{r_min * 1e3:g}–{r_max * 1e3:g} mm radii, so the cell stays wider "
                        "than twice the contact cut-off)")
    p.add_argument("--seed", type=int, default=1, help="random seed; RVE b uses seed + b (1)")
    p.add_argument("--pressure", type=positive, default=DEFAULT_PRESSURE,
                   help=f"isotropic consolidation pressure [Pa] ({DEFAULT_PRESSURE:g}; at most "
                        f"{MAX_OVERLAP / 2:g}·kn/thickness, or {MAX_OVERLAP / 2:g}·contact-young·"
                        "radius-min/thickness for frictmat, so contacts overlap under "
                        f"{MAX_OVERLAP:.0%}% of the radius)")
    p.add_argument("--batch", type=positive_int, default=1, help="number of RVEs B (1)")
    add_out(p, "RVE file (rve.npz)", default=Path("rve.npz"))
    add_rve_material_options(p, old_names=True)
    _add_run_options(p)
    p.set_defaults(func=_run_prepare)

    p = subparsers.add_parser(
        "biaxial-dem", help="drained biaxial test of the RVE(s) of a file",
        description="σxx held at -confining by a servo while the axial strain εyy is driven. "
        "CSV columns: rve, step, axial_strain (compression positive), lateral_strain, "
        "volumetric_strain, sxx, syy, sxy [Pa, tension positive], stress_ratio, void_ratio, "
        "coordination. Exit code 1 (the final σxx in the message) when the servo kept σxx "
        f"more than {SERVO_FAIL:.0%} off in most records; a warning where it strayed more "
        f"than {SERVO_WARN:.0%}.",
    )
    p.add_argument("rve", type=Path, help="RVE file (.npz)")
    p.add_argument("--axial-strain", type=positive, default=DEFAULT_AXIAL_STRAIN,
                   help=f"final strain ({DEFAULT_AXIAL_STRAIN:g})")
    p.add_argument("--confining", type=positive, default=DEFAULT_PRESSURE,
                   help=f"[Pa] ({DEFAULT_PRESSURE:g})")
    p.add_argument("--strain-per-step", type=positive, default=DEFAULT_STRAIN_PER_STEP,
                   help=f"({DEFAULT_STRAIN_PER_STEP:g})")
    p.add_argument("--record-every", type=positive_int, default=DEFAULT_RECORD_EVERY,
                   help=f"steps between CSV rows ({DEFAULT_RECORD_EVERY})")
    add_max_dem_steps(p, "the test")
    add_out(p, "CSV of the curve(s)")
    p.add_argument("--plot", type=Path, default=None, help="PNG of σ1/σ3 and εv vs εa")
    _add_run_options(p)
    p.set_defaults(func=_run_biaxial)

    p = subparsers.add_parser(
        "dem-drive", help="apply a displacement gradient to the RVE(s) of a file",
        description="Applies the total ∇u in K equal strain-driven increments (at most "
        "--max-strain-per-step strain a step, Guo & Zhao). CSV: one row per increment and "
        "RVE (increment 0 = initial state): rve, increment, Gxx, Gxy, Gyx, Gyy (∇u so far), "
        "sxx, syy, sxy [Pa, tension positive], void_ratio, coordination, steps.",
    )
    p.add_argument("rve", type=Path, help="RVE file (.npz)")
    p.add_argument("--grad-u", type=_grad_u, required=True, metavar="Gxx,Gxy,Gyx,Gyy",
                   help="total displacement gradient ∂u_i/∂x_j")
    p.add_argument("--increments", type=positive_int, default=_INCREMENTS,
                   help=f"K ({_INCREMENTS})")
    p.add_argument("--max-strain-per-step", type=positive, default=DEFAULT_STRAIN_PER_STEP,
                   help=f"({DEFAULT_STRAIN_PER_STEP:g})")
    add_max_dem_steps(p, "the whole path (all increments)")
    add_out(p, "CSV of the path")
    _add_run_options(p)
    p.set_defaults(func=_run_drive)
