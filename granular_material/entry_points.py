"""What plugins register: the names in an entry-point group and the one lookup of a name
(materials, post-processors, commands), for every layer."""

from __future__ import annotations

from importlib.metadata import entry_points
from typing import Any

__all__ = ["entry_point_names", "load_entry_point"]


def entry_point_names(group: str) -> list[str]:
    """The names registered in the entry-point group ``group``, sorted."""
    return sorted({ep.name for ep in entry_points(group=group)})


def load_entry_point(group: str, name: str, what: str) -> Any:
    """What is registered under ``name`` in the entry-point group ``group``, loaded; a
    ``ValueError`` naming ``what`` it is (``material``, ``post-processor``) and the choices
    installed when nothing is."""
    matches = [ep for ep in entry_points(group=group) if ep.name == name]
    if not matches:
        choices = ", ".join(entry_point_names(group)) or "none installed"
        raise ValueError(f"{what} {name!r} is not registered; available: {choices}")
    return matches[0].load()
