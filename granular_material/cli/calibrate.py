"""The ``calibrate`` command: a Mohr–Coulomb material read from drained biaxial DEM tests of
an RVE file (:func:`~granular_material.procedures.calibration.calibrate_mohr_coulomb`)."""

from __future__ import annotations

import argparse
import json
import sys
import textwrap
from pathlib import Path
from typing import TYPE_CHECKING, Any

from granular_material.cli.options import (
    UsageError,
    add_device,
    add_dtype,
    add_json,
    add_progress,
    check_output_dir,
    emit,
    positive,
    positive_int,
    progress_enabled,
    rve_file_shape,
    shown,
)
from granular_material.errors import ParameterError
from granular_material.procedures.element_tests import DEFAULT_AXIAL_STRAIN
from granular_material.vocabulary import renamed

if TYPE_CHECKING:
    from granular_material.procedures.calibration import Calibration

__all__ = ["OUTPUT_FILES", "calibration_toml", "register"]

#: the files ``calibrate`` writes into --out
OUTPUT_FILES = ("mohr-coulomb.toml", "calibration.json", "calibration.csv",
                "mohr-coulomb.csv", "calibration.png")
#: the output folder by default
DEFAULT_OUT = Path("calibration")


def calibration_toml(calibration: Calibration) -> str:
    """The parameters as a material file: the Mohr–Coulomb run parameters as top-level keys
    (``young`` [Pa], ``poisson`` [-], ``friction_angle``, ``dilation_angle`` [deg],
    ``cohesion`` [Pa], ``critical_friction_angle`` [deg], ``softening_strain`` [-]), each
    with how it was read in the comments above it."""
    from granular_material.procedures.calibration import PARAMETER_UNITS

    c = calibration
    lines = ["# Mohr–Coulomb parameters calibrated from drained biaxial DEM tests",
             "# (granular-material calibrate); the readings in full: calibration.json",
             f"# RVE file: {c.source}", f"# confining pressure P = {c.pressure:g} Pa",
             *textwrap.wrap("test: " + ", ".join(f"{k} = {v}" for k, v in c.settings.items()),
                            92, initial_indent="# ", subsequent_indent="#   "),
             "# each value: the mean over the RVEs; ± their standard deviation, [min, max];",
             "# windows in axial strain (engineering, compression positive)"]
    for note in c.notes:
        lines += textwrap.wrap(f"note: {note}", 92, initial_indent="# ",
                               subsequent_indent="#   ")
    for name, unit in PARAMETER_UNITS.items():
        r = c.readings[name]
        lo, hi = min(w[0] for w in r.windows), max(w[1] for w in r.windows)
        lines += ["", *textwrap.wrap(f"{name} [{unit}]: {r.method}", 92,
                                     initial_indent="# ", subsequent_indent="#   "),
                  f"#   read {r.value:.6g} ± {r.std:.3g} [{r.min:.6g}, {r.max:.6g}] over "
                  f"{len(r.per_rve)} RVE(s), axial strain {lo:.4g} to {hi:.4g}"]
        if name == "critical_friction_angle" \
                and c.material_keywords()["critical_friction_angle"] is None:
            lines.append("# critical_friction_angle left out: no softening read (φcs = φ)")
        else:
            lines.append(f"{name} = {float(c.parameters[name])!r}")
    return "\n".join(lines) + "\n"


def _write_text(path: Path, text: str) -> None:
    from granular_material.filesafe import write_whole

    write_whole(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def _run_calibrate(args: argparse.Namespace) -> int:
    from granular_material.dem import resolve_device
    from granular_material.procedures.calibration import calibrate_mohr_coulomb, model_curve
    from granular_material.results.calibration_plot import plot_calibration
    from granular_material.results.writers import strict_json, write_csv

    # refusals before any work: nothing is written on a refused run
    try:  # --pressure, its old name: warned, read as --confining
        confining = renamed({"confining": args.confining, "pressure": args.pressure},
                            "calibrate", given=lambda v: v is not None).get("confining")
    except ParameterError as exc:
        raise UsageError(shown(exc)) from None
    if confining is None:
        raise UsageError("--confining is required: the confining pressure P [Pa] of the tests")
    check_output_dir(args.out)
    n_rve, _ = rve_file_shape(args.rve, "RVE")
    if args.rves is not None and args.rves > n_rve:
        raise UsageError(f"--rves {args.rves} asks for more RVEs than the {n_rve} of "
                         f"{args.rve}")
    calibration = calibrate_mohr_coulomb(
        args.rve, confining, axial_strain=args.axial_strain,
        device=resolve_device(args.device),
        progress=progress_enabled(args), rves=args.rves, dtype=args.dtype,
        record_every=args.record_every, elastic_window=args.elastic_window,
        dilatancy_window=args.dilatancy_window, critical_fraction=args.critical_fraction)
    model = model_curve(calibration)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    _write_text(out / "mohr-coulomb.toml", calibration_toml(calibration))
    _write_text(out / "calibration.json",  # strict JSON: null for a number not finite
                json.dumps(strict_json(calibration.as_dict()), indent=2, ensure_ascii=False,
                           allow_nan=False) + "\n")
    write_csv(calibration.curve, out / "calibration.csv")
    write_csv(model, out / "mohr-coulomb.csv")
    plot_calibration(calibration, model, out / "calibration.png")
    report: dict[str, Any] = {name: calibration.parameters[name]
                              for name in calibration.parameters}
    report |= {f"{name}_std": r.std for name, r in calibration.readings.items()
               if name != "cohesion"}
    report |= {"rves": calibration.settings.get("rves"), "out": str(out),
               "notes": list(calibration.notes), "error": None}
    for note in calibration.notes:
        print(f"granular-material calibrate: note: {note}", file=sys.stderr)
    emit(args, report)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``calibrate`` to the command line."""
    from granular_material.procedures.calibration import (
        DEFAULT_CRITICAL_FRACTION,
        DEFAULT_DILATANCY_WINDOW,
        DEFAULT_ELASTIC_WINDOW,
        DEFAULT_RECORD_EVERY,
    )

    p = subparsers.add_parser(
        "calibrate", help="Mohr–Coulomb parameters from drained biaxial DEM tests of an RVE file",
        description="Drained biaxial DEM tests of the RVEs of a file at the confining pressure "
        "--confining (an RVE whose stress is more than 1%% off −P is first re-consolidated "
        "isotropically to P), stepped as the DEM material steps (1e-5 strain a DEM step); "
        "then E and ν (secant over the first --elastic-window of axial strain), φ at the "
        "peak of σ1/σ3 (c = 0), ψ from the plastic dilatancy at the peak, φcs over the last "
        "--critical-fraction of the strain and the softening strain, each the mean over the "
        "RVEs with its scatter. Writes into --out: " + ", ".join(OUTPUT_FILES) + " (the "
        "material file: mohr-coulomb.toml, in the mohr-coulomb material's run parameters).")
    p.add_argument("rve", type=Path, help="RVE file (.npz)")
    p.add_argument("--confining", type=positive, default=None, metavar="PA",
                   help="confining pressure P [Pa] of the tests (compression positive; "
                        "required)")
    p.add_argument("--pressure", type=positive, default=None,  # its old name: hidden
                   help=argparse.SUPPRESS)
    p.add_argument("--axial-strain", type=positive, default=DEFAULT_AXIAL_STRAIN,
                   help=f"final axial strain of the tests ({DEFAULT_AXIAL_STRAIN:g}); long "
                        "enough to pass the peak and reach a steady ratio")
    p.add_argument("--rves", type=positive_int, default=None, metavar="N",
                   help="test the first N RVEs of the file (default: all of them)")
    p.add_argument("--record-every", type=positive_int, default=DEFAULT_RECORD_EVERY,
                   help=f"DEM steps between the curve's records ({DEFAULT_RECORD_EVERY})")
    p.add_argument("--elastic-window", type=positive, default=DEFAULT_ELASTIC_WINDOW,
                   help=f"axial strain E and ν are read over ({DEFAULT_ELASTIC_WINDOW:g})")
    p.add_argument("--dilatancy-window", type=positive, default=DEFAULT_DILATANCY_WINDOW,
                   help="width in axial strain of the window around the peak ψ is read over "
                        f"({DEFAULT_DILATANCY_WINDOW:g})")
    p.add_argument("--critical-fraction", type=positive, default=DEFAULT_CRITICAL_FRACTION,
                   help="last fraction of the axial strain φcs is read over "
                        f"({DEFAULT_CRITICAL_FRACTION:g})")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT,
                   help=f"output folder ({DEFAULT_OUT})")
    add_device(p)
    add_dtype(p)
    add_progress(p)
    add_json(p)
    p.set_defaults(func=_run_calibrate)
