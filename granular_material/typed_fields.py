"""Dataclass fields checked by their annotated types, where they are built (a base module:
the run specification, :mod:`granular_material.runs.spec_checks`, and the materials' own
parameters use it alike).

:func:`conform` turns a value given for a field into the field's own type or raises
:class:`~granular_material.errors.ParameterError` naming the field: a number where a number
is due (an integer is one; a string, a boolean, NaN or an infinity is not), an integer where
a count is (a float only when it is a whole number), a string where a name is, a path as a
non-empty string, a list where a tuple is (each item checked; a pair must have two). The type
is read from the field's annotation, so a field added to a dataclass is checked with nothing
to add here; a type this module does not know (an array, a nested dataclass) is left to the
class's own check. Ranges are the classes' own checks.
"""

from __future__ import annotations

import math
import numbers
import os
import sys
import types
import typing
from collections.abc import Mapping
from dataclasses import fields
from functools import cache
from pathlib import Path
from typing import Any

from granular_material.errors import ParameterError

__all__ = ["conform", "conform_fields", "conform_mapping", "describe", "field_types"]


class _MismatchError(Exception):
    """A value that is not of the type asked (inside :func:`conform`)."""


@cache
def field_types(kind: type) -> dict[str, Any]:
    """The resolved annotation of every dataclass field of ``kind`` (``Any`` where an
    annotation cannot be resolved)."""
    try:
        return typing.get_type_hints(kind)
    except (NameError, TypeError, AttributeError):
        pass
    hints: dict[str, Any] = {}
    for f in fields(kind):
        owner = next((c for c in kind.__mro__ if f.name in getattr(c, "__annotations__", {})),
                     kind)
        namespace = vars(sys.modules[owner.__module__])
        try:
            hints[f.name] = (eval(f.type, namespace) if isinstance(f.type, str)
                             else f.type)
        except Exception:  # an annotation only a type checker resolves: not checked here
            hints[f.name] = Any
    return hints


def describe(hint: Any) -> str:
    """What a value of ``hint`` is, in words (for messages)."""
    if hint is type(None) or hint is None:
        return "none (left out)"
    arms = _arms(hint)
    if arms is not None:
        return " or ".join(describe(a) for a in arms)
    if hint is bool:
        return "true or false"
    if hint is int:
        return "an integer"
    if hint is float:
        return "a finite number"
    if hint is str:
        return "a string"
    if hint is Path:
        return "a path (a non-empty string)"
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return f"a list of {_plural(args[0])}"
    if origin is tuple:
        return f"a list of {len(args)} {_plural(args[0])}" if len(set(args)) == 1 else (
            "a list (" + ", ".join(describe(a) for a in args) + ")")
    return getattr(hint, "__name__", str(hint))


def _plural(hint: Any) -> str:
    return {int: "integers", float: "finite numbers", str: "strings", bool: "booleans"}.get(
        hint, describe(hint))


def _arms(hint: Any) -> tuple[Any, ...] | None:
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return typing.get_args(hint)
    return None


def _shown(value: Any) -> str:
    text = repr(value)
    text = text if len(text) <= 60 else text[:57] + "..."
    return f"{text} ({type(value).__name__})"


def _conform(value: Any, hint: Any) -> Any:
    """``value`` as ``hint``; _MismatchError where it is not one."""
    if hint is Any:
        return value
    if hint is type(None) or hint is None:
        if value is None:
            return None
        raise _MismatchError
    arms = _arms(hint)
    if arms is not None:
        if value is None:
            if type(None) in arms:
                return None
            raise _MismatchError
        for arm in arms:
            if arm is type(None):
                continue
            try:
                return _conform(value, arm)
            except _MismatchError:
                continue
        raise _MismatchError
    if hint is bool:
        if isinstance(value, bool) or type(value).__name__ == "bool_":
            return bool(value)
        raise _MismatchError
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        raise _MismatchError  # a boolean is no number, string or path here
    if hint is int:
        if isinstance(value, numbers.Integral):
            return int(value)
        if isinstance(value, numbers.Real) and math.isfinite(value) and value == int(value):
            return int(value)
        raise _MismatchError
    if hint is float:
        try:
            if isinstance(value, numbers.Real) and math.isfinite(float(value)):
                return float(value)
        except OverflowError:  # an integer beyond any float
            pass
        raise _MismatchError
    if hint is str:
        if isinstance(value, str):
            return value
        raise _MismatchError
    if hint is Path:
        if isinstance(value, str | os.PathLike) and str(value).strip():
            return Path(value)
        raise _MismatchError
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is tuple:
        if getattr(value, "ndim", 0) and hasattr(value, "tolist"):  # an array: its items
            value = value.tolist()
        if isinstance(value, str | bytes | Mapping) or not isinstance(value, list | tuple):
            raise _MismatchError
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_conform(v, args[0]) for v in value)
        if len(value) != len(args):
            raise _MismatchError
        return tuple(_conform(v, a) for v, a in zip(value, args, strict=True))
    return value  # a type this checker does not know: the section's own check decides


def conform(name: str, value: Any, hint: Any,
            error: type[ParameterError] = ParameterError) -> Any:
    """``value`` of the field ``name`` as its type ``hint``; ``error`` (a ParameterError)
    naming the field and what it must be otherwise."""
    try:
        return _conform(value, hint)
    except _MismatchError:
        raise error(name, f"must be {describe(hint)}, got {_shown(value)}") from None


def conform_fields(obj: Any, skip: tuple[str, ...] = (),
                   error: type[ParameterError] = ParameterError) -> None:
    """Every dataclass field of the frozen ``obj`` (but ``skip``) conformed in place."""
    hints = field_types(type(obj))
    for f in fields(obj):
        if f.name in skip:
            continue
        value = getattr(obj, f.name)
        object.__setattr__(obj, f.name, conform(f.name, value, hints.get(f.name, Any), error))


def conform_mapping(kind: type, given: Mapping[str, Any],
                    error: type[ParameterError] = ParameterError) -> dict[str, Any]:
    """The keywords ``given`` for the dataclass ``kind``, each conformed to its field."""
    hints = field_types(kind)
    return {name: conform(name, value, hints.get(name, Any), error)
            for name, value in given.items()}
