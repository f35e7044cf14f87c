"""The keys of a scene, read from the command parsers (each a
:class:`~granular_material.cli.parsers.CommandParser`, which records its options): every
option of a command is a key, its long name in snake_case (``--axial-strain`` →
``axial_strain``: :func:`granular_material.vocabulary.key_of`), its TOML value converted and
checked by the parser's own ``type`` and ``choices``."""

from __future__ import annotations

import argparse
import difflib
from pathlib import Path
from typing import Any

from granular_material.cli.parsers import CommandParser, HelpAll
from granular_material.cli.scene_toml import toml_repr
from granular_material.vocabulary import key_of

__all__ = ["command_parsers", "convert", "help_of", "kind_of", "scene_keys", "suggest"]


def command_parsers() -> dict[str, CommandParser]:
    """The sub-command parsers of ``granular-material`` (plugins included), by name."""
    from granular_material.cli.commands import build_parser

    parsers = build_parser().commands
    if not parsers:
        raise RuntimeError("granular-material has no sub-commands")
    return parsers


def _flag(action: argparse.Action) -> str | None:
    """The first long option of ``action`` (None: a positional argument)."""
    return next((o for o in action.option_strings if o.startswith("--")), None)


def _key_name(action: argparse.Action) -> str:
    """The scene key of an option: its first long option in snake_case (``--axial-strain``
    → ``axial_strain``); of a positional argument, its name."""
    flag = _flag(action)
    return action.dest if flag is None else key_of(flag)


def scene_keys(parser: CommandParser) -> dict[str, argparse.Action]:
    """Every scene key of the command ``parser`` with its action (``help`` left out; the
    options of :data:`_NOT_KEYS` included, they are refused with advice), in the order the
    options were added (:attr:`CommandParser.arguments`)."""
    return {_key_name(a): a for a in parser.arguments
            if not isinstance(a, (argparse._HelpAction, argparse._VersionAction, HelpAll))}


def kind_of(action: argparse.Action) -> str:
    """What TOML value an option takes: ``flag`` (a boolean), ``integer``, ``number``,
    ``path`` or ``text`` (a string), found by probing the parser's own ``type``."""
    if action.nargs == 0:
        return "flag"
    if action.type is None:
        return "text"
    try:
        probe = action.type("1")
    except (argparse.ArgumentTypeError, ValueError, TypeError):
        return "text"
    if isinstance(probe, bool):
        return "text"
    if isinstance(probe, int):
        return "integer"
    if isinstance(probe, float):
        return "number"
    if isinstance(probe, Path):
        return "path"
    return "text"


def _item_text(key: str, kind: str, action: argparse.Action, value: Any) -> str:
    """One TOML item as the command-line text the parser converts (ValueError: wrong type)."""
    if kind in ("integer", "number"):
        wanted = "an integer" if kind == "integer" else "a number"
        numeric = isinstance(value, int) or (kind == "number" and isinstance(value, float))
        if isinstance(value, bool) or not numeric:
            hint = (" (values are SI numbers, without unit names)" if isinstance(value, str)
                    else "")
            raise ValueError(f"'{key}' takes {wanted}, got {toml_repr(value)}{hint}")
        return repr(value)
    if isinstance(value, str):
        return value
    if kind == "text" and action.type is None and isinstance(value, int) \
            and not isinstance(value, bool):
        return str(value)  # e.g. Gauss point ids of track
    raise ValueError(f"'{key}' takes a string, got {toml_repr(value)}")


def convert(key: str, kind: str, action: argparse.Action, value: Any) -> tuple[Any, list[str]]:
    """A TOML value of the option ``action`` → (the parsed value, its command-line words);
    ValueError (naming ``key``) where the parser would refuse it."""
    nargs = action.nargs
    flag = _flag(action) or ""
    if kind == "flag":
        if not isinstance(value, bool):
            raise ValueError(f"'{key}' is a switch: true or false, got {toml_repr(value)}")
        if isinstance(action, argparse.BooleanOptionalAction):
            return value, [flag if value else "--no-" + flag[2:]]
        return (action.const, [flag]) if value else (action.default, [])
    if nargs in (None, "?"):
        if isinstance(value, (list, dict)):
            raise ValueError(f"'{key}' takes one value, got {toml_repr(value)}")
        items = [value]
    else:
        items = value if isinstance(value, list) else [value]
        if isinstance(nargs, int) and len(items) != nargs:
            raise ValueError(f"'{key}' takes a list of {nargs} values, got {toml_repr(value)}")
        if not items:
            raise ValueError(f"'{key}' takes at least one value, got []")
    texts = [_item_text(key, kind, action, item) for item in items]
    parsed = []
    for text in texts:
        try:
            one = action.type(text) if action.type is not None else text
        except (argparse.ArgumentTypeError, ValueError, TypeError) as exc:
            raise ValueError(f"'{key}': {exc}") from None
        if action.choices is not None and one not in action.choices:
            raise ValueError(f"'{key}' must be one of {', '.join(map(str, action.choices))}; "
                             f"got {toml_repr(text)}")
        parsed.append(one)
    result = parsed[0] if nargs in (None, "?") else parsed
    if not action.option_strings:  # a positional argument
        return result, texts
    if len(texts) == 1 and nargs in (None, "?") and texts[0].startswith("-"):
        return result, [f"{flag}={texts[0]}"]
    return result, [flag, *texts]


def help_of(action: argparse.Action) -> str:
    """The option's help text, in parentheses after a message ("" without one)."""
    text = " ".join((action.help or "").split()).replace("%%", "%")
    return f" ({text})" if text else ""


def suggest(name: str, known: list[str]) -> str:
    """" (did you mean ...?)" with the keys of ``known`` closest to ``name`` ("" if none)."""
    close = difflib.get_close_matches(name, known, n=3)
    return f" (did you mean {' or '.join(repr(c) for c in close)}?)" if close else ""


