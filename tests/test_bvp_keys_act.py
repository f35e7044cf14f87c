"""Every key of every table of a boundary-value scene acts or is refused naming it (and its
line): none is read and then ignored (issue 61, kind 5)."""

from __future__ import annotations

from pathlib import Path

import pytest
import tomllib

from granular_material.cli import main
from granular_material.runs.boundary_value.spec import (
    CONDITION_KEYS,
    CONDITION_TYPES,
    INITIAL_KEYS,
    INITIAL_STATES,
    SCENE_KEYS,
    BoundaryValueSpec,
    ConditionSpec,
    InitialStateSpec,
    MeshSpec,
    bvp_from_dict,
)
from granular_material.runs.spec import SpecError

#: a value of the right type for every key of [[conditions]] and [initial]
VALUES = {"type": '"fixed"', "boundary": '"bottom"', "component": '"x"', "value": "0.001",
          "end": "30e3", "displacement": "[0.0, -0.001]", "rough": "false",
          "state": '"uniform"', "pressure": "20e3", "k0": "0.6", "surcharge": "10e3",
          "surface": "0.4", "minimum_pressure": "1e3", "strength_fraction": "0.7"}
#: a complete condition of every type (the keys it needs)
NEEDS = {"fixed": {}, "roller": {"component": '"y"'}, "displacement": {"component": '"y"',
                                                                          "value": "0.001"},
         "rigid": {"displacement": "[0.0, -0.001]"}, "pressure": {"value": "20e3"}}

BASE = """test = "boundary-value"
steps = 2
[mesh]
size = [0.4, 0.2]
elements = [2, 2]
[[conditions]]
type = "roller"
boundary = "left"
component = "x"
[[conditions]]
type = "{type}"
boundary = "bottom"
{keys}
[initial]
{initial}
[material]
name = "linear-elastic"
[material.parameters]
young = 60e6
poisson = 0.3
"""
UNIFORM = 'state = "uniform"\npressure = 20e3'
#: an initial table of every state, with nothing it ignores
STARTS = {"uniform": UNIFORM, "geostatic": 'state = "geostatic"\nsurcharge = 20e3',
          "continuum": 'state = "continuum"\nminimum_pressure = 1e3'}


def _text(kind: str = "fixed", keys: dict[str, str] | None = None,
          initial: str = UNIFORM) -> str:
    given = {**NEEDS[kind], **(keys or {})}
    return BASE.format(type=kind, keys="\n".join(f"{k} = {v}" for k, v in given.items()),
                       initial=initial)


def test_the_tables_of_keys_cover_every_key_of_their_scene_table():
    """The walk below reaches every key: the per-type tables partition the scene's."""
    assert set(CONDITION_KEYS) == set(CONDITION_TYPES)
    assert set().union(*CONDITION_KEYS.values()) == SCENE_KEYS["conditions"]
    assert set(INITIAL_KEYS) == set(INITIAL_STATES)
    assert set().union(*INITIAL_KEYS.values()) == SCENE_KEYS["initial"]


def test_a_scene_with_every_condition_type_and_its_keys_is_read():
    for kind in CONDITION_TYPES:
        keys = {k: VALUES[k] for k in CONDITION_KEYS[kind] - {"type", "boundary"}}
        if kind == "rigid":
            keys["rough"] = "false"  # smooth: along y
        bvp_from_dict(tomllib.loads(_text(kind, keys)))


CONDITION_CASES = [(kind, key) for kind in CONDITION_TYPES
                   for key in sorted(SCENE_KEYS["conditions"] - CONDITION_KEYS[kind])]


@pytest.mark.parametrize("kind, key", CONDITION_CASES,
                         ids=[f"{k}-{key}" for k, key in CONDITION_CASES])
def test_a_condition_key_its_type_ignores_is_refused_with_its_line(tmp_path, capsys, kind,
                                                                    key):
    text = _text(kind, {key: VALUES[key]})
    with pytest.raises(SpecError) as refused:
        bvp_from_dict(tomllib.loads(text))
    assert refused.value.field == f"conditions.{key}"
    said = str(refused.value)
    assert f"a {kind} condition" in said or (key == "end" and "only a pressure" in said)
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    out = tmp_path / "run"
    assert main(["run", str(scene), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    line = next(n for n, t in enumerate(text.splitlines(), start=1)
                if t.startswith(f"{key} =") and n > 10)  # the second condition's
    assert f"line {line}:" in err and f"conditions.{key}" in err
    assert not out.exists()


INITIAL_CASES = [(state, key) for state in INITIAL_STATES
                 for key in sorted(SCENE_KEYS["initial"] - INITIAL_KEYS[state])]


@pytest.mark.parametrize("state, key", INITIAL_CASES,
                         ids=[f"{s}-{k}" for s, k in INITIAL_CASES])
def test_an_initial_key_its_state_ignores_is_refused_with_its_line(tmp_path, capsys, state,
                                                                    key):
    initial = STARTS[state]
    text = _text(initial=f"{initial}\n{key} = {VALUES[key]}")
    with pytest.raises(SpecError) as refused:
        bvp_from_dict(tomllib.loads(text))
    assert refused.value.field == f"initial.{key}"
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    assert main(["run", str(scene), "--check"]) == 2
    line = text.splitlines().index(f"{key} = {VALUES[key]}") + 1
    assert f"line {line}:" in capsys.readouterr().err


@pytest.mark.parametrize("key, value", [("elements", "[2, 2]"), ("element", '"tri3"'),
                                        ("grading", "[2.0, 1.0]"), ("size", "[1.0, 1.0]"),
                                        ("align_x", "[0.1]")])
def test_a_generated_meshs_key_beside_a_mesh_file_is_refused(tmp_path, key, value):
    (tmp_path / "m.msh").write_text("")  # read only once the scene is accepted
    data = tomllib.loads(f'test = "boundary-value"\n[mesh]\nfile = "m.msh"\n{key} = {value}\n'
                         '[[conditions]]\ntype = "fixed"\nboundary = "base"\n')
    with pytest.raises(SpecError) as refused:
        bvp_from_dict(data, tmp_path)
    assert refused.value.field.startswith("mesh.")


def test_out_given_twice_and_a_factor_without_weight_are_refused():
    data = tomllib.loads(_text())
    with pytest.raises(SpecError, match="given twice"):
        bvp_from_dict({**data, "out": "a", "output": {"out": "b"}})
    with pytest.raises(SpecError) as refused:
        bvp_from_dict({**data, "gravity": {"factor": [1.0, 2.0]}})
    assert refused.value.field == "gravity.factor"
    bvp_from_dict({**data, "gravity": {"factor": [1.0, 2.0], "unit_weight": 18e3}})


@pytest.mark.parametrize("build, field", [
    (lambda: ConditionSpec(type="roller", boundary="b", component=0, value=1.0),
     "conditions.value"),
    (lambda: ConditionSpec(type="fixed", boundary="b", displacement=(0.0, 1.0)),
     "conditions.displacement"),
    (lambda: ConditionSpec(type="fixed", boundary="b", component=1), "conditions.component"),
    (lambda: ConditionSpec(type="pressure", boundary="b", value=1.0, rough=False),
     "conditions.rough"),
    (lambda: InitialStateSpec(state="geostatic", pressure=20e3), "initial.pressure"),
    (lambda: InitialStateSpec(state="uniform", pressure=20e3, k0=0.7), "initial.k0"),
    (lambda: InitialStateSpec(state="continuum", k0=0.7), "initial.k0"),
    (lambda: InitialStateSpec(state="geostatic", strength_fraction=0.7),
     "initial.strength_fraction"),
    (lambda: InitialStateSpec(state="continuum", strength_fraction=1.5),
     "initial.strength_fraction"),
    (lambda: MeshSpec(file=Path("m.msh"), grading=(2.0, 1.0)), "mesh.grading"),
    (lambda: BoundaryValueSpec(mesh=MeshSpec(size=(1.0, 1.0), elements=(1, 1)),
                               conditions=(ConditionSpec(type="fixed", boundary="bottom"),),
                               gravity_factor=(1.0, 2.0)), "gravity.factor"),
])
def test_the_api_refuses_what_a_scene_refuses(build, field):
    with pytest.raises(SpecError) as refused:
        build()
    assert refused.value.field == field


#: a changed value for every key of every table but [[conditions]] and [initial] (walked by
#: type and state above), [newton] (NewtonSpec's own fields) and [material.parameters] (the
#: material's own)
CHANGED = {
    "": {"test": "biaxial", "steps": 3, "name": "other", "out": "elsewhere"},
    "mesh": {"file": "m.msh", "size": [0.8, 0.2], "elements": [3, 2], "element": "tri6",
             "grading": [2.0, 1.0], "quadrature": 3, "align_x": [0.15], "align_y": [0.05]},
    "gravity": {"unit_weight": 18e3, "factor": [1.0, 2.0]},
    "material": {"name": "mohr-coulomb", "parameters": {"young": 70e6, "poisson": 0.3}},
    "output": {"out": "elsewhere", "device": "cpu", "shards": 2, "progress": True,
               "fields": False, "points_csv": True, "figures": False},
    "regularisation": {"model": "second-gradient", "internal_length": 0.01},
    "strength_reduction": {"factor_end": 2.5, "steps": 5},
}
#: the tables; [adaptivity] needs a dem material: its keys are walked in test_adaptive.py
TABLES = ("mesh", "boundaries", "conditions", "gravity", "initial", "material", "newton",
          "output", "regularisation", "regions", "materials", "phases", "strength_reduction",
          "adaptivity")
#: the materials by region: [regions] (free names, walked by changing a predicate) and a
#: changed value for every key of a [[materials]] entry (walked on the first of two)
REGIONAL = {"regions": {"lower": "y <= 0.05"},
            "materials": {"region": "upper", "name": "mohr-coulomb",
                          "parameters": {"young": 70e6}, "unit_weight": 18e3, "k0": 0.6}}


def test_the_walk_reaches_every_key_of_every_table():
    assert set(CHANGED[""]) | set(TABLES) == SCENE_KEYS[""]
    for table in ("mesh", "gravity", "material", "output", "regularisation",
                  "strength_reduction"):
        assert set(CHANGED[table]) == SCENE_KEYS[table], table
    assert set(REGIONAL["materials"]) == SCENE_KEYS["materials"]


def _regional() -> dict:
    """The scene of :func:`_text` with a material per region in place of [material]."""
    data = tomllib.loads(_text())
    del data["material"]
    data["regions"] = {"lower": "y <= 0.1", "upper": "y >= 0.1"}
    data["materials"] = [{"region": r, "name": "linear-elastic",
                          "parameters": {"young": 60e6, "poisson": 0.3}}
                         for r in ("lower", "upper")]
    return data


@pytest.mark.parametrize("table, key", [(t, k) for t, keys in REGIONAL.items() for k in keys])
def test_every_key_of_the_regions_either_acts_or_is_refused_naming_it(table, key):
    data = _regional()
    base = bvp_from_dict(data)
    changed = dict(data)
    if table == "regions":
        changed["regions"] = {**data["regions"], **REGIONAL["regions"]}
    else:
        first = {**data["materials"][0], key: REGIONAL["materials"][key]}
        changed["materials"] = [first, data["materials"][1]]
    try:
        spec = bvp_from_dict(changed)
    except SpecError as refused:
        assert refused.field.startswith(f"{table}.")
        return
    assert spec != base


def test_the_api_refuses_a_material_beside_materials_by_region():
    from granular_material.runs.boundary_value.spec import RegionMaterialSpec
    from granular_material.runs.spec import MaterialSpec

    spec = bvp_from_dict(_regional())
    with pytest.raises(SpecError) as refused:
        BoundaryValueSpec(mesh=spec.mesh, conditions=spec.conditions, regions=spec.regions,
                          materials=spec.materials,
                          material=MaterialSpec(name="mohr-coulomb"))
    assert refused.value.field == "material"
    with pytest.raises(SpecError) as refused:
        RegionMaterialSpec(region="lower", material=MaterialSpec(name="linear-elastic"),
                           unit_weight="heavy")
    assert refused.value.field == "materials.unit_weight"


WALK = [(table, key) for table, keys in CHANGED.items() for key in keys]


@pytest.mark.parametrize("table, key", WALK, ids=[f"{t or 'scene'}.{k}" for t, k in WALK])
def test_every_key_either_acts_or_is_refused_naming_it(tmp_path, table, key):
    """Changing the key's value changes the spec, or is refused naming the key (or a key of
    its table): no key is read and then dropped."""
    (tmp_path / "m.msh").write_text("")
    data = tomllib.loads(_text())
    base = bvp_from_dict(data, tmp_path)
    changed = dict(data)
    if table:
        changed[table] = {**changed.get(table, {}), key: CHANGED[table][key]}
    else:
        changed[key] = CHANGED[table][key]
    try:
        spec = bvp_from_dict(changed, tmp_path)
    except SpecError as refused:
        # named: the key, or within its table (a mesh file beside the generated mesh's keys
        # names the first of those it would ignore)
        assert refused.field == key if not table else (
            refused.field == table or refused.field.startswith(f"{table}."))
        return
    assert spec != base
