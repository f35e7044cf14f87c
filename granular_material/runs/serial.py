"""A run specification as data: nested dicts, JSON and TOML (lossless both ways), and the
flat form of its fields' bare names that command-line options, scene keys, presets and
older checkpoints use.

Nested form::

    {"problem": {...}, "material": {"name": "dem", "parameters": {...}},
     "newton": {...}, "output": {...}, "device": ..., "shards": ..., "backend": ...,
     "preset": ...}

Flat form: every field by its bare name (``steps``, ``rtol``, ``particles``, ``out``), the
material's name as ``material`` and the problem's ``test``; a field left out takes its
default.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Mapping
from dataclasses import MISSING, fields
from pathlib import Path
from typing import Any

from granular_material.runs.spec import (
    MaterialSpec,
    NewtonSpec,
    OutputSpec,
    ProblemSpec,
    RunSpec,
    SpecError,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

__all__ = ["SECTIONS", "from_dict", "from_flat", "load", "save", "to_dict", "to_flat",
           "to_toml"]

#: the sections of a spec and their types
SECTIONS: dict[str, type] = {"problem": ProblemSpec, "newton": NewtonSpec,
                             "output": OutputSpec}
#: the spec's own fields (beside its sections)
_RUN_FIELDS = ("device", "shards", "backend", "preset")


def _plain(value: Any) -> Any:
    """``value`` as JSON/TOML data: paths as text, tuples as lists."""
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


def _fields(obj: Any) -> dict[str, Any]:
    return {f.name: _plain(getattr(obj, f.name)) for f in fields(obj)}


def to_dict(spec: RunSpec) -> dict[str, Any]:
    """The nested form of ``spec`` (JSON-able)."""
    data: dict[str, Any] = {name: _fields(getattr(spec, name)) for name in SECTIONS}
    data["material"] = {"name": spec.material.name,
                        "parameters": {k: _plain(v) for k, v in spec.material.values().items()}}
    data.update({name: getattr(spec, name) for name in _RUN_FIELDS})
    return data


def _known(kind: type, values: Mapping[str, Any], where: str) -> dict[str, Any]:
    names = {f.name for f in fields(kind)}
    unknown = sorted(set(values) - names)
    if unknown:
        raise SpecError(unknown[0], f"is no field of {where} (it has {', '.join(sorted(names))})")
    return dict(values)


def from_dict(data: Mapping[str, Any]) -> RunSpec:
    """The spec of a nested form (:func:`to_dict`); SpecError naming an unknown field."""
    unknown = sorted(set(data) - {*SECTIONS, "material", *_RUN_FIELDS})
    if unknown:
        raise SpecError(unknown[0], "is no section of a run spec")
    material = dict(data.get("material") or {})
    if "name" not in material:
        raise SpecError("material", "must name the material (material.name)")
    sections = {name: kind(**_known(kind, data.get(name) or {}, name))
                for name, kind in SECTIONS.items() if name != "problem"}
    problem = ProblemSpec(**_known(ProblemSpec, data.get("problem") or {}, "problem"))
    return RunSpec(problem=problem,
                   material=MaterialSpec(name=material["name"],
                                         parameters=material.get("parameters") or {}),
                   **sections, **{k: data[k] for k in _RUN_FIELDS if k in data})


def _names(kind: type) -> set[str]:
    return {f.name for f in fields(kind)}


def _material_names(name: str) -> set[str] | None:
    """The parameter names of the material ``name`` (None: it takes any keywords)."""
    kind = getattr(MaterialSpec(name=name).cls, "Parameters", None)
    return None if kind is None else _names(kind)


def from_flat(values: Mapping[str, Any], *, strict: bool = True) -> RunSpec:
    """The spec of a flat form (bare field names; ``material`` the material's name,
    ``test`` the problem's). ``strict``: a name that is no field is a SpecError naming it;
    else it is left out (a checkpoint of an older version)."""
    values = dict(values)
    if "material" not in values:
        raise SpecError("material", "must name the material")
    name = values.pop("material")
    data: dict[str, Any] = {key: {} for key in SECTIONS}
    parameters: dict[str, Any] = {}
    material_names = _material_names(name)
    for key, value in values.items():
        section = next((s for s, kind in SECTIONS.items() if key in _names(kind)), None)
        if section is not None:
            data[section][key] = value
        elif key in _RUN_FIELDS:
            data[key] = value
        elif material_names is None or key in material_names:
            parameters[key] = value
        elif strict:
            raise SpecError(key, f"is no field of a run of the material {name}")
    data["material"] = {"name": name, "parameters": parameters}
    return from_dict(data)


def to_flat(spec: RunSpec) -> dict[str, Any]:
    """The flat form of ``spec``: every field by its bare name (JSON-able)."""
    data = to_dict(spec)
    flat: dict[str, Any] = {"material": spec.material.name}
    for name in SECTIONS:
        flat.update(data[name])
    flat.update(data["material"]["parameters"])
    flat.update({k: data[k] for k in _RUN_FIELDS})
    return flat


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML value for {value!r}")


def _table(name: str, values: Mapping[str, Any], defaults: Mapping[str, Any]) -> list[str]:
    lines = [f"[{name}]"]
    for key, value in values.items():
        if value is None:
            if defaults.get(key) is not None:
                raise ValueError(f"{name}.{key} is None where its default is not: TOML has "
                                 "no null; save the spec as JSON")
            continue
        lines.append(f"{key} = {_toml_value(value)}")
    return lines


def _defaults(kind: type) -> dict[str, Any]:
    return {f.name: (f.default if f.default is not MISSING else None) for f in fields(kind)}


def to_toml(spec: RunSpec) -> str:
    """``spec`` as TOML (a field that is None is left out, as its default)."""
    data = to_dict(spec)
    lines = [f"{k} = {_toml_value(data[k])}" for k in _RUN_FIELDS if data[k] is not None]
    for name, kind in SECTIONS.items():
        lines += ["", *_table(name, data[name], _defaults(kind))]
    kind = getattr(spec.material.cls, "Parameters", None)
    lines += ["", "[material]", f"name = {_toml_value(spec.material.name)}", "",
              *_table("material.parameters", data["material"]["parameters"],
                      _defaults(kind) if kind is not None else {})]
    return "\n".join(lines) + "\n"


def save(spec: RunSpec, path: str | Path) -> None:
    """Write ``spec`` to ``path``: TOML for a ``.toml`` suffix, else JSON."""
    path = Path(path)
    text = (to_toml(spec) if path.suffix == ".toml"
            else json.dumps(to_dict(spec), indent=2) + "\n")
    path.write_text(text)


def load(path: str | Path) -> RunSpec:
    """The spec saved in ``path`` (TOML for a ``.toml`` suffix, else JSON)."""
    path = Path(path)
    text = path.read_text()
    data = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    return from_dict(data)
