"""The ``granular-material`` command line: the core commands plus plugin commands.

The core commands are registered here directly: ``prepare``, ``biaxial-dem`` and
``dem-drive`` (:mod:`granular_material.cli.dem`), ``single-element`` and ``biaxial``
(:mod:`granular_material.cli.fem`), ``run`` (:mod:`granular_material.cli.scene`: one of
them described by a TOML scene file), ``trade-study`` (:mod:`granular_material.cli.study`)
and ``calibrate`` (:mod:`granular_material.cli.calibrate`); their shared options are defined once in
:mod:`granular_material.cli.options`, the stop signals in :mod:`granular_material.cli.signals`.
Plugins add sub-commands through the ``granular_material.commands`` entry-point group; each
entry point is a ``register(subparsers)`` callable that adds its parsers and sets ``func`` (a
callable taking the parsed arguments and returning the exit code). warp prints nothing on
stdout (which ``--json`` keeps for the report): the package keeps it quiet
(:func:`granular_material.verbose`).
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
import warnings
from typing import Any

from granular_material import __version__
from granular_material.cli.parsers import CommandParser
from granular_material.cli.signals import interrupt_exit_code, stop_signals_as_interrupt
from granular_material.entry_points import entry_point_names, load_entry_point

#: the entry-point group of plugin commands (each a ``register(subparsers)`` callable)
COMMAND_GROUP = "granular_material.commands"

__all__ = ["UsageError", "build_parser", "entry", "main"]

#: the one-line help of every command, in the order of ``granular-material --help``: what
#: the top-level help shows without importing the commands (numpy, warp, scikit-fem,
#: matplotlib, scipy.stats, the plugins); tests check it against the full parser. A plugin
#: command missing here is listed by its entry point's name with a generic line.
COMMAND_HELP: dict[str, str] = {
    "prepare": "generate and consolidate periodic RVE packings",
    "biaxial-dem": "drained biaxial test of the RVE(s) of a file",
    "dem-drive": "apply a displacement gradient to the RVE(s) of a file",
    "single-element": "one element (Q4, 4 Gauss points, unless --element) in a drained "
                      "biaxial test",
    "biaxial": "biaxial specimen (50 mm x 100 mm) of DEM Gauss points",
    "run": "run the scene of a TOML file into one folder",
    "trade-study": "speed against accuracy: every knob against a reference run",
    "calibrate": "Mohr–Coulomb parameters from drained biaxial DEM tests of an RVE file",
    "fractal": "pore image and multifractal spectrum (D0, alpha0) of an RVE file",
    "reproduce": "rerun a paper's study: each claim beside our measurement",
    "rve-size-study": "how many discs an RVE needs: pore spectra and biaxial tests by size",
    "validate-yade": "cross-validate the DEM against YADE (needs Debian's yade)",
}
#: the module of :mod:`granular_material.cli` that registers each core command
_CORE_MODULES = {"prepare": "dem", "biaxial-dem": "dem", "dem-drive": "dem",
                 "single-element": "fem", "biaxial": "fem", "run": "scene",
                 "trade-study": "study", "calibrate": "calibrate"}
_CORE = tuple(_CORE_MODULES)
#: commands that run the others (a scene names any command): built with the full parser
_RUNS_OTHER_COMMANDS = frozenset({"run"})


def __getattr__(name: str) -> Any:  # UsageError, imported only when asked for (it is heavy)
    if name == "UsageError":
        from granular_material.cli.options import UsageError

        return UsageError
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _register_plugins(subparsers: argparse._SubParsersAction,
                      names: list[str] | None = None) -> None:
    """Register the plugin commands ``names`` (default: every one installed)."""
    for name in entry_point_names(COMMAND_GROUP) if names is None else names:
        try:
            register = load_entry_point(COMMAND_GROUP, name, "command")
        except ImportError as exc:
            warnings.warn(f"command plugin {name!r} could not be loaded: {exc}", stacklevel=2)
            continue
        register(subparsers)


def _top_parser() -> tuple[CommandParser, argparse._SubParsersAction]:
    parser = CommandParser(
        prog="granular-material",
        description="Multiscale FEM x DEM simulation of granular geomaterials.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    return parser, subparsers


def command_parser() -> CommandParser:
    """The top-level parser alone (commands listed with their one-line help, no options),
    built without importing any command: what ``granular-material --help``, ``--version``
    and a missing command use."""
    parser, subparsers = _top_parser()
    plugins = entry_point_names(COMMAND_GROUP)
    names = [n for n in COMMAND_HELP if n in _CORE or n in plugins]
    names += sorted(n for n in plugins if n not in COMMAND_HELP)
    for name in names:
        subparsers.add_parser(name, help=COMMAND_HELP.get(
            name, f"a plugin command (granular-material {name} --help)"))
    return parser


def _names_a_command(argv: list[str]) -> bool:
    """Whether ``argv`` reaches a command (a first argument that is not an option)."""
    return bool(argv) and not argv[0].startswith("-")


def build_parser(command: str | None = None) -> CommandParser:
    """The full argument parser, plugin commands included; with ``command`` (an installed
    command's name) only that command's, so that running or asking for the help of one
    command imports no other (the plugins' matplotlib and scipy.stats among them). An
    unknown name, and ``run`` (whose scenes name any command), get the full parser."""
    parser, subparsers = _top_parser()
    plugins = entry_point_names(COMMAND_GROUP)
    if command in _CORE_MODULES and command not in _RUNS_OTHER_COMMANDS:
        modules, names = [_CORE_MODULES[command]], []
    elif command in plugins:
        modules, names = [], [command]
    else:
        modules, names = list(dict.fromkeys(_CORE_MODULES.values())), plugins
    for module in modules:  # imported here: the top-level help imports light
        importlib.import_module(f"granular_material.cli.{module}").register(subparsers)
    _register_plugins(subparsers, names)
    return parser


#: exit codes of a command stopped by a signal (SIGHUP, Ctrl-C, SIGTERM)
_STOPPED_CODES = frozenset({128 + 1, 128 + 2, 128 + 15})


def _named(exc: BaseException) -> str:
    """The message of ``exc``; a library's ParameterError with its fields named as options
    (:func:`~granular_material.cli.options.message_of`)."""
    from granular_material.cli.options import message_of

    return message_of(exc)


def _usage_error() -> type[Exception]:
    from granular_material.cli.options import UsageError

    return UsageError


def entry() -> None:
    """The process's entry point (console script, ``python -m``): :func:`main`, then exit
    with its code. A command stopped by a signal ignores the stop signals of a storm that
    arrive after its reports, until the process has exited (they would kill it by the
    signal, without its exit code)."""
    code = main()
    if code in _STOPPED_CODES:
        for name in ("SIGTERM", "SIGHUP"):
            if hasattr(signal, name):
                signal.signal(getattr(signal, name), signal.SIG_IGN)
    sys.exit(code)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (2 for bad input, 1 for a failed run,
    130/143 for a run stopped by Ctrl-C/SIGTERM)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not _names_a_command(argv):  # --help, --version or nothing: no command to import
        command_parser().parse_args(argv)
    from granular_material.cli.stored_help import asks_for_help, print_stored

    option = asks_for_help(argv)  # a command's help: stored, the command not imported
    if option is not None and print_stored(argv[0], option):
        raise SystemExit(0)
    parser = build_parser(argv[0])
    if option == "--help-all" and not getattr(parser.commands.get(argv[0]), "_advanced", 1):
        argv = ["--help" if a == option else a for a in argv]  # all its options are shown
    args = parser.parse_args(argv)
    with stop_signals_as_interrupt():  # the reports below too: a later signal is ignored
        try:
            return int(args.func(args) or 0)
        except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM that the command did not catch
            code = interrupt_exit_code(exc)
            what = ("interrupted" if code == 130 else
                    f"terminated ({signal.Signals(code - 128).name})")
            print(f"granular-material {args.command}: {what} before its outputs "
                  "were complete", file=sys.stderr)
            return code
        except (_usage_error(), ValueError, OSError) as exc:
            print(f"granular-material {args.command}: error: {_named(exc)}", file=sys.stderr)
            return 2
        except RuntimeError as exc:  # e.g. DEMInstabilityError naming the RVEs
            print(f"granular-material {args.command}: failed: {exc}", file=sys.stderr)
            return 1
