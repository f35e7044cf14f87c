"""A DEM run's specification as data: nested dicts, JSON and TOML, lossless both ways, in
sections like a FEM run spec's (:mod:`granular_material.runs.serial`)::

    {"problem": {"test": "biaxial-dem", "rve": "rve.npz", "axial_strain": 0.1, ...},
     "output": {"out": "curve.csv", "plot": None, "progress": False},
     "device": None, "dtype": "float64"}

``prepare``'s RVE material (radii, contact law, friction, damping, density, thickness) is
its ``material`` section. A field left out takes its default; an unknown one, one in another
section, a missing required one or a value of the wrong type is a
:class:`~granular_material.runs.spec_checks.SpecError` naming it.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from dataclasses import MISSING, fields
from pathlib import Path
from typing import Any

from granular_material.runs.dem.spec import DEM_TESTS, SPECS, DemSpec
from granular_material.runs.serial import (
    _plain,
    _section,
    _toml_value,
    read_spec_file,
    write_spec_file,
)
from granular_material.runs.spec_checks import SpecError

if sys.version_info >= (3, 11):
    pass
else:  # Python 3.10
    pass

__all__ = ["from_dict", "is_dem", "load", "save", "to_dict", "to_flat", "to_toml"]


def is_dem(data: Any) -> bool:
    """Whether ``data`` (a spec, or a dict form) is a DEM run's."""
    if isinstance(data, Mapping):
        problem = data.get("problem")
        return isinstance(problem, Mapping) and problem.get("test") in DEM_TESTS
    return isinstance(data, tuple(SPECS.values()))


#: the sections of a DEM spec's nested form but ``problem``, and their fields
_SECTIONS = {"output": ("out", "plot", "progress"),
             "material": ("radius_min", "radius_max", "law", "kn", "kt", "contact_young",
                          "kt_over_kn", "contact_friction_angle", "damping", "density",
                          "thickness")}
#: the spec's own fields (beside its sections)
_RUN_FIELDS = ("device", "dtype")


def _section_of(name: str) -> str | None:
    """The section of the field ``name`` (None: a run field, at the top)."""
    if name in _RUN_FIELDS:
        return None
    return next((section for section, names in _SECTIONS.items() if name in names), "problem")


def to_flat(spec: DemSpec) -> dict[str, Any]:
    """Every field of ``spec`` by its name (JSON-able), ``test`` first."""
    return {"test": spec.test, **{f.name: _plain(getattr(spec, f.name)) for f in fields(spec)}}


def to_dict(spec: DemSpec) -> dict[str, Any]:
    """The nested form of ``spec`` (JSON-able): ``problem`` (with ``test``), ``material``
    (``prepare``'s), ``output``, and ``device``, ``dtype``."""
    data: dict[str, Any] = {"problem": {"test": spec.test}}
    for f in fields(spec):
        section = _section_of(f.name)
        value = _plain(getattr(spec, f.name))
        if section is None:
            data[f.name] = value
        else:
            data.setdefault(section, {})[f.name] = value
    return data


def from_dict(data: Mapping[str, Any]) -> DemSpec:
    """The spec of a nested form (:func:`to_dict`); SpecError naming an unknown, misplaced,
    missing or ill-typed field."""
    if not isinstance(data, Mapping):
        raise SpecError("spec", f"must be a table of sections, got {data!r} "
                                f"({type(data).__name__})")
    problem = dict(_section("problem", data.get("problem")))
    test = problem.pop("test", None)
    if test not in DEM_TESTS:
        raise SpecError("test", f"must be one of {', '.join(DEM_TESTS)}, got {test!r}")
    kind = SPECS[test]
    names = {f.name for f in fields(kind)}
    sections = {_section_of(name) for name in names} - {None}
    unknown = sorted(set(map(str, data)) - sections - set(_RUN_FIELDS))
    if unknown:
        raise SpecError(unknown[0], f"is no section of a {test} run spec (it has "
                                    f"{', '.join(sorted(sections | set(_RUN_FIELDS)))})")
    values: dict[str, Any] = {k: data[k] for k in _RUN_FIELDS if k in data}
    for section in sorted(sections):
        table = problem if section == "problem" else _section(section, data.get(section))
        for key, value in table.items():
            key = str(key)
            if key not in names or _section_of(key) != section:
                where = (f"; it is a field of {_section_of(key) or 'the spec itself'}"
                         if key in names else "")
                raise SpecError(key, f"is no field of {section} in a {test} run spec{where}")
            values[key] = value
    missing = [f.name for f in fields(kind) if f.name not in values
               and f.default is MISSING and f.default_factory is MISSING]
    if missing:
        raise SpecError(missing[0], f"must be given for a {test} run (it has no default)")
    return kind(**values)


def to_toml(spec: DemSpec) -> str:
    """``spec`` as TOML (a field that is None is left out: its default is None)."""
    data = to_dict(spec)
    lines = [f"{k} = {_toml_value(data[k])}" for k in _RUN_FIELDS if data[k] is not None]
    for section in ("problem", "material", "output"):
        if section in data:
            lines += ["", f"[{section}]"]
            lines += [f"{k} = {_toml_value(v)}" for k, v in data[section].items()
                      if v is not None]
    return "\n".join(lines) + "\n"


def save(spec: DemSpec, path: str | Path) -> None:
    """Write ``spec`` to ``path``: TOML for a ``.toml`` suffix, else JSON; whole or not at
    all."""
    if not is_dem(spec):
        raise TypeError(f"save() takes a DEM run's spec, got {type(spec).__name__}")
    write_spec_file(path, to_toml(spec), to_dict(spec))


def load(path: str | Path) -> DemSpec:
    """The DEM spec saved in ``path`` (TOML for a ``.toml`` suffix, else JSON); a file that
    is no spec a ValueError naming it, a bad field a SpecError naming the field."""
    return from_dict(read_spec_file(path, "DEM run spec"))
