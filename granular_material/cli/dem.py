"""The DEM commands ``prepare``, ``biaxial-dem`` and ``dem-drive``: their options, the
DEM run specification they make of them (:mod:`granular_material.runs.dem`) and its report;
the run itself is :func:`granular_material.runs.run`."""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Callable
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np

from granular_material.checks import WordedError
from granular_material.cli.options import (
    UsageError,
    add_device,
    add_dtype,
    add_json,
    add_max_dem_steps,
    add_out,
    add_progress,
    add_rve_material_options,
    as_flags,
    dem_renamed,
    emit,
    flag_of,
    positive,
    positive_int,
    progress_enabled,
    resume_hint,
    warn,
)
from granular_material.cli.signals import interrupt_exit_code
from granular_material.errors import ParameterError
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
from granular_material.runs import run
from granular_material.runs.dem import (
    SERVO_FAIL,
    SERVO_WARN,
    BiaxialDemSpec,
    DemSpec,
    DriveSpec,
    PrepareSpec,
)
from granular_material.runs.dem.spec import DRIVE_INCREMENTS, field_names

__all__ = ["check_args", "command_line", "register", "run_spec_file", "spec_from_args"]

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


def _add_resume_options(parser: argparse.ArgumentParser) -> None:
    """``--resume`` and ``--fresh``: a run stopped part-way keeps its checkpoint beside
    ``--out`` (OUT.checkpoint/)."""
    parser.add_argument("--resume", action="store_true",
                        help="continue the run stopped part-way (Ctrl-C, SIGTERM, killed) from "
                             "the checkpoint kept beside --out (OUT.checkpoint/), given the "
                             "options it was started with; the table is the one an "
                             "uninterrupted run writes")
    parser.add_argument("--fresh", action="store_true",
                        help="start afresh over the checkpoint of a run stopped part-way "
                             "beside --out (thrown away); without it such a run is refused")


def _text(text: str) -> str:
    """A library message (fields in backquotes) as the command line says it: each field as
    its option."""
    return as_flags(text)


def _usage(exc: ParameterError) -> UsageError:
    """A refusal of the spec or its run as the command line's, naming the options."""
    text = exc.message if isinstance(exc, WordedError) else f"`{exc.field}` {exc.message}"
    return UsageError(_text(text))


def _spec(args: argparse.Namespace, kind: type) -> DemSpec:
    """The spec ``kind`` of the command's options (a UsageError naming the option where a
    value cannot run)."""
    if kind is PrepareSpec:  # the RVE material's old option names, read with a warning
        args = dem_renamed(args)
    values = {name: getattr(args, name) for name in field_names(kind)
              if name != "progress"}
    if "grad_u" in values:
        values["grad_u"] = tuple(np.asarray(values["grad_u"], dtype=float).ravel())
    try:
        return kind(**values, progress=progress_enabled(args))
    except ParameterError as exc:
        raise _usage(exc) from None


def _finish(args: argparse.Namespace, report: dict[str, Any], error: str | None,
            interrupt: KeyboardInterrupt | None = None) -> int:
    """Emit ``report`` with its ``error``; exit code 1 (said on stderr) when there is one,
    130/143 when Ctrl-C/SIGTERM (``interrupt``) stopped the run after what it wrote."""
    report["error"] = error
    emit(args, report)
    if interrupt is not None:
        print(f"granular-material {args.command}: {error}", file=sys.stderr)
        again = resume_hint()  # a scene's: `run SCENE --resume`
        if again is not None:
            print(f"granular-material {args.command}: continue it with `{again}`",
                  file=sys.stderr)
        elif getattr(args, "out", None) is not None and hasattr(args, "resume"):
            print(f"granular-material {args.command}: continue it with --resume and the same "
                  "options", file=sys.stderr)
        return interrupt_exit_code(interrupt)
    if error is not None:
        print(f"granular-material {args.command}: failed: {error}", file=sys.stderr)
        return 1
    return 0


#: the spec of each command
_KINDS = {"prepare": PrepareSpec, "biaxial-dem": BiaxialDemSpec, "dem-drive": DriveSpec}


def spec_from_args(args: argparse.Namespace) -> DemSpec:
    """The DEM run specification of a DEM command's options (a UsageError naming the option
    where a value cannot run)."""
    return _spec(args, _KINDS[args.command])


def check_args(args: argparse.Namespace) -> None:
    """Every check the command makes before any work (:func:`granular_material.runs.check`),
    a refusal a UsageError naming the option; nothing is run or written."""
    from granular_material.runs import check

    try:
        check(spec_from_args(args))
    except ParameterError as exc:
        raise _usage(exc) from None


def _command(args: argparse.Namespace, kind: type) -> int:
    """Run the command's spec (:func:`granular_material.runs.run`) and report it."""
    spec = _spec(args, kind)
    try:
        outcome = run(spec, resume=bool(getattr(args, "resume", False)),
                      fresh=bool(getattr(args, "fresh", False)))
    except ParameterError as exc:
        raise _usage(exc) from None
    report = outcome.report
    report["warnings"] = [warn(args, _text(w)) for w in outcome.warnings]
    error = None if outcome.error is None else _text(outcome.error)
    return _finish(args, report, error, outcome.interrupt)


#: the file each command writes into a run folder (``run SPEC --out DIR``)
_FILES = {"prepare": "rve.npz", "biaxial-dem": "curve.csv", "dem-drive": "path.csv"}


def command_line(spec: DemSpec) -> str:
    """The command line of ``spec``: its command and an option for every field not at its
    default."""
    words = ["granular-material", spec.test]
    if hasattr(spec, "rve"):
        words.append(str(spec.rve))
    defaults = {f.name: f.default for f in fields(spec)}
    for f in fields(spec):
        value = getattr(spec, f.name)
        if f.name in ("rve", "progress") or value == defaults[f.name] or value is None:
            continue
        flag = flag_of(f.name)
        if f.name == "grad_u":
            words.append(f"{flag}={','.join(repr(v) for v in value)}")
        else:
            words += [flag, str(value)]
    return shlex.join(words)


def run_spec_file(path: Path, text: str, data: dict[str, Any], args: argparse.Namespace,
                  refusal: Callable[[Path, str, ValueError], UsageError]) -> int:
    """``run SPEC.toml`` of a DEM run's spec (the nested form that
    :func:`granular_material.runs.dem.save` writes): checked whole (a refusal as ``refusal``
    words it, with the field's line), then run (``--check``: only checked, and shown as a
    command line). ``--out DIR`` puts the output file (and figure) into ``DIR``; a spec that
    names no output writes into a folder named after the file."""
    from granular_material.runs import check
    from granular_material.runs.dem import from_dict

    try:
        spec = from_dict(data)
    except ValueError as exc:
        raise refusal(path, text, exc) from exc
    name = _FILES[spec.test]
    changes: dict[str, Any] = {}
    if args.out is not None:
        changes["out"] = Path(args.out) / name
        if getattr(spec, "plot", None) is not None:
            changes["plot"] = Path(args.out) / Path(spec.plot).name
    elif spec.out is None:
        if not path.is_file():
            raise UsageError(f"{path} names no output (output.out) and is no file to name "
                             "one after (a pipe?): give --out DIR")
        changes["out"] = Path(path.stem) / name
    try:
        spec = spec.replace(**changes)
        check(spec)
    except (ValueError, FileNotFoundError) as exc:
        raise refusal(path, text, exc) from exc
    if args.check:
        print(command_line(spec))
        return 0
    if args.out is None and "out" in changes:
        print(f"granular-material run: {path} names no output (output.out); the run writes "
              f"{spec.out}", file=sys.stderr)
    report_args = argparse.Namespace(json=False, command=spec.test)
    try:
        outcome = run(spec, resume=bool(args.resume), fresh=False)
    except ParameterError as exc:
        raise _usage(exc) from None
    report = outcome.report
    report["warnings"] = [warn(report_args, _text(w)) for w in outcome.warnings]
    error = None if outcome.error is None else _text(outcome.error)
    code = _finish(report_args, report, error, outcome.interrupt)
    if outcome.interrupt is not None:
        again = shlex.join(["granular-material", "run", str(path),
                            *(["--out", str(args.out)] if args.out is not None else []),
                            "--resume"])
        print(f"continue it with `{again}`", file=sys.stderr)
    return code


def _run_prepare(args: argparse.Namespace) -> int:
    return _command(args, PrepareSpec)


def _run_biaxial(args: argparse.Namespace) -> int:
    return _command(args, BiaxialDemSpec)


def _run_drive(args: argparse.Namespace) -> int:
    return _command(args, DriveSpec)


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
    _add_resume_options(p)
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
    p.add_argument("--increments", type=positive_int, default=DRIVE_INCREMENTS,
                   help=f"K ({DRIVE_INCREMENTS})")
    p.add_argument("--max-strain-per-step", type=positive, default=DEFAULT_STRAIN_PER_STEP,
                   help=f"({DEFAULT_STRAIN_PER_STEP:g})")
    add_max_dem_steps(p, "the whole path (all increments)")
    add_out(p, "CSV of the path")
    _add_resume_options(p)
    _add_run_options(p)
    p.set_defaults(func=_run_drive)
