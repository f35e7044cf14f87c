"""``granular-material run SCENE`` for a boundary-value problem (``test = "boundary-value"``):
the scene is read whole into a
:class:`~granular_material.runs.boundary_value.spec.BoundaryValueSpec`
(a refusal names the key and its line, exit 2, nothing written), then run into its folder
(:func:`~granular_material.runs.boundary_value.runner.run_boundary_value`), the scene copied in as
``scene.toml`` once every check has passed and the run starts (a refused run changes
nothing in the folder)."""

from __future__ import annotations

import argparse
import re
import shlex
import sys
from pathlib import Path
from typing import Any

from granular_material.cli.options import UsageError, as_flags, check_output_dir, emit
from granular_material.cli.signals import interrupt_exit_code
from granular_material.filesafe import write_whole
from granular_material.results.lock import FolderLock
from granular_material.runs.run_folder import when_starting
from granular_material.runs.spec_checks import SpecError

__all__ = ["BOUNDARY_VALUE", "run_bvp_scene"]

#: the ``test`` of a boundary-value scene
BOUNDARY_VALUE = "boundary-value"


def _line_of(text: str, key: str, entry: tuple[str, int] | None = None) -> int | None:
    """The line of the scene's text where ``key`` (the last part of a dotted name) is set;
    ``entry`` = (array, index): within the index-th ``[[array]]`` table (from its header,
    its sub-tables such as ``[materials.parameters]`` included)."""
    name = key.rsplit(".", 1)[-1].replace("_", "[-_]")
    pattern = re.compile(rf"^\s*{name}\s*=")
    lines = list(enumerate(text.splitlines(), start=1))
    if entry is not None:
        header = re.compile(rf"^\s*\[\[\s*{re.escape(entry[0])}\s*\]\]")
        starts = [k for k, (_, line) in enumerate(lines) if header.match(line)]
        if entry[1] >= len(starts):
            return None
        lines = lines[starts[entry[1]] + 1:]
        # its sub-tables ([materials.parameters], [phases.gravity], [[phases.conditions]])
        own = re.compile(rf"^\s*\[\[?\s*{re.escape(entry[0])}\.")
        ends = [k for k, (_, line) in enumerate(lines)
                if line.lstrip().startswith("[") and not own.match(line)]
        lines = lines[:ends[0]] if ends else lines
    for number, line in lines:
        if pattern.match(line):
            return number
    return None


def _refusal(path: Path, text: str, exc: ValueError) -> UsageError:
    key = getattr(exc, "field", None)
    line = _line_of(text, key, getattr(exc, "entry", None)) if key else None
    where = f"{path}, line {line}" if line else f"{path}"
    named = f"{key}: " if key and key not in str(exc) else ""
    return UsageError(f"{where}: {named}{exc}")


def _run_folder(path: Path, data: dict[str, Any], out: Path | None) -> Path:
    if out is not None:
        folder = Path(out).expanduser()
        check_output_dir(folder, "--out")
        return folder
    given = data.get("out") or (data.get("output") or {}).get("out")
    if given is None:
        folder = Path(path.stem)
        check_output_dir(folder, "the run folder (the scene's name; set out or --out)")
        return folder
    folder = path.parent / Path(str(given)).expanduser()
    check_output_dir(folder, "out")
    return folder


def run_bvp_scene(path: Path, text: str, data: dict[str, Any],
                  args: argparse.Namespace) -> int:
    """Check and run the boundary-value scene ``path`` (``data``: its TOML); the exit code
    (0: it reached the end, 1: it stopped short). ``args``: the ``run`` command's (``out``,
    ``check``, ``resume``: continue a stopped run in the same folder); stopped by Ctrl-C,
    SIGTERM or SIGHUP: 130, 143 or 129, with the command that continues it on stderr."""
    from granular_material.runs.boundary_value.resume import check_not_stopped
    from granular_material.runs.boundary_value.runner import build, run_boundary_value
    from granular_material.runs.boundary_value.spec import bvp_from_dict

    resume = bool(getattr(args, "resume", False))
    try:
        spec = bvp_from_dict(data, path.parent)
        if args.check:
            build(spec, allocate=False)  # mesh, boundaries, conditions, material: no step
            what = (f"material {spec.material.name}" if spec.materials is None else
                    "materials " + ", ".join(f"{m.region}: {m.material.name}"
                                             for m in spec.materials))
            phases = (f" in {len(spec.phases)} phases ("
                      + ", ".join(f"{p.name}: {p.steps}" for p in spec.phases) + ")"
                      if spec.phases else "")
            print(f"{path}: a boundary-value problem of {spec.steps} steps{phases}, {what}: "
                  "checked")
            return 0
    except ValueError as exc:
        raise _refusal(path, text, exc) from exc
    folder = _run_folder(path, data, args.out)

    def copy_scene() -> None:  # once every check has passed and the run starts writing
        folder.mkdir(parents=True, exist_ok=True)
        write_whole(folder / "scene.toml", lambda tmp: tmp.write_text(text, encoding="utf-8"))

    with FolderLock(folder), when_starting(copy_scene):
        if not resume:
            try:
                check_not_stopped(spec, folder)
            except SpecError as exc:  # `resume` is the run command's --resume
                raise UsageError(as_flags(f"{path}: {exc.message}")) from None
        try:
            outcome = run_boundary_value(spec, out=folder, resume=resume)
        except ValueError as exc:
            raise _refusal(path, text, exc) from exc
    emit(argparse.Namespace(json=False), outcome.summary)
    if outcome.interrupt is not None:  # Ctrl-C, SIGTERM, SIGHUP: the shell's code, and how on
        print(f"error: {outcome.error}", file=sys.stderr)
        again = shlex.join(["granular-material", "run", str(path),
                            *(["--out", str(args.out)] if args.out is not None else []),
                            "--resume"])
        print(f"continue it with `{again}`", file=sys.stderr)
        return interrupt_exit_code(outcome.interrupt)
    if outcome.error:
        print(f"error: {outcome.error}", file=sys.stderr)
        return 1
    return 0
