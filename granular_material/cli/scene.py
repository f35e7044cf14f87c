"""``granular-material run SCENE``: one run described by a TOML scene file.

A scene names the command it runs (``test = "single-element"``) and sets that command's
options under their command-line names, dashes included (``axial-strain = 0.02``; a
positional argument by its name, ``rve = "rve.npz"``). The schema is not written down here:
it is read from the command's own argparse parser, so every option of a command is a scene
key, and its value is converted and checked by the parser's own ``type`` and ``choices``.
Tables (``[loading]``, ``[newton]``, ...) only group keys; their names are free.

The whole scene is checked before anything runs (a ``UsageError`` naming the key and its line:
exit 2, nothing written). Then the command's own function runs with the namespace, so every
check of the command applies as on the command line, into one folder per run: the scene
copied in as ``scene.toml`` once the command's checks have passed and its run starts
writing (:func:`granular_material.runs.run_folder.when_starting`; a refusal changes nothing
in the folder), the command's tables, figures and fields, and ``summary.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import re
import shlex
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from granular_material.cli.bvp import BOUNDARY_VALUE, run_bvp_scene
from granular_material.cli.options import (
    UsageError,
    message_of,
    reports_to,
    resumed_with,
)
from granular_material.cli.scene_keys import (
    command_parsers,
    scene_keys,
)
from granular_material.cli.scene_load import TESTS, Scene, load_scene
from granular_material.cli.scene_toml import read_toml
from granular_material.filesafe import write_whole
from granular_material.results import write_json
from granular_material.results.lock import FolderLock
from granular_material.runs.run_folder import when_starting

__all__ = ["TESTS", "Scene", "check_scene", "command_parsers", "load_scene", "register",
           "run_scene", "scene_keys"]

_SCENE_COPY = "scene.toml"
_SUMMARY = "summary.json"


# -- the run ---------------------------------------------------------------------------------
def _copy_scene(scene: Scene) -> None:
    """The scene copied into its run folder as ``scene.toml`` (the folder made)."""
    scene.run_dir.mkdir(parents=True, exist_ok=True)
    text = scene.path.read_bytes()
    write_whole(scene.run_dir / _SCENE_COPY, lambda tmp: tmp.write_bytes(text))


def _write_summary(folder: Path, report: dict[str, Any]) -> None:
    """``report`` as ``folder/summary.json``, whole or not at all."""
    write_json(report, folder / _SUMMARY)


def _located(scene: Scene, message: str) -> str:
    """``message`` of the command, with the scene's line of the first option it names."""
    for flag in re.findall(r"--([A-Za-z][A-Za-z0-9_-]*)", message):
        name = flag.replace("-", "_")  # the scene key of the option (snake_case)
        if name in scene.lines:
            return f"{scene.path}, line {scene.lines[name]}: {message}"
    return f"{scene.path}: {message}"


def run_scene(scene: Scene) -> int:
    """Run the checked ``scene`` into its run folder; returns the command's exit code."""
    reports: list[dict[str, Any]] = []
    namespace = scene.namespace
    # one writer per run folder: the FEM commands lock their --out themselves; a DEM
    # command's scene is locked here, its summary.json included
    with contextlib.ExitStack() as stack:
        if TESTS[scene.test] is not None:
            stack.enter_context(FolderLock(scene.run_dir))
        # the scene is copied in when the run starts writing, after every check of the
        # command has passed: a refused run leaves the folder as it was
        try:
            with when_starting(lambda: _copy_scene(scene)) as copied, \
                    reports_to(reports.append), resumed_with(scene.resume_with):
                code = int(namespace.func(namespace) or 0)
        except ValueError as exc:  # the command's own checks: say where the scene set it
            raise UsageError(_located(scene, message_of(exc))) from exc
        if not copied():  # a command that never said it started (it ran all the same)
            _copy_scene(scene)
        # the FEM commands write summary.json into their folder themselves; the DEM
        # commands, whose --out is a file, report on stdout only: their report is kept here
        if TESTS[scene.test] is not None and reports:
            _write_summary(scene.run_dir, reports[-1])
    return code


#: the tests whose options make a run specification (checked whole by ``run --check``)
_SPEC_TESTS = frozenset({"single-element", "biaxial"})


def check_scene(scene: Scene) -> None:
    """What ``run`` checks before any work, without running: the scene's keys (done by
    :func:`load_scene`) and, for a FEM or DEM test, its run specification as the run makes
    it (:func:`granular_material.runs.check`: the material's inputs, memory, output folder).
    A refusal is a UsageError naming the scene's line where it can."""
    from granular_material.cli.dem import check_args
    from granular_material.runs.dem import DEM_TESTS

    try:
        if scene.test in DEM_TESTS:  # a DEM run's spec, checked as the command checks it
            check_args(scene.namespace)
            return
        if scene.test not in _SPEC_TESTS:
            return
        from granular_material.cli.fem import spec_from_args
        from granular_material.runs import check

        check(spec_from_args(scene.namespace))
    except ValueError as exc:
        raise UsageError(_located(scene, message_of(exc))) from exc


def _spec_error(path: Path, text: str, exc: ValueError) -> UsageError:
    """A run spec file's refusal, with the line of the field it names (where one is); the
    command-line options a library check names (``--rve``) are named as the file's fields
    (``rve``)."""
    name = getattr(exc, "field", None)
    message = str(exc)
    if name is None:
        options = re.findall(r"--([a-z][a-z0-9-]*)", message)
        name = options[0].replace("-", "_") if options else None
        message = re.sub(r"--([a-z][a-z0-9-]*)", lambda m: m.group(1).replace("-", "_"),
                         message)
        exc = ValueError(message)
    pattern = re.compile(rf"^\s*{re.escape(name)}\s*=") if name else None
    table = re.compile(rf"^\s*\[\s*([\w.]*\.)?{re.escape(name)}\s*\]") if name else None
    for want in (pattern, table):  # the field's line, else its table's header
        for number, line in enumerate(text.splitlines(), start=1):
            if want is not None and want.match(line):
                return UsageError(f"{path}, line {number}: {exc}")
    return UsageError(f"{path}: {exc}")


def _run_spec_file(path: Path, text: str, data: dict[str, Any],
                   args: argparse.Namespace) -> int:
    """``run SPEC.toml``: a run specification in its nested form (``[problem]``,
    ``[material]``, ...; what :func:`granular_material.runs.save` writes) checked whole, then
    run (``--check``: only checked, and shown as a command line)."""
    from dataclasses import replace

    from granular_material.cli.fem import command_line, report
    from granular_material.runs import check, from_dict, run
    from granular_material.runs.dem import is_dem

    if is_dem(data):  # a DEM run's spec ([problem] test = "prepare", ...)
        from granular_material.cli.dem import run_spec_file

        return run_spec_file(path, text, data, args, _spec_error)
    try:
        spec = from_dict(data)
    except ValueError as exc:
        raise _spec_error(path, text, exc) from exc
    # the run folder: --out, else the spec's output.out, else (as a scene's) the file's name
    # in the current folder: a run from the command line never writes nothing
    if args.out is None and spec.output.out is None and not path.is_file():
        raise UsageError(f"{path} names no output folder (output.out) and is no file to "
                         "name one after (a pipe?): give --out DIR")
    out = args.out if args.out is not None else spec.output.out or Path(path.stem)
    try:
        spec = spec.replace(output=replace(spec.output, out=out))
        check(spec)
    except (ValueError, FileNotFoundError) as exc:
        raise _spec_error(path, text, exc) from exc
    if args.check:
        print(command_line(spec))
        return 0
    if args.out is None and "out" not in (data.get("output") or {}):
        print(f"granular-material run: {path} names no output folder (output.out); the run "
              f"writes into {out}", file=sys.stderr)
    outcome = run(spec, resume=args.resume, keep_stopped=True)
    again = shlex.join(["granular-material", "run", str(path),
                        *(["--out", str(args.out)] if args.out is not None else []),
                        "--resume"])
    return report(argparse.Namespace(json=False), outcome.summary, outcome.interrupt,
                  resume_with=again)


def _check_test_spelling(path: Path, text: str, test: Any) -> None:
    """A UsageError at the line of ``test`` where it names a test but for its case or its
    underscores (``"Boundary-Value"``), before the rest of the scene is read as that of
    another test."""
    if not isinstance(test, str) or test == BOUNDARY_VALUE or test in TESTS:
        return
    meant = test.strip().lower().replace("_", "-")
    if meant != BOUNDARY_VALUE and meant not in TESTS:
        return
    line = next((k for k, row in enumerate(text.splitlines(), start=1)
                 if re.match(r"\s*test\s*=", row)), None)
    where = f"{path}, line {line}" if line else f"{path}"
    raise UsageError(f"{where}: test {test!r} is no test: did you mean {meant!r}? (a test "
                     "is named in lower case, with dashes)")


def _run_command(parsers: Mapping[str, argparse.ArgumentParser], args: argparse.Namespace,
                 ) -> int:
    text, data = read_toml(Path(args.scene))
    if "problem" in data:  # a run specification (a scene has no such key)
        return _run_spec_file(Path(args.scene), text, data, args)
    _check_test_spelling(Path(args.scene), text, data.get("test"))
    if data.get("test") == BOUNDARY_VALUE:
        return run_bvp_scene(Path(args.scene), text, data, args)
    scene = load_scene(args.scene, parsers, out=args.out, resume=args.resume)
    if args.check:
        check_scene(scene)
        print(scene.command_line())
        return 0
    return run_scene(scene)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``run`` command (its scene tests are the commands registered beside it)."""
    tests = ", ".join(f'"{t}"' for t in TESTS)
    p = subparsers.add_parser(
        "run", help="run the scene of a TOML file into one folder",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=f"""\
Run one scene: a TOML file naming the command it runs (test = one of
{tests})
and that command's options under their command-line names, e.g.

    test = "single-element"
    particles = 64
    axial-strain = 0.02   # SI values, no unit names
    steps = 10
    device = "cpu"

The scene is checked whole before anything runs: an unknown key, a wrong type or
a missing required key exits with code 2, naming the key and its line, and writes
nothing. Paths in a scene are relative to its folder. The run folder (--out, else
the scene's `out`, else the scene's name in the current folder) gets the scene as
scene.toml, the command's tables, figures and fields, and summary.json.

A file with a [problem] table is a run specification instead (the nested form
that granular_material.runs.save writes and a run's checkpoint keeps): its
[problem], [material] (name, [material.parameters]), [newton] and [output]
tables hold the spec's fields by their Python names; it is checked whole and run
as it is (--out overrides its output.out). So is a DEM run's spec, whose
[problem] has test = "prepare", "biaxial-dem" or "dem-drive" (what
granular_material.runs.dem.save writes).

A scene with test = "boundary-value" is a boundary-value problem: a mesh (a
file or a generated rectangle), named boundaries, conditions on them
([[conditions]]: fixed, roller, displacement, rigid, pressure), gravity, an
initial state (uniform or geostatic) and a material; see
examples/scenes/footing-*.toml and docs/guide/boundary-value.md.""",
    )
    p.add_argument("scene", type=Path, help="the scene file (.toml)")
    p.add_argument("--out", type=Path, default=None, metavar="DIR",
                   help="the run folder (overrides the scene's out)")
    p.add_argument("--resume", action="store_true",
                   help="continue the stopped or killed run in the run folder from its last "
                        "checkpoint (single-element, biaxial, biaxial-dem, dem-drive, "
                        "boundary-value); a folder with no stopped run: the run starts there")
    p.add_argument("--check", action="store_true",
                   help="check the scene as the run would (for single-element, biaxial and "
                        "the DEM tests: its whole run specification) and print the same run "
                        "as a command line; run nothing, write nothing")
    p.set_defaults(func=lambda args: _run_command(subparsers.choices, args))
