"""The FEM commands ``single-element`` and ``biaxial``: their options, the run
specification they make of them (:func:`spec_from_args`) and its report; the run itself is
:func:`granular_material.runs.run`."""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from granular_material.cli.fem_options import DEFAULT_MATERIAL, add_fem_commands
from granular_material.cli.material_options import (
    check_material_options,
    material_file_values,
)
from granular_material.cli.options import (
    RVE_MATERIAL_DEFAULTS,
    UsageError,
    emit,
    flag_of,
    progress_enabled,
    resume_hint,
    shown,
)
from granular_material.cli.parsers import CommandParser
from granular_material.cli.signals import interrupt_exit_code
from granular_material.errors import ParameterError
from granular_material.fem import load_material
from granular_material.runs import RunSpec, SpecError, from_flat, run, to_flat
from granular_material.runs.presets import preset_fields
from granular_material.vocabulary import renamed

__all__ = ["command_line", "register", "report", "run_biaxial_command", "run_single_element",
           "spec_from_args"]

#: the command parsers, for their defaults (:func:`_given`)
_PARSERS: dict[str, CommandParser] = {}


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``single-element`` and ``biaxial`` commands (their options:
    :mod:`granular_material.cli.fem_options`)."""
    parsers = add_fem_commands(subparsers)
    parsers["single-element"].set_defaults(func=run_single_element)
    parsers["biaxial"].set_defaults(func=run_biaxial_command)
    _PARSERS.update(parsers)


#: options that are the command line's own, no fields of the run spec
_CLI_ONLY = frozenset({"command", "func", "json", "resume", "preset", "material",
                       "material_file"})


def _given(args: argparse.Namespace) -> dict[str, Any]:
    """The options of ``args`` given other than at their defaults (flat spec names)."""
    parser = _PARSERS[args.command]
    return {k: v for k, v in vars(args).items()
            if k not in _CLI_ONLY and v != parser.get_default(k)}


def _check_rve_options(material: str, given: dict[str, Any]) -> None:
    """An RVE material option given (at its default value too: they default to None) with a
    material that prepares no RVEs, or beside an RVE file, which carries its own, is refused
    (the other options of another material are left unused)."""
    own = set(load_material(material).Parameters.__dataclass_fields__)
    rve_options = [flag_of(k) for k in given if k in RVE_MATERIAL_DEFAULTS and k not in own]
    sets = f"set{'s' if len(rve_options) == 1 else ''}"
    if rve_options:
        raise UsageError(f"{', '.join(rve_options)} {sets} the material of the RVEs a run "
                         f"prepares, but --material {material} has no RVEs")
    rve_options = [flag_of(k) for k in given if k in RVE_MATERIAL_DEFAULTS]
    sets = f"set{'s' if len(rve_options) == 1 else ''}"
    if rve_options and given.get("rve") is not None:
        raise UsageError(f"{', '.join(rve_options)} {sets} the material of the RVEs a run "
                         f"prepares, but --rve {given['rve']} carries its own (give them to "
                         "`granular-material prepare` instead)")


def spec_from_args(args: argparse.Namespace) -> RunSpec:
    """The run specification of a FEM command's options: its defaults, then the
    ``--preset``'s values, then every option given (not at its default); a value that cannot
    run is a UsageError naming its option."""
    material = getattr(args, "material", DEFAULT_MATERIAL)
    try:  # the material's old names (--phi, dem's --friction-angle): warned, read as new
        given = renamed(_given(args), material)
    except ParameterError as exc:
        raise UsageError(shown(exc)) from None
    flat: dict[str, Any] = {"test": args.command, "material": material}
    if args.preset is not None:
        if material != DEFAULT_MATERIAL:
            raise UsageError(f"--preset {args.preset} sets DEM and Newton settings; it needs "
                             f"--material {DEFAULT_MATERIAL}")
        flat.update(preset_fields(args.preset, confining=args.confining,
                                  with_discs=args.rve is None))
        flat["preset"] = args.preset
    _check_rve_options(material, given)
    check_material_options(material, given)
    if getattr(args, "material_file", None) is not None:
        flat.update(material_file_values(args.material_file, material))
    flat.update(given)
    if args.resume is not None:
        flat["out"] = args.resume
    flat["progress"] = progress_enabled(args)
    try:  # another material's options, given or not, are no fields of this run
        return from_flat(flat, strict=False)
    except SpecError as exc:
        raise UsageError(shown(exc)) from None


def report(args: argparse.Namespace, summary: dict[str, Any],
           interrupt: KeyboardInterrupt | None = None, resume_with: str | None = None) -> int:
    """Print the summary; the exit code: 0, 1 when the run stopped short, 130/143 when
    Ctrl-C or SIGTERM (``interrupt``) stopped it, with how to continue it (``resume_with``:
    the command that does, else ``--resume OUT`` with the same options)."""
    emit(args, summary)
    out = summary.get("out")
    if interrupt is not None:
        print(f"error: {summary['error']}", file=sys.stderr)
        if resume_with is not None:
            print(f"continue it with `{resume_with}`", file=sys.stderr)
        elif out is not None:
            print(f"continue it with --resume {out} and the same options", file=sys.stderr)
        return interrupt_exit_code(interrupt)
    if summary["error"]:
        print(f"error: {summary['error']}", file=sys.stderr)
        return 1
    return 0


def command_line(spec: RunSpec) -> str:
    """The command line of ``spec``: its command and an option for every field not at the
    command's default (the spec's own defaults where the command has no option)."""
    test = spec.problem.test
    if test not in _PARSERS:  # made with the command line's parser
        from granular_material.cli.commands import build_parser

        build_parser()
    parser = _PARSERS[test]
    dests = {a.dest: a for a in parser.arguments if a.option_strings}
    words = ["granular-material", test]
    flat = to_flat(spec)
    material = flat.pop("material")
    if material != DEFAULT_MATERIAL:
        words += ["--material", material]
    adaptive = spec.adaptivity is not None
    defaults = to_flat(from_flat({"test": test, "material": material,
                                  **({"adaptivity": True} if adaptive else {})}))
    defaults["adaptivity"] = False  # the settings' defaults are adaptivity's, the switch off
    # beside --shear-strain, --mobilised-fraction is given even at its default: alone,
    # --shear-strain is the only threshold
    both = adaptive and None not in (spec.adaptivity.shear_strain,
                                     spec.adaptivity.mobilised_fraction)
    for name, value in flat.items():
        action = dests.get(name)
        at_default = value == defaults.get(name) and not (both and name == "mobilised_fraction")
        if action is None or at_default or value is None:
            continue
        if isinstance(action, argparse.BooleanOptionalAction):  # --name or --no-name
            words += [action.option_strings[0 if value else 1]]
            continue
        if action.nargs == 0:  # a flag: given where the value is the one it stores
            words += [action.option_strings[-1]] if value == action.const else []
            continue
        flag = next(o for o in action.option_strings if o.startswith("--"))
        values = value if isinstance(value, list) else [value]
        words += [flag, *(str(v) for v in values)]
    return shlex.join(words)


def _check_resume_folder(args: argparse.Namespace) -> None:
    """``--resume DIR`` continues in DIR: an ``--out`` naming another folder is refused."""
    if args.resume is None or args.out is None:
        return
    if Path(args.out).resolve() != Path(args.resume).resolve():
        raise UsageError(f"--resume {args.resume} continues in that folder; --out {args.out} "
                         "names another (leave --out out)")


def _command(args: argparse.Namespace) -> int:
    _check_resume_folder(args)
    spec = spec_from_args(args)
    outcome = run(spec, resume=args.resume is not None, keep_stopped=True)
    # a scene's run is continued by `run SCENE --resume` (options.resumed_with)
    return report(args, outcome.summary, outcome.interrupt, resume_with=resume_hint())


def _on_backend(args: argparse.Namespace, command: Callable[[argparse.Namespace], int]) -> int:
    """``command`` as the material's ``--backend`` runs it: here, or with ``mpi`` on rank 0
    of the job while the other ranks serve its points (they write and print nothing)."""
    if args.backend == "inprocess":
        return command(args)
    material = load_material(getattr(args, "material", DEFAULT_MATERIAL))
    if not hasattr(material, "launch"):
        raise UsageError(f"--backend {args.backend} needs --material {DEFAULT_MATERIAL}")
    return material.launch(args.backend, lambda: command(args))


def run_single_element(args: argparse.Namespace) -> int:
    """The ``single-element`` command; returns the exit code."""
    return _on_backend(args, _command)


def run_biaxial_command(args: argparse.Namespace) -> int:
    """The ``biaxial`` command; returns the exit code."""
    return _on_backend(args, _command)
