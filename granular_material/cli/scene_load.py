"""A scene file read and checked whole (:func:`load_scene`): its ``test`` (the command it
runs), each key converted and checked by that command's own parser (its ``type`` and
``choices``), the files it reads and the run folder it writes; a refusal is a
``UsageError`` naming the key and its line. Running it is :mod:`granular_material.cli.scene`'s.
"""

from __future__ import annotations

import argparse
import shlex
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from granular_material.cli.options import (
    UsageError,
    check_output_dir,
)
from granular_material.cli.scene_keys import (
    command_parsers,
    convert,
    help_of,
    kind_of,
    scene_keys,
    suggest,
)
from granular_material.cli.scene_toml import Where, flatten, line_of, read_toml, toml_repr
from granular_material.vocabulary import RenamedWarning, key_of, user_stacklevel

__all__ = ["TESTS", "Scene", "load_scene"]

#: the commands a scene can run (its ``test``), each with the file its ``--out`` names inside
#: the run folder; None: its ``--out`` is the run folder itself
TESTS: dict[str, str | None] = {
    "single-element": None,
    "biaxial": None,
    "biaxial-dem": "curve.csv",
    "dem-drive": "path.csv",
    "prepare": "rve.npz",
    "rve-size-study": None,  # the reproduction plugin's
}
#: files a test writes beside its table when the scene names none, inside the run folder
_DEFAULT_FILES: dict[str, dict[str, str]] = {"biaxial-dem": {"plot": "curve.png"}}
#: path keys that name files the run writes: relative to the run folder (other path keys
#: name files the run reads: relative to the scene's folder, and they must exist)
_RUN_FOLDER_KEYS = frozenset({"plot"})
#: options that are no scene keys, and what to do instead
_NOT_KEYS = {
    "resume": "a scene describes a run; continue a stopped one with "
              "`granular-material run SCENE --resume` (same --out)",
}


@dataclass
class Scene:
    """A checked scene: the command it runs, its parsed options and where it writes."""

    path: Path                       #: the scene file
    test: str                        #: the command (sub-command name)
    namespace: argparse.Namespace    #: the options, as the command's parser would give them
    run_dir: Path                    #: the run folder
    resume_with: str = ""            #: the command that continues a stopped run of it
    argv: list[str] = field(default_factory=list)  #: the same run as a command line
    lines: dict[str, int] = field(default_factory=dict)  #: key → its line in the file

    def command_line(self) -> str:
        """The equivalent ``granular-material`` command line."""
        return shlex.join(["granular-material", self.test, *self.argv])


# -- the scene's test ---------------------------------------------------------------------
def _test_of(entries: list[tuple[tuple[str, ...], Any]], where: Where,
             parsers: Mapping[str, argparse.ArgumentParser]) -> str:
    tests = [t for t in TESTS if t in parsers]
    given = [(p, v) for p, v in entries if p[-1] == "test"]
    if not given:
        raise where.error((), f"missing key 'test': the command this scene runs, one of "
                              f"{', '.join(tests)}")
    if len(given) > 1:
        raise where.error(given[1][0], "'test' is given twice")
    path, value = given[0]
    if not isinstance(value, str) or value not in tests:
        hint = suggest(value, tests) if isinstance(value, str) else ""
        raise where.error(path, f"'test' must be one of {', '.join(tests)}; got "
                                f"{toml_repr(value)}{hint}")
    return value


def load_scene(path: Path, parsers: Mapping[str, argparse.ArgumentParser] | None = None,
               out: Path | None = None, resume: bool = False) -> Scene:
    """Read and check the scene file ``path`` (UsageError naming the key and its line);
    ``out`` (the run folder) overrides the scene's ``out``; ``resume`` continues the run in
    it from its checkpoint. Reads input files' existence only; writes nothing."""
    path = Path(path)
    parsers = command_parsers() if parsers is None else parsers
    text, data = read_toml(path)
    where = Where(path, text)
    entries = flatten(data, where)
    test = _test_of(entries, where, parsers)
    parser = parsers[test]
    keys = scene_keys(parser)
    aliases = {a.dest: k for k, a in keys.items() if a.dest != k}

    seen: dict[str, tuple[str, ...]] = {}
    for key_path, _ in entries:
        name = key_path[-1]
        if name == "test":
            continue
        key = name if name in keys else aliases.get(name)
        if key is None and key_of(name) in keys:  # the kebab-case spelling of old
            key = key_of(name)
            line = line_of(text, key_path)
            warnings.warn(f"{path}{f', line {line}' if line else ''}: scene key '{name}' is "
                          f"deprecated: it is spelled '{key}' now (scene keys are snake_case, "
                          "as in Python and the run specification; the kebab-case spelling "
                          "is read until the next release)", RenamedWarning,
                          stacklevel=user_stacklevel())
        if key is None:
            raise where.error(key_path, f"unknown key '{name}': not an option of {test}"
                                        f"{suggest(name, sorted(keys))}; its keys are the "
                                        f"options of `granular-material {test} --help`")
        if key in _NOT_KEYS:
            raise where.error(key_path, f"'{name}' is not a scene key: {_NOT_KEYS[key]}")
        if key in seen:
            first = line_of(text, seen[key])
            raise where.error(key_path, f"'{key}' is given twice"
                                        + (f" (first on line {first})" if first else ""))
        seen[key] = key_path

    folder = path.parent
    given = dict(entries)
    out_path = seen.get("out")
    run_dir = _run_folder(where, out_path, keys["out"],
                          None if out_path is None else given[out_path], folder, out)
    values: dict[str, Any] = {}
    options: list[str] = []
    positional: list[str] = []
    for key, key_path in seen.items():
        if key == "out":
            continue
        action = keys[key]
        kind = kind_of(action)
        try:
            parsed, words = convert(key, kind, action, given[key_path])
        except ValueError as exc:
            raise where.error(key_path, f"{exc}{help_of(action)}") from None
        if kind == "path":
            if key in _RUN_FOLDER_KEYS:
                parsed = run_dir / Path(parsed).expanduser()
            else:
                parsed = folder / Path(parsed).expanduser()
                if not parsed.exists():
                    raise where.error(key_path, f"'{key}': {parsed} does not exist (paths in a "
                                                f"scene are relative to its folder)")
            words = [words[0], str(parsed)] if action.option_strings else [_word(parsed)]
        values[action.dest] = parsed
        (options if action.option_strings else positional).extend(words)

    for key, action in keys.items():
        if action.required and action.dest not in values:
            raise where.error((), f"missing key '{key}': {test} needs it{help_of(action)}")
    # files the run writes: inside the run folder, where the scene names none
    for key, name in _DEFAULT_FILES.get(test, {}).items():
        if keys[key].dest not in values:
            values[keys[key].dest] = run_dir / name
            options += [keys[key].option_strings[0], str(run_dir / name)]
    values["out"] = run_dir / TESTS[test] if TESTS[test] else run_dir
    options += ["--out", str(values["out"])]
    if resume:
        if "resume" not in keys:
            able = [t for t in TESTS if t in parsers and "resume" in scene_keys(parsers[t])]
            raise UsageError(f"--resume: a {test} run keeps no checkpoint to continue from "
                             f"(only {' and '.join(able)} do)")
        if keys["resume"].nargs == 0:  # a DEM command's switch: the checkpoint beside out
            values["resume"] = True
            options += ["--resume"]
        else:  # a FEM command's folder
            values["resume"] = run_dir
            options += ["--resume", str(run_dir)]

    namespace = _defaults(parser)
    for dest, value in values.items():
        setattr(namespace, dest, value)
    namespace.command = test
    lines = {key: line_of(text, key_path) for key, key_path in seen.items()}
    # how a stopped run of the scene is continued, as its command says when it stops
    again = shlex.join(["granular-material", "run", str(path),
                        *(["--out", str(out)] if out is not None else []), "--resume"])
    return Scene(path=path, test=test, namespace=namespace, run_dir=run_dir,
                 resume_with=again, argv=positional + options,
                 lines={key: line for key, line in lines.items() if line is not None})


def _word(path: Path) -> str:
    """A path as a positional command-line word (never read as an option)."""
    text = str(path)
    return "./" + text if text.startswith("-") else text


def _run_folder(where: Where, key_path: tuple[str, ...] | None, action: argparse.Action,
                value: Any, folder: Path, out: Path | None) -> Path:
    """The run folder: ``out`` (``run --out``), else the scene's ``out`` (relative to its
    folder), else the scene's name in the current folder; checked to be writable."""
    if key_path is not None:
        try:
            parsed, _ = convert("out", "path", action, value)
        except ValueError as exc:
            raise where.error(key_path, f"{exc} (the run folder)") from None
    if out is not None:
        run_dir = Path(out).expanduser()
        check_output_dir(run_dir, "--out")
        return run_dir
    if key_path is None:
        run_dir = Path(where.path.stem)
        check_output_dir(run_dir, "the run folder (the scene's name; set out or --out)")
        return run_dir
    run_dir = folder / Path(parsed).expanduser()
    try:
        check_output_dir(run_dir, "out")
    except UsageError as exc:
        raise where.error(key_path, f"{exc} (the run folder)") from None
    return run_dir


def _defaults(parser: argparse.ArgumentParser) -> argparse.Namespace:
    """The namespace the command's parser gives when no option is given (as argparse makes
    it: string defaults converted by the option's type, then ``set_defaults``)."""
    namespace = argparse.Namespace()
    for action in scene_keys(parser).values():
        default = parser.get_default(action.dest)
        if isinstance(default, str) and action.type is not None:
            default = action.type(default)
        setattr(namespace, action.dest, default)
    namespace.func = parser.get_default("func")
    return namespace
