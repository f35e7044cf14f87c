"""What every command shares: the options (device, dtype, progress, json, out) defined once,
their argument types, the one way results are reported on stdout."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import re
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from granular_material import checks
from granular_material.checks import (
    DISC_BYTES,
    RVE_MATERIAL_DEFAULTS,
    cleanup_on_rejection,
    make_parents,
    rve_material_given,
)
from granular_material.errors import ParameterError
from granular_material.reference_values import DEFAULT_MAX_DEM_STEPS
from granular_material.vocabulary import renamed, renames

__all__ = [
    "DEFAULT_MAX_DEM_STEPS",
    "DISC_BYTES",
    "RVE_MATERIAL_DEFAULTS",
    "UsageError",
    "add_convergence",
    "add_device",
    "add_dtype",
    "add_element",
    "add_json",
    "add_max_dem_steps",
    "add_out",
    "add_progress",
    "add_rve_material_options",
    "as_flags",
    "check_figure_file",
    "check_memory",
    "check_output_dir",
    "check_output_file",
    "cleanup_on_rejection",
    "dem_renamed",
    "emit",
    "flag_of",
    "make_parents",
    "message_of",
    "packing_parameters",
    "positive",
    "positive_int",
    "progress_enabled",
    "reports_to",
    "rve_file_shape",
    "rve_material_given",
    "scalar_or_list",
    "shown",
    "warn",
]


class UsageError(ValueError):
    """Bad input from the user: reported on stderr with exit code 2."""


#: the run specification's fields whose option is not their name: [regularisation]'s
#: ``model`` is ``--regularisation``
_OPTION_NAMES = {"model": "regularisation"}


def flag_of(field: str) -> str:
    """The command-line option of a field of the library (a
    :class:`~granular_material.errors.ParameterError`'s ``field``, a run specification's flat
    name): ``max_strain_per_step`` → ``--max-strain-per-step``. The one place where the
    library's names become the command line's."""
    return f"--{_OPTION_NAMES.get(field, field).replace('_', '-')}"


#: how a library message names a field beside its own: in backquotes, ```convergence```, or
#: with its value as a keyword, ```radius_min`` = 0.008` (on the command line
#: ``--radius-min 0.008``)
_FIELD_IN_MESSAGE = re.compile(r"`([A-Za-z][A-Za-z0-9_]*)`( = )?")


def as_flags(text: str) -> str:
    """``text`` with every field in backquotes named as its option."""
    return _FIELD_IN_MESSAGE.sub(lambda m: flag_of(m.group(1)) + (" " if m.group(2) else ""),
                                 text)


def shown(exc: ParameterError) -> str:
    """A library ParameterError as the command line shows it: its field as the option, and
    every other field its message names in backquotes too (``reuse_tol 0.01 needs
    `convergence` force`` → ``--reuse-tol 0.01 needs --convergence force``); a
    :class:`~granular_material.checks.WordedError` is the sentence alone."""
    text = exc.message if isinstance(exc, checks.WordedError) else f"`{exc.field}` {exc.message}"
    return as_flags(text)


def message_of(exc: BaseException) -> str:
    """What the command line says of ``exc``: a library ParameterError as :func:`shown`
    (a run specification's SpecError is named by the scene or command that read it), any
    other error as its message."""
    if isinstance(exc, ParameterError):
        from granular_material.runs.spec_checks import SpecError

        if not isinstance(exc, SpecError):
            return shown(exc)
    return str(exc)


@contextlib.contextmanager
def _as_option(option: str | None) -> Iterator[None]:
    """ParameterErrors of the block as UsageErrors naming the option: ``option`` (a flag, or
    words saying what set the value) in place of the field's own; None: the field's."""
    try:
        yield
    except checks.WordedError as exc:
        raise UsageError(shown(exc)) from None
    except ParameterError as exc:
        if option is None:
            raise UsageError(shown(exc)) from None
        raise UsageError(f"{option} {as_flags(exc.message)}") from None


def check_output_file(path: Path | None, option: str = "--out") -> None:
    """Before any work: the output file ``path`` (None: none) can be written
    (:func:`granular_material.checks.check_output_file`); a UsageError naming ``option``."""
    with _as_option(option):
        checks.check_output_file(path)


def check_output_dir(path: Path | None, option: str = "--out") -> None:
    """Before any work: the output folder ``path`` (None: none) is one or can be made, and
    written in (:func:`granular_material.checks.check_output_dir`); a UsageError naming
    ``option``."""
    with _as_option(option):
        checks.check_output_dir(path)


def rve_file_shape(path: Path, option: str = "--rve") -> tuple[int, int]:
    """(B, N) of the RVE file ``path`` (:func:`granular_material.checks.rve_file_shape`); a
    UsageError naming ``option`` where it does not exist."""
    with _as_option(option):
        return checks.rve_file_shape(path)


def check_memory(needed: float, what: str) -> None:
    """:func:`granular_material.checks.check_memory` (``what``: the options, in words), its
    refusal a UsageError."""
    try:
        checks.check_memory(needed, what)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def packing_parameters(args: argparse.Namespace, particles: int, pressure: float,
                       pressure_option: str = "--pressure") -> Any:
    """The RVE material options of ``args`` as
    :class:`~granular_material.procedures.packing.PackingParameters`
    (:func:`granular_material.checks.packing_parameters`); a UsageError naming the options
    (the pressure as ``pressure_option``)."""
    field = pressure_option.removeprefix("--").replace("-", "_")
    with _as_option(None):
        return checks.packing_parameters(dem_renamed(args), particles, pressure, field)


def dem_renamed(args: argparse.Namespace) -> argparse.Namespace:
    """``args`` with the deprecated RVE material options of a DEM command (``--young``,
    ``--friction-angle``: :func:`granular_material.vocabulary.renames` of ``dem``) given
    read as their new ones, with a warning; one given beside its new one (not at its
    default) is refused."""
    old = {name: getattr(args, name) for name in renames("dem")
           if getattr(args, name, None) is not None}
    if not old:
        return args
    new = {rename.new: getattr(args, rename.new) for name, rename in renames("dem").items()
           if name in old and getattr(args, rename.new) != RVE_MATERIAL_DEFAULTS[rename.new]}
    values = renamed({**new, **old}, "dem")
    return argparse.Namespace(**{**vars(args), **{k: None for k in old}, **values})


def positive(text: str) -> float:
    """argparse type: a positive finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value


def add_device(parser: argparse.ArgumentParser, what: str = "warp device") -> None:
    """``--device cpu|cuda`` (default None: CUDA when present, else CPU)."""
    parser.add_argument("--device", choices=["cpu", "cuda"], default=None,
                        help=f"{what} (default: CUDA when present, else CPU)")


def add_element(parser: argparse.ArgumentParser, advanced: bool = False) -> None:
    """``--element`` and ``--quadrature`` of the FEM commands (a group of their own; one
    that only ``--help-all`` shows where ``advanced``)."""
    from granular_material.fem.boundary_value.biaxial import ELEMENTS

    g = (parser.add_argument_group("finite elements", advanced=True) if advanced
         else parser.add_argument_group("finite elements"))
    g.add_argument("--element", choices=tuple(ELEMENTS), default="quad4",
                   help="quad4: bilinear, 4 nodes, 2x2 Gauss points (full; default); quad8: "
                        "serendipity, 8 nodes (midside nodes), 2x2 Gauss points: REDUCED "
                        "integration (full is 3x3), as in Guo & Zhao's FEMxDEM biaxial: "
                        "4 RVEs per element instead of 9, at the risk of one spurious zero-"
                        "energy (hourglass) mode per element, which does not spread through "
                        "a mesh of more than one element but may show as a checkerboard in a "
                        "softening band; quad9: biquadratic Lagrange, 9 nodes, 3x3 (full); "
                        "tri3 / tri6: each rectangle cut into two linear (1 point) or "
                        "quadratic (3 points) triangles (full). One RVE per Gauss point")
    g.add_argument("--quadrature", type=positive_int, default=None, metavar="N",
                   help="Gauss points per direction of every quadrilateral, 1 to 10 (N x N "
                        "points, one RVE each), or per triangle (1, 3, 6, 7 or 12), "
                        "overriding the element's default (quad4 2, quad8 2, quad9 3, tri3 1, "
                        "tri6 3); fewer than the default under-integrates (quad4 with 1: "
                        "two hourglass modes per element)")


def add_convergence(group: Any, default: str | None = "force", rtol: float | None = 0.005,
                    ) -> None:
    """``--convergence`` of the FEM commands' Newton solver, in ``group`` (``default`` None:
    residual-displacement for a noisy (DEM) material, force for any other)."""
    from granular_material.fem.solver.newton import CONVERGENCE_TESTS

    said = (default if default is not None
            else "residual-displacement for dem, force for linear-elastic and mohr-coulomb")
    group.add_argument("--convergence", choices=CONVERGENCE_TESTS, default=default,
                       help=f"Newton convergence test (default {said}). force: "
                            "||R||/||R0|| <= --rtol, or ||R|| below the --stress-tol floor; "
                            "displacement (Guo & Zhao): ||du||/||Du|| <= --rtol, du the Newton "
                            "correction of the iteration, Du the increment of the load step so "
                            "far, L2 norms over the specimen; the material is evaluated once "
                            "more after the accepted correction (at least 2 evaluations per "
                            "increment) and --stress-tol is not used (Guo & Zhao: --rtol "
                            "0.01); residual-displacement: the same ratio of the correction "
                            "the current iterate asks for, which is then not applied: that "
                            "iterate, already evaluated, is accepted (one material evaluation "
                            "an increment fewer"
                            + ("" if rtol is None else f"; default --rtol {rtol:g} in every "
                               "test") + "). "
                            "steps.csv records which test accepted each step (converged_by)")


def add_dtype(parser: argparse.ArgumentParser) -> None:
    """``--dtype float64|float32`` of the DEM."""
    from granular_material.dem.kernels.sets import DTYPES

    parser.add_argument("--dtype", choices=DTYPES, default="float64",
                        help="floating-point precision of the DEM (default: float64)")


def add_progress(parser: argparse.ArgumentParser) -> None:
    """``--progress/--no-progress`` (default: when stderr is a terminal)."""
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                        help="progress bars on stderr (default: when stderr is a terminal)")


def add_json(parser: argparse.ArgumentParser, what: str = "the key results") -> None:
    """``--json``: the report as JSON on stdout."""
    parser.add_argument("--json", action="store_true", help=f"print {what} as JSON on stdout")


def add_out(parser: argparse.ArgumentParser, help: str, default: Path | None = None) -> None:
    """``--out PATH`` (a file or a folder, as ``help`` says)."""
    parser.add_argument("--out", type=Path, default=default, help=help)


def add_max_dem_steps(parser: argparse.ArgumentParser | argparse._ArgumentGroup, what: str,
                      default: int = DEFAULT_MAX_DEM_STEPS, help: str | None = None) -> None:
    """``--max-dem-steps N`` (an integer >= 1; :data:`DEFAULT_MAX_DEM_STEPS` unless
    ``default`` says): the most DEM steps ``what`` may take, checked before work (or
    ``help``, the whole help text, where the caller says it otherwise)."""
    parser.add_argument("--max-dem-steps", type=positive_int, default=default,
                        help=help or f"the most DEM steps {what} may take; a run needing more "
                                     f"is refused before it starts (default {default:.0e})")


def add_rve_material_options(parser: argparse.ArgumentParser | argparse._ArgumentGroup,
                             defaults: bool = True, old_names: bool = False) -> None:
    """The material of prepared RVEs and how they are packed (e0, radii, contact law,
    friction, damping, density, thickness): ``prepare`` and the FEM commands take the same;
    :func:`packing_parameters` turns them into :class:`PackingParameters`. With ``defaults``
    False each defaults to None (its default is the material's, applied where the DEM
    settings are built, and shown in the help), so an option given at its default value
    still counts as given: refused beside a material that prepares no RVEs. ``old_names``
    (a command whose material is the DEM's alone, ``prepare``): the deprecated
    ``--friction-angle`` and ``--young`` are read too, as ``--contact-friction-angle`` and
    ``--contact-young`` (:func:`packing_parameters` renames them, with a warning)."""
    d = RVE_MATERIAL_DEFAULTS

    def default(name: str) -> Any:
        return d[name] if defaults else None

    parser.add_argument("--target-void-ratio", type=positive, default=default("target_void_ratio"),
                        help="first compress the gas to this 2D void ratio (Wu et al.: 0.18)")
    parser.add_argument("--radius-min", type=positive, default=default("radius_min"),
                        help=f"[m] ({d['radius_min']:g})")
    parser.add_argument("--radius-max", type=positive, default=default("radius_max"),
                        help=f"[m] ({d['radius_max']:g})")
    parser.add_argument("--law", choices=["constant", "frictmat"], default=default("law"),
                        help=f"contact stiffness law (constant: Wu et al. Table 1; default "
                             f"{d['law']})")
    parser.add_argument("--kn", type=positive, default=default("kn"),
                        help=f"normal stiffness [N/m] ({d['kn']:g})")
    parser.add_argument("--kt", type=positive, default=default("kt"),
                        help=f"tangential stiffness [N/m] ({d['kt']:g})")
    parser.add_argument("--contact-young", type=positive, default=default("contact_young"),
                        metavar="PA",
                        help="--law frictmat: the discs' Young's modulus [Pa], which sets the "
                             "contact stiffness kn = 2E r1 r2/(r1 + r2) "
                             f"({d['contact_young']:g}; not a continuum's --young)")
    parser.add_argument("--kt-over-kn", type=positive, default=default("kt_over_kn"),
                        help=f"FrictMat kt/kn ({d['kt_over_kn']:g})")
    parser.add_argument("--contact-friction-angle", type=float, metavar="RAD",
                        default=default("contact_friction_angle"),
                        help="the contacts' friction angle [rad] "
                             f"({d['contact_friction_angle']:g})")
    if old_names:  # deprecated, not shown: read as the new ones (packing_parameters)
        for old in renames("dem"):
            parser.add_argument(flag_of(old), type=float, default=None,
                                help=argparse.SUPPRESS)
    parser.add_argument("--damping", type=float, default=default("damping"),
                        help=f"local damping ({d['damping']:g})")
    parser.add_argument("--density", type=positive, default=default("density"),
                        help=f"[kg/m³] ({d['density']:g})")
    parser.add_argument("--thickness", type=positive, default=default("thickness"),
                        help=f"disc thickness [m] ({d['thickness']:g})")


def progress_enabled(args: argparse.Namespace) -> bool:
    """Whether to show progress bars: ``--progress/--no-progress``, else stderr is a tty."""
    return sys.stderr.isatty() if args.progress is None else bool(args.progress)


def scalar_or_list(values: np.ndarray) -> Any:
    """A batch of B values as a JSON value: the value itself when B = 1, else a list."""
    values = np.asarray(values)
    listed = values.tolist()
    return listed[0] if values.shape[0] == 1 else listed


#: callables that are handed every report :func:`emit` makes (see :func:`reports_to`)
_REPORT_SINKS: list[Callable[[dict[str, Any]], None]] = []


@contextlib.contextmanager
def reports_to(sink: Callable[[dict[str, Any]], None]) -> Iterator[None]:
    """While the block runs, every report :func:`emit` makes is also handed to ``sink``, as
    the dict the command reported (``granular-material run`` keeps it as summary.json)."""
    _REPORT_SINKS.append(sink)
    try:
        yield
    finally:
        _REPORT_SINKS.remove(sink)


#: the command that continues the run in hand where it is no command line's own (a scene's)
_RESUME_WITH: list[str] = []


@contextlib.contextmanager
def resumed_with(command: str) -> Iterator[None]:
    """While the block runs, a stopped run says ``command`` continues it (a scene's
    ``granular-material run SCENE --resume``) instead of its own options with ``--resume``."""
    _RESUME_WITH.append(command)
    try:
        yield
    finally:
        _RESUME_WITH.pop()


def resume_hint() -> str | None:
    """The command of :func:`resumed_with` in force, None where there is none."""
    return _RESUME_WITH[-1] if _RESUME_WITH else None


def emit(args: argparse.Namespace, result: dict[str, Any]) -> None:
    """Report ``result`` on stdout: JSON with ``--json``, else one aligned line per key (and
    to the sinks of :func:`reports_to`)."""
    for sink in tuple(_REPORT_SINKS):
        sink(result)
    if args.json:
        json.dump(result, sys.stdout, indent=2, default=str)
        sys.stdout.write("\n")
    else:
        for key, value in result.items():
            print(f"{key:>24}: {value}")


def warn(args: argparse.Namespace, message: str) -> str:
    """Say ``message`` on stderr as a warning of the command; returns it (for ``warnings``)."""
    print(f"granular-material {args.command}: warning: {message}", file=sys.stderr)
    return message


def check_figure_file(path: Path | None, option: str = "--plot",
                      others: dict[str, Path | None] | None = None) -> None:
    """Before any work: the figure file ``path`` (None: none) can be written, in a format
    matplotlib writes (its suffix), and is none of the command's ``others`` output files
    (option: path), which it would overwrite."""
    if path is None:
        return
    check_output_file(path, option)
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    suffix = Path(path).suffix.lower().removeprefix(".")
    if suffix not in formats:
        raise UsageError(f"{option} {path}: a figure is written as one of "
                         f"{', '.join('.' + f for f in sorted(formats))} (its suffix), not "
                         f"{'.' + suffix if suffix else 'a file without suffix'}")
    for name, other in (others or {}).items():
        if other is not None and Path(other).resolve() == Path(path).resolve():
            raise UsageError(f"{option} {path} and {name} {other} name the same file; give "
                             "each its own")


