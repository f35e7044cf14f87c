"""The parser of the ``granular-material`` command line: the core commands, registered here
by the module that defines each, and the plugin commands of the ``granular_material.commands``
entry-point group; the top-level parser alone lists them without importing any."""

from __future__ import annotations

import argparse
import importlib
import warnings

from granular_material import __version__
from granular_material.cli.parsers import CommandParser
from granular_material.entry_points import entry_point_names, load_entry_point

#: the entry-point group of plugin commands (each a ``register(subparsers)`` callable)
COMMAND_GROUP = "granular_material.commands"

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


def names_a_command(argv: list[str]) -> bool:
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
