"""Every field of a run specification fed values of every type, from Python, the nested form
(JSON), the flat form and a TOML file: a value is either taken (and the spec it makes reads
back the same) or refused as a SpecError naming that field; never a TypeError,
AttributeError or KeyError."""

from __future__ import annotations

import json
import math
from dataclasses import fields
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from granular_material.cli import main
from granular_material.runs import (
    MaterialSpec,
    NewtonSpec,
    OutputSpec,
    ProblemSpec,
    RunSpec,
    SpecError,
    from_dict,
    from_flat,
    load,
    to_dict,
)
from granular_material.runs.serial import to_toml

#: values of every JSON/TOML/Python type a hostile user might put in a field
_SCALARS = (st.none() | st.booleans() | st.integers(-10**12, 10**12)
            | st.floats(allow_nan=True, allow_infinity=True)
            | st.text(max_size=12) | st.sampled_from(["", "all", "cpu", "1e5", "nan", "quad4",
                                                      "biaxial", "smooth", "none", "aitken"]))
_VALUES = (_SCALARS | st.lists(_SCALARS, max_size=3) | st.dictionaries(st.text(max_size=4),
                                                                        _SCALARS, max_size=2)
           | st.just(Path("x.npz")) | st.just(object()))

_PROBLEM = [f.name for f in fields(ProblemSpec) if f.name != "test"]
_NEWTON = [f.name for f in fields(NewtonSpec)]
_OUTPUT = [f.name for f in fields(OutputSpec)]
_RUN = ["device", "shards", "backend", "preset"]
_MATERIALS = {name: [f.name for f in fields(MaterialSpec(name=name).cls.Parameters)]
              for name in ("linear-elastic", "mohr-coulomb", "dem")}


def _base() -> dict:
    return {"problem": {"test": "biaxial"}, "material": {"name": "linear-elastic"}}


def _taken_or_named(build, name: str):
    """``build()`` makes a spec, or raises a SpecError naming ``name``."""
    try:
        spec = build()
    except SpecError as exc:
        assert exc.field == name, f"{exc} names {exc.field!r}, not {name!r}"
        return None
    return spec


def _reads_back(spec: RunSpec | None) -> None:
    if spec is not None:
        assert from_dict(json.loads(json.dumps(to_dict(spec)))) == spec


def _section_case(section: str, name: str, value) -> dict:
    data = _base()
    data.setdefault(section, {})[name] = value
    return data


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from([("problem", n) for n in _PROBLEM] + [("newton", n) for n in _NEWTON]
                       + [("output", n) for n in _OUTPUT]), _VALUES)
def test_every_section_field_takes_or_names_every_value(where, value):
    section, name = where
    kind = {"problem": ProblemSpec, "newton": NewtonSpec, "output": OutputSpec}[section]
    extra = {"test": "biaxial"} if kind is ProblemSpec else {}
    # from Python
    made = _taken_or_named(lambda: kind(**extra, **{name: value}), name)
    # the nested form and the flat form
    spec = _taken_or_named(lambda: from_dict(_section_case(section, name, value)), name)
    _reads_back(spec)
    flat = {"test": "biaxial", "material": "linear-elastic", name: value}
    assert (_taken_or_named(lambda: from_flat(flat), name) is None) == (spec is None)
    assert (made is None) == (spec is None)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from([(m, n) for m, names in _MATERIALS.items() for n in names]), _VALUES)
def test_every_material_parameter_takes_or_names_every_value(where, value):
    material, name = where
    data = _base()
    data["material"] = {"name": material, "parameters": {name: value}}
    spec = _taken_or_named(lambda: from_dict(data), name)
    _reads_back(spec)
    made = _taken_or_named(lambda: MaterialSpec(name=material, parameters={name: value}), name)
    assert (made is None) == (spec is None)


@settings(max_examples=120, deadline=None)
@given(st.sampled_from(_RUN), _VALUES)
def test_every_run_field_takes_or_names_every_value(name, value):
    data = {**_base(), name: value}
    spec = _taken_or_named(lambda: from_dict(data), name)
    _reads_back(spec)


@settings(max_examples=80, deadline=None)
@given(st.sampled_from(["problem", "newton", "output", "material", "parameters"]), _SCALARS
       | st.lists(_SCALARS, max_size=2))
def test_a_section_that_is_no_table_is_named(section, value):
    data = _base()
    if section == "parameters":
        data["material"]["parameters"] = value
    else:
        data[section] = value
    try:
        from_dict(data)
    except SpecError as exc:
        assert exc.field in (section, "material", "test")
    # None is an absent table: the problem then lacks its test, the others take defaults


@pytest.mark.parametrize(("build", "name"), [
    (lambda: ProblemSpec(test="biaxial", confining="100e3"), "confining"),
    (lambda: ProblemSpec(test="biaxial", confining=None), "confining"),
    (lambda: ProblemSpec(test="biaxial", elements=5), "elements"),
    (lambda: ProblemSpec(test="biaxial", steps=2.5), "steps"),
    (lambda: ProblemSpec(test="biaxial", steps=True), "steps"),
    (lambda: OutputSpec(checkpoint_minutes=None), "checkpoint_minutes"),
    (lambda: OutputSpec(map_strain=[math.nan]), "map_strain"),
    (lambda: OutputSpec(map_strain=[0.01] * 500), "map_strain"),
    (lambda: OutputSpec(track=["-1"]), "track"),
    (lambda: OutputSpec(postprocess=["no-such-thing"]), "postprocess"),
    (lambda: MaterialSpec(name="dem", parameters={"rve": 5}), "rve"),
    (lambda: MaterialSpec(name=5), "material"),
    (lambda: from_dict({**_base(), "device": 3}), "device"),
    (lambda: from_dict({**_base(), "device": "gpu"}), "device"),
    (lambda: from_dict({**_base(), "preset": "fastest"}), "preset"),
    (lambda: from_dict({"problem": {}, "material": {"name": "dem"}}), "test"),
    (lambda: from_dict(None), "spec"),
    (lambda: from_dict({**_base(), "newton": 5}), "newton"),
])
def test_the_issue_s_cases_are_named(build, name):
    with pytest.raises(SpecError) as info:
        build()
    assert info.value.field == name


def test_a_json_null_spec_file_is_named(tmp_path):
    (tmp_path / "spec.json").write_text("null")
    with pytest.raises(SpecError, match="spec must be a table"):
        load(tmp_path / "spec.json")
    (tmp_path / "broken.json").write_text("{")
    with pytest.raises(ValueError, match=r"broken\.json is no JSON run spec"):
        load(tmp_path / "broken.json")


@pytest.mark.parametrize(("text", "line"), [
    ('[problem]\ntest = "single-element"\nconfining = "100e3"\n', 3),
    ('[problem]\ntest = "biaxial"\nelements = 5\n', 3),
    ('newton = 5\n[problem]\ntest = "biaxial"\n', 1),
    ('device = 3\n[problem]\ntest = "biaxial"\n', 1),
    ('[problem]\ntest = "biaxial"\n[output]\nmap_strain = [nan]\n', 4),
    ('[problem]\ntest = "biaxial"\n[output]\ncheckpoint_minutes = "soon"\n', 4),
])
def test_a_spec_file_s_bad_field_is_exit_2_with_its_line(tmp_path, capsys, text, line):
    path = tmp_path / "spec.toml"
    path.write_text(text + '\n[material]\nname = "linear-elastic"\n')
    assert main(["run", str(path), "--check"]) == 2
    err = capsys.readouterr().err
    assert f"spec.toml, line {line}:" in err
    assert "Traceback" not in err


def test_a_toml_spec_takes_what_from_dict_takes():
    spec = from_dict({**_base(), "problem": {"test": "biaxial", "elements": [3, 6]},
                      "output": {"track": [0, 3], "map_strain": [0.01, 0.02]}})
    assert spec.problem.elements == (3, 6) and spec.output.track == ("0", "3")
    import sys

    tomllib = __import__("tomllib" if sys.version_info >= (3, 11) else "tomli")
    assert from_dict(tomllib.loads(to_toml(spec))) == spec


def test_a_spec_file_names_its_fields_not_the_command_s_options(tmp_path, capsys):
    path = tmp_path / "spec.toml"
    path.write_text('[problem]\ntest = "single-element"\n\n[material]\nname = "dem"\n\n'
                    '[material.parameters]\nrve = "missing.npz"\n')
    assert main(["run", str(path), "--check"]) == 2
    err = capsys.readouterr().err
    assert "spec.toml, line 8: rve missing.npz does not exist" in err and "--rve" not in err
