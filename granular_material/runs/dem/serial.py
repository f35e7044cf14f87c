"""A DEM run's specification as data: a flat dict (``test`` and every field by its name,
JSON-able), JSON and TOML, lossless both ways::

    {"test": "biaxial-dem", "rve": "rve.npz", "axial_strain": 0.1, ..., "out": "curve.csv"}

A field left out takes its default; an unknown one, a missing required one or a value of
the wrong type is a :class:`~granular_material.runs.spec_checks.SpecError` naming it.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from dataclasses import MISSING, fields
from pathlib import Path
from typing import Any

from granular_material.runs.dem.spec import DEM_TESTS, SPECS, DemSpec
from granular_material.runs.serial import _toml_value
from granular_material.runs.spec_checks import SpecError

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

__all__ = ["from_dict", "is_dem", "load", "save", "to_dict", "to_toml"]


def is_dem(data: Any) -> bool:
    """Whether ``data`` (a spec, or a dict form) is a DEM run's."""
    if isinstance(data, Mapping):
        return data.get("test") in DEM_TESTS
    return isinstance(data, tuple(SPECS.values()))


def _plain(value: Any) -> Any:
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


def to_dict(spec: DemSpec) -> dict[str, Any]:
    """The dict form of ``spec``: ``test`` and every field (JSON-able)."""
    return {"test": spec.test, **{f.name: _plain(getattr(spec, f.name)) for f in fields(spec)}}


def from_dict(data: Mapping[str, Any]) -> DemSpec:
    """The spec of a dict form (:func:`to_dict`); SpecError naming an unknown, missing or
    ill-typed field."""
    if not isinstance(data, Mapping):
        raise SpecError("spec", f"must be a table of fields, got {data!r} "
                                f"({type(data).__name__})")
    test = data.get("test")
    if test not in DEM_TESTS:
        raise SpecError("test", f"must be one of {', '.join(DEM_TESTS)}, got {test!r}")
    kind = SPECS[test]
    names = {f.name for f in fields(kind)}
    values = {str(k): v for k, v in data.items() if k != "test"}
    unknown = sorted(set(values) - names)
    if unknown:
        raise SpecError(unknown[0], f"is no field of a {test} run (it has "
                                    f"{', '.join(sorted(names))})")
    missing = [f.name for f in fields(kind) if f.name not in values
               and f.default is MISSING and f.default_factory is MISSING]
    if missing:
        raise SpecError(missing[0], f"must be given for a {test} run (it has no default)")
    return kind(**values)


def to_toml(spec: DemSpec) -> str:
    """``spec`` as TOML (a field that is None is left out: its default is None)."""
    lines = [f"{key} = {_toml_value(value)}" for key, value in to_dict(spec).items()
             if value is not None]
    return "\n".join(lines) + "\n"


def save(spec: DemSpec, path: str | Path) -> None:
    """Write ``spec`` to ``path``: TOML for a ``.toml`` suffix, else JSON; whole or not at
    all."""
    from granular_material.filesafe import write_whole

    if not is_dem(spec):
        raise TypeError(f"save() takes a DEM run's spec, got {type(spec).__name__}")
    path = Path(path)
    text = (to_toml(spec) if path.suffix == ".toml"
            else json.dumps(to_dict(spec), indent=2) + "\n")
    write_whole(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def load(path: str | Path) -> DemSpec:
    """The DEM spec saved in ``path`` (TOML for a ``.toml`` suffix, else JSON); a file that
    is no spec a ValueError naming it, a bad field a SpecError naming the field."""
    path = Path(path)
    kind = "TOML" if path.suffix == ".toml" else "JSON"
    try:
        text = path.read_text(encoding="utf-8")
        data = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    except UnicodeDecodeError:
        raise ValueError(f"{path} is no DEM run spec: not UTF-8 text") from None
    except ValueError as exc:  # TOMLDecodeError, JSONDecodeError
        raise ValueError(f"{path} is no {kind} DEM run spec: {exc}") from None
    return from_dict(data)
