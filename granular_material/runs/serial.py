"""A run specification as data: nested dicts, JSON and TOML (lossless both ways), and the
flat form of its fields' bare names that command-line options, scene keys, presets and
older checkpoints use.

Nested form::

    {"problem": {...}, "material": {"name": "dem", "parameters": {...}},
     "newton": {...}, "output": {...}, "regularisation": {...},
     "adaptivity": {...} or None, "device": ..., "shards": ..., "backend": ...,
     "preset": ...}

Flat form: every field by its bare name (``steps``, ``rtol``, ``particles``, ``out``), the
material's name as ``material`` and the problem's ``test``; a field left out takes its
default. Adaptivity, an optional section, is ``adaptivity`` (true: on) and its fields by
their bare names (``mobilised_fraction``, ``start``, …), which need it on; as in a scene's
``[adaptivity]`` table, ``shear_strain`` given alone is the only threshold.
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
    AdaptivitySpec,
    MaterialSpec,
    NewtonSpec,
    OutputSpec,
    ProblemSpec,
    RegularisationSpec,
    RunSpec,
    SpecError,
)
from granular_material.vocabulary import renamed

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

__all__ = ["SECTIONS", "from_dict", "from_flat", "load", "save", "to_dict", "to_flat",
           "to_toml"]

#: the sections of a spec and their types
SECTIONS: dict[str, type] = {"problem": ProblemSpec, "newton": NewtonSpec,
                             "output": OutputSpec, "regularisation": RegularisationSpec}
#: the spec's own fields (beside its sections)
_RUN_FIELDS = ("device", "shards", "backend", "preset")
#: the optional section (None: off) and its fields' bare names
_ADAPTIVITY = "adaptivity"


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
    data[_ADAPTIVITY] = None if spec.adaptivity is None else _fields(spec.adaptivity)
    data.update({name: getattr(spec, name) for name in _RUN_FIELDS})
    return data


def _section(name: str, value: Any) -> Mapping[str, Any]:
    """The section ``name`` of a nested form: a table of fields (absent: empty)."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise SpecError(name, f"must be a table of fields ([{name}] in TOML, an object in "
                              f"JSON), got {value!r} ({type(value).__name__})")
    bad = [k for k in value if not isinstance(k, str)]
    if bad:
        raise SpecError(name, f"has a key that is no field name: {bad[0]!r}")
    return value


def _known(kind: type, values: Any, where: str) -> dict[str, Any]:
    values = _section(where, values)
    names = {f.name for f in fields(kind)}
    unknown = sorted(set(values) - names)
    if unknown:
        raise SpecError(unknown[0], f"is no field of {where} (it has {', '.join(sorted(names))})")
    required = [f.name for f in fields(kind)
                if f.default is MISSING and f.default_factory is MISSING]
    missing = [name for name in required if name not in values]
    if missing:
        raise SpecError(missing[0], f"must be given in {where} (it has no default)")
    return dict(values)


def _adaptivity(values: Any) -> AdaptivitySpec | None:
    """The adaptivity section of a nested form: None (off) or a table of its fields (empty:
    every default; ``shear_strain`` named alone is the only threshold)."""
    if values is None:
        return None
    table = _known(AdaptivitySpec, values, _ADAPTIVITY)
    if "shear_strain" in table and "mobilised_fraction" not in table:
        table["mobilised_fraction"] = None
    try:
        return AdaptivitySpec(**table)
    except SpecError as exc:  # a field by its bare name, as every field of a run spec
        raise SpecError(exc.field.removeprefix(f"{_ADAPTIVITY}."), exc.message) from None


def from_dict(data: Mapping[str, Any]) -> RunSpec:
    """The spec of a nested form (:func:`to_dict`); SpecError naming an unknown, missing or
    ill-typed field."""
    if not isinstance(data, Mapping):
        raise SpecError("spec", "must be a table of sections (problem, material, newton, "
                                f"output), got {data!r} ({type(data).__name__})")
    unknown = sorted(set(map(str, data)) - {*SECTIONS, "material", _ADAPTIVITY, *_RUN_FIELDS})
    if unknown:
        raise SpecError(unknown[0], "is no section of a run spec")
    material = dict(_section("material", data.get("material")))
    if "name" not in material:
        raise SpecError("material", "must name the material (material.name)")
    extra = sorted(set(material) - {"name", "parameters"})
    if extra:
        raise SpecError(extra[0], "is no field of material (it has name, parameters: a "
                                  "material's own parameters go in material.parameters)")
    parameters = _section("parameters", material.get("parameters"))
    sections = {name: kind(**_known(kind, data.get(name), name))
                for name, kind in SECTIONS.items() if name != "problem"}
    problem = ProblemSpec(**_known(ProblemSpec, data.get("problem"), "problem"))
    return RunSpec(problem=problem,
                   material=MaterialSpec(name=material["name"], parameters=dict(parameters)),
                   **sections, adaptivity=_adaptivity(data.get(_ADAPTIVITY)),
                   **{k: data[k] for k in _RUN_FIELDS if k in data})


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
    values = dict(_section("spec", values))
    if "material" not in values:
        raise SpecError("material", "must name the material")
    name = values.pop("material")
    if not isinstance(name, str):
        raise SpecError("material", f"must name the material (a string), got {name!r}")
    data: dict[str, Any] = {key: {} for key in SECTIONS}
    parameters: dict[str, Any] = {}
    adaptive = values.pop(_ADAPTIVITY, False)
    if not isinstance(adaptive, bool):
        raise SpecError(_ADAPTIVITY, f"must be true or false, got {adaptive!r}")
    adaptivity: dict[str, Any] = {}
    material_names = _material_names(name)
    for key, value in renamed(values, name).items():  # old names: warned, read as new
        section = next((s for s, kind in SECTIONS.items() if key in _names(kind)), None)
        if section is not None:
            data[section][key] = value
        elif key in _names(AdaptivitySpec):
            adaptivity[key] = value
        elif key in _RUN_FIELDS:
            data[key] = value
        elif material_names is None or key in material_names:
            parameters[key] = value
        elif strict:
            raise SpecError(key, f"is no field of a run of the material {name}")
    data["material"] = {"name": name, "parameters": parameters}
    if not adaptive:
        given = [k for k, v in adaptivity.items() if v is not None]
        if given:
            raise SpecError(given[0], "is a setting of adaptivity: it needs `adaptivity`")
    else:
        data[_ADAPTIVITY] = adaptivity
    return from_dict(data)


def to_flat(spec: RunSpec) -> dict[str, Any]:
    """The flat form of ``spec``: every field by its bare name (JSON-able)."""
    data = to_dict(spec)
    flat: dict[str, Any] = {"material": spec.material.name}
    for name in SECTIONS:
        flat.update(data[name])
    flat.update(data["material"]["parameters"])
    flat[_ADAPTIVITY] = spec.adaptivity is not None
    flat.update(data[_ADAPTIVITY] or {})
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
    if spec.adaptivity is not None:  # a threshold that is None is left out (the other alone)
        values = {k: v for k, v in data[_ADAPTIVITY].items()
                  if v is not None or k != "mobilised_fraction"}
        lines += ["", *_table(_ADAPTIVITY, values, _defaults(AdaptivitySpec))]
    kind = getattr(spec.material.cls, "Parameters", None)
    lines += ["", "[material]", f"name = {_toml_value(spec.material.name)}", "",
              *_table("material.parameters", data["material"]["parameters"],
                      _defaults(kind) if kind is not None else {})]
    return "\n".join(lines) + "\n"


def write_spec_file(path: str | Path, toml_text: str, data: Mapping[str, Any]) -> None:
    """Write a spec's forms to ``path``: ``toml_text`` for a ``.toml`` suffix, else ``data``
    as JSON; whole or not at all (:func:`~granular_material.filesafe.write_whole`: a failed
    write, a full disk included, keeps the file that was there)."""
    from granular_material.filesafe import write_whole

    path = Path(path)
    text = toml_text if path.suffix == ".toml" else json.dumps(data, indent=2) + "\n"
    write_whole(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def read_spec_file(path: str | Path, what: str = "run spec") -> dict[str, Any]:
    """The nested dict saved in ``path`` (TOML for a ``.toml`` suffix, else JSON); a file
    that is no such text a ValueError naming it and ``what`` it should have been."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{path} is no {what}: not UTF-8 text (TOML or JSON)") from None
    kind = "TOML" if path.suffix == ".toml" else "JSON"
    try:
        return tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    except ValueError as exc:  # TOMLDecodeError, JSONDecodeError
        raise ValueError(f"{path} is no {kind} {what}: {exc}") from None
    except RecursionError:  # arrays or tables nested thousands deep
        raise ValueError(f"{path} is no {kind} {what}: nested too deep to read") from None


def save(spec: RunSpec, path: str | Path) -> None:
    """Write ``spec`` to ``path``: TOML for a ``.toml`` suffix, else JSON; whole or not at
    all (:func:`write_spec_file`)."""
    if not isinstance(spec, RunSpec):
        raise TypeError(f"save() takes a RunSpec, got {type(spec).__name__}")
    write_spec_file(path, to_toml(spec), to_dict(spec))


def load(path: str | Path) -> RunSpec:
    """The spec saved in ``path`` (TOML for a ``.toml`` suffix, else JSON); a file that is
    no spec is a ValueError naming it, a bad field a SpecError naming the field."""
    return from_dict(read_spec_file(path))
