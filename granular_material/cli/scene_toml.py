"""A scene file as TOML: its keys with the line each is set on (for messages that name it),
its values as TOML writes them, and its tables flattened into (key path, value) pairs."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

from granular_material.cli.options import UsageError

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

__all__ = ["Where", "flatten", "line_of", "read_toml", "toml_repr"]


_PART = r"(?:[A-Za-z0-9_-]+|\"(?:[^\"\\]|\\.)*\"|'[^']*')"
_KEY_LINE = re.compile(rf"^\s*({_PART}(?:\s*\.\s*{_PART})*)\s*=")
_HEADER_LINE = re.compile(rf"^\s*\[\[?\s*({_PART}(?:\s*\.\s*{_PART})*)\s*\]")


def _parts(dotted: str) -> tuple[str, ...]:
    """The keys of a dotted TOML key (quoted ones decoded as TOML decodes them)."""
    parts = []
    for part in re.findall(_PART, dotted):
        if part[0] in "\"'":
            try:
                part = next(iter(tomllib.loads(f"{part} = 0")))
            except tomllib.TOMLDecodeError:
                part = part[1:-1]
        parts.append(part)
    return tuple(parts)


def line_of(text: str, path: tuple[str, ...]) -> int | None:
    """The line (from 1) where the key ``path`` (table names, then the key) is set, or its
    table's header when ``path`` names a table; None when it cannot be found."""
    table: tuple[str, ...] = ()
    for number, line in enumerate(text.splitlines(), start=1):
        header = _HEADER_LINE.match(line)
        if header:
            table = _parts(header.group(1))
            if table == path:
                return number
            continue
        key = _KEY_LINE.match(line)
        if key and table + _parts(key.group(1)) == path:
            return number
    return None


class Where:
    """Messages about one scene file, each with the line of the key it names."""

    def __init__(self, path: Path, text: str) -> None:
        self.path, self.text = path, text

    def error(self, key_path: tuple[str, ...], message: str) -> UsageError:
        """A UsageError of ``message`` at the file and the line of ``key_path``."""
        line = line_of(self.text, key_path) if key_path else None
        at = f"{self.path}, line {line}" if line else f"{self.path}"
        return UsageError(f"{at}: {message}")


def toml_repr(value: Any) -> str:
    """``value`` as TOML writes it (for messages)."""
    if isinstance(value, list):
        return "[" + ", ".join(toml_repr(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    return repr(value)


def read_toml(path: Path) -> tuple[str, dict[str, Any]]:
    """The text of the scene file ``path`` and its TOML; a UsageError naming the file (and
    the line of a TOML error)."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise UsageError(f"scene {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(f"scene {path} cannot be read: {exc}") from None
    try:
        return text, tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        found = re.search(r"line (\d+)", str(exc))
        shown = ""
        if found:
            lines = text.splitlines()
            number = int(found.group(1))
            if 1 <= number <= len(lines):
                shown = f": {lines[number - 1].strip()}"
        line = f", line {found.group(1)}" if found else ""
        raise UsageError(f"{path}{line}: not valid TOML ({exc}){shown}") from None


def flatten(data: dict[str, Any], where: Where) -> list[tuple[tuple[str, ...], Any]]:
    """(key path, value) of every key; tables only group keys, one level deep."""
    entries: list[tuple[tuple[str, ...], Any]] = []
    for name, value in data.items():
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            raise where.error((name,), f"[[{name}]]: a scene describes one run; write one "
                                       "scene per run")
        if not isinstance(value, dict):
            entries.append(((name,), value))
            continue
        for key, item in value.items():
            if isinstance(item, dict):
                raise where.error((name, key), f"[{name}.{key}]: tables only group keys, "
                                               "one level deep")
            entries.append(((name, key), item))
    return entries


