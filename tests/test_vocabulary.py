"""One vocabulary (issue 57): every name a user writes (a scene key, a run-specification field,
a command's option in snake_case, a keyword of the public Python API) is a row of the one
table in docs/cli.md#vocabulary, and every row names something; the old spellings the table
gives are the ones :mod:`granular_material.vocabulary` still reads, each with a warning that
names the new one; and an old spelling is read only where its material is known."""

from __future__ import annotations

import argparse
import inspect
import json
import re
import warnings
from dataclasses import fields
from pathlib import Path

import pytest

from granular_material.cli import main
from granular_material.cli.commands import build_parser
from granular_material.cli.scene_keys import scene_keys
from granular_material.errors import ParameterError
from granular_material.fem import available_materials, load_material
from granular_material.fem.materials.linear_elastic import (
    LinearElastic,
    LinearElasticParameters,
)
from granular_material.fem.materials.mohr_coulomb import MohrCoulomb, MohrCoulombParameters
from granular_material.multiscale import DEMMaterial
from granular_material.multiscale.parameters import DEMMaterialParameters
from granular_material.procedures.calibration import calibrate_mohr_coulomb
from granular_material.procedures.packing import PackingParameters, prepare_packing
from granular_material.runs import from_flat
from granular_material.runs.boundary_value.spec import SCENE_KEYS
from granular_material.runs.dem import BiaxialDemSpec, DriveSpec, PrepareSpec
from granular_material.runs.spec import MaterialSpec, NewtonSpec, OutputSpec, ProblemSpec, RunSpec
from granular_material.vocabulary import RENAMED, RenamedWarning, renamed

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "cli.md"
EXAMPLES = ROOT / "examples" / "scenes"

#: the public classes and functions whose keywords are names a user writes
SIGNATURES = (MohrCoulomb, LinearElastic, DEMMaterial, prepare_packing, calibrate_mohr_coulomb)
#: the public parameter dataclasses whose fields are names a user writes
DATACLASSES = (MohrCoulombParameters, LinearElasticParameters, DEMMaterialParameters,
               PackingParameters, RunSpec, ProblemSpec, NewtonSpec, OutputSpec, MaterialSpec,
               PrepareSpec, BiaxialDemSpec, DriveSpec)


def code_names() -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """(names, old names) the code reads, each with where: every command's options (a
    hidden one is an old name), the boundary-value scenes' keys, the run specification's
    fields and every installed material's, and the public keywords."""
    names: dict[str, set[str]] = {}
    old: dict[str, set[str]] = {}
    for command, parser in build_parser().commands.items():
        for key, action in scene_keys(parser).items():
            hidden = action.help == argparse.SUPPRESS
            (old if hidden else names).setdefault(key, set()).add(f"{command} option")
    for table, keys in SCENE_KEYS.items():
        for key in keys:
            names.setdefault(key, set()).add(f"boundary-value scene [{table or 'top'}]")
    for kind in DATACLASSES:
        for f in fields(kind):
            names.setdefault(f.name, set()).add(kind.__name__)
    for material in available_materials():
        kind = getattr(load_material(material), "Parameters", None)
        for f in fields(kind) if kind is not None else ():
            names.setdefault(f.name, set()).add(f"{material} run parameters")
    olds = {r.old for renames in RENAMED.values() for r in renames}
    for thing in SIGNATURES:
        for p in inspect.signature(thing).parameters.values():
            if p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL):
                continue
            where = f"{thing.__name__}()"
            # a keyword that is only an old name (E= of MohrCoulomb) is one
            is_old = p.name in olds and p.default is None and p.name not in names
            (old if is_old else names).setdefault(p.name, set()).add(where)
    return names, old


_ROW = re.compile(r"^\|\s*`([A-Za-z_][A-Za-z0-9_]*)`\s*\|([^|]*)\|([^|]*)\|([^|]*)\|\s*$")


def table_rows(text: str | None = None) -> dict[str, tuple[str, str, set[str]]]:
    """The rows of docs/cli.md's vocabulary table: name → (unit, meaning, old spellings)."""
    text = DOC.read_text(encoding="utf-8") if text is None else text
    section = text.split('<a id="vocabulary"></a>', 1)[1].split("\n## ", 2)[1]
    rows: dict[str, tuple[str, str, set[str]]] = {}
    for line in section.splitlines():
        m = _ROW.match(line)
        if m:
            name, unit, meaning, olds = m.groups()
            assert name not in rows, f"{name} has two rows"
            rows[name] = (unit.strip(), meaning.strip(), set(re.findall(r"`([^`]+)`", olds)))
    return rows


def mismatches(names: dict[str, set[str]], old: dict[str, set[str]],
               rows: dict[str, tuple[str, str, set[str]]]) -> list[str]:
    """What the table and the code disagree on, in words (empty: they agree)."""
    problems = [f"{n!r} ({', '.join(sorted(w))}) has no row in docs/cli.md#vocabulary"
                for n, w in sorted(names.items()) if n not in rows]
    problems += [f"the row {n!r} names nothing the code reads" for n in sorted(rows)
                 if n not in names]
    table_old = {(o, n) for n, (_, _, olds) in rows.items() for o in olds}
    renames = {(r.old, r.new) for rs in RENAMED.values() for r in rs}
    problems += [f"{o!r} is read as {n!r} but the row {n!r} does not give it as an old spelling"
                 for o, n in sorted(renames - table_old)]
    problems += [f"the row {n!r} gives the old spelling {o!r}, which is not read as it"
                 for o, n in sorted(table_old - renames)]
    problems += [f"{o!r} ({', '.join(sorted(w))}) is read but is no old spelling of the table"
                 for o, w in sorted(old.items()) if o not in {o for o, _ in table_old}]
    problems += [f"the row {n!r} gives no unit (write - for none)" for n, (u, _, _) in
                 sorted(rows.items()) if not u]
    return problems


def test_every_name_has_one_row_and_every_row_names_something():
    names, old = code_names()
    assert mismatches(names, old, table_rows()) == []


def test_the_check_fails_on_a_missing_row_an_empty_row_and_an_unread_old_name():
    names, old = code_names()
    rows = table_rows()
    assert mismatches({**names, "yield_stress": {"X"}}, old, rows) == [
        "'yield_stress' (X) has no row in docs/cli.md#vocabulary"]
    assert mismatches(names, old, {**rows, "grain_size": ("m", "d50", set())}) == [
        "the row 'grain_size' names nothing the code reads"]
    unit, meaning, olds = rows["friction_angle"]
    problems = mismatches(names, old, {**rows, "friction_angle": (unit, meaning, olds | {"fi"})})
    assert problems == ["the row 'friction_angle' gives the old spelling 'fi', which is not "
                        "read as it"]
    assert mismatches(names, {**old, "Young": {"X"}}, rows) == [
        "'Young' (X) is read but is no old spelling of the table"]


def test_the_angles_say_their_unit():
    rows = table_rows()
    for name in ("friction_angle", "dilation_angle", "critical_friction_angle"):
        assert rows[name][0] == "°", name
    assert rows["contact_friction_angle"][0] == "rad"
    assert rows["contact_young"][0] == rows["young"][0] == "Pa"


# -- old spellings: read, warned, and never read as another quantity -----------------------
@pytest.mark.parametrize(("material", "old", "new", "value"), [
    ("mohr-coulomb", "phi", "friction_angle", 33.0),
    ("mohr-coulomb", "phi_cs", "critical_friction_angle", 28.0),
    ("mohr-coulomb", "E", "young", 2e7),
    ("linear-elastic", "nu", "poisson", 0.2),
    ("dem", "friction_angle", "contact_friction_angle", 0.3),
    ("dem", "young", "contact_young", 5e8),
])
def test_an_old_field_of_a_spec_warns_naming_the_new_one_and_is_read_as_it(material, old, new,
                                                                           value):
    flat = {"test": "single-element", "material": material, old: value}
    if old == "phi_cs":
        flat["softening_strain"] = 0.01
    with pytest.warns(RenamedWarning, match=rf"`{old}` is deprecated: it is now `{new}`"):
        spec = from_flat(flat)
    assert getattr(spec.material.parameters, new) == value
    own = {k: v for k, v in flat.items() if k not in ("test", "material")}
    with pytest.warns(RenamedWarning):
        assert MaterialSpec(name=material, parameters=own).parameters == \
            spec.material.parameters


def test_an_old_name_beside_its_new_one_is_refused():
    with pytest.raises(ParameterError, match="given twice") as refused:
        renamed({"phi": 30.0, "friction_angle": 31.0}, "mohr-coulomb")
    assert refused.value.field == "friction_angle"


def test_mohr_coulomb_s_friction_angle_is_never_read_as_the_contacts():
    """friction_angle is the soil's φ [°] for Mohr–Coulomb and the contacts' old name [rad]
    for the DEM material only: read where the material is known, and nowhere else."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RenamedWarning)  # no rename for Mohr–Coulomb
        mc = from_flat({"test": "single-element", "material": "mohr-coulomb",
                        "friction_angle": 30.0}).material.parameters
    assert mc.friction_angle == 30.0
    with pytest.raises(ParameterError, match="friction_angle"):  # no such field: refused
        MaterialSpec(name="linear-elastic", parameters={"friction_angle": 0.5})
    assert renamed({"friction_angle": 0.5}, "linear-elastic") == {"friction_angle": 0.5}


def test_an_old_checkpoint_record_resumes_quietly(tmp_path):
    """A run started before the renames keeps its options under the old names (the flat
    record of older versions, and a saved spec): both load as the new names, without a
    warning the user can do nothing about."""
    from granular_material.runs.resume import _saved_spec

    flat = {"command": "single-element", "material": "dem", "friction_angle": 0.3,
            "young": 5e8, "law": "frictmat", "steps": 3, "axial_strain": 0.01,
            "confining": 100e3}
    spec = {"problem": {"test": "single-element", "steps": 3},
            "material": {"name": "mohr-coulomb", "parameters": {"E": 2e7, "phi": 33.0}}}
    with warnings.catch_warnings():
        warnings.simplefilter("error", RenamedWarning)
        dem = _saved_spec(flat).material.parameters
        mc = _saved_spec({"spec": spec}).material.parameters
    assert (dem.contact_friction_angle, dem.contact_young, dem.law) == (0.3, 5e8, "frictmat")
    assert (mc.young, mc.friction_angle) == (2e7, 33.0)


# -- the command line -------------------------------------------------------------------------
def test_old_options_warn_on_stderr_naming_the_new_ones(tmp_path, capsys):
    """prepare's --friction-angle and --young are the contacts' (--contact-friction-angle,
    --contact-young); a FEM command's --phi is --friction-angle of mohr-coulomb, and its
    --friction-angle with --material dem the contacts' of old."""
    from granular_material.cli.fem import spec_from_args

    args = build_parser("biaxial").parse_args(["biaxial", "--friction-angle", "0.3"])
    with pytest.warns(RenamedWarning, match="`friction_angle` is deprecated: it is now "
                                            "`contact_friction_angle`"):
        spec = spec_from_args(args)
    assert spec.material.parameters.contact_friction_angle == 0.3
    args = build_parser("biaxial").parse_args(
        ["biaxial", "--material", "mohr-coulomb", "--phi", "33", "--friction-angle", "0.3"])
    with pytest.raises(ValueError, match="given twice"):
        spec_from_args(args)
    args = build_parser("biaxial").parse_args(
        ["biaxial", "--material", "mohr-coulomb", "--phi", "33", "--E", "2e7"])
    with pytest.warns(RenamedWarning) as caught:
        parameters = spec_from_args(args).material.parameters
    assert (parameters.friction_angle, parameters.young) == (33.0, 2e7)
    assert sorted(str(w.message).split("`")[1] for w in caught) == ["E", "phi"]
    out = tmp_path / "rve.npz"
    assert main(["prepare", "--particles", "16", "--device", "cpu", "--friction-angle", "0.3",
                 "--out", str(out), "--json"]) == 0
    err = capsys.readouterr().err
    assert "granular-material prepare: warning: the dem material's --friction-angle is " \
           "deprecated: it is now --contact-friction-angle ([rad]" in err
    from granular_material.dem import load_rve

    assert load_rve(out).meta.friction_angle == 0.3


def test_an_old_scene_warns_and_runs_as_the_new_one(tmp_path, capsys):
    """A scene of the old spellings (kebab-case keys, the DEM material's friction_angle) is
    read as the committed scene in the new names, each old spelling named once on stderr."""
    old = tmp_path / "old.toml"
    old.write_text('test = "single-element"\nmaterial = "dem"\nparticles = 16\n'
                   'axial-strain = 0.001\nsteps = 1\ndevice = "cpu"\n[rves]\n'
                   'friction-angle = 0.3\nradius-min = 4e-3\n')
    new = tmp_path / "new.toml"
    new.write_text('test = "single-element"\nmaterial = "dem"\nparticles = 16\n'
                   'axial_strain = 0.001\nsteps = 1\ndevice = "cpu"\n[rves]\n'
                   'contact_friction_angle = 0.3\nradius_min = 4e-3\n')
    from granular_material.cli.fem import spec_from_args
    from granular_material.cli.scene import load_scene

    assert main(["run", str(new), "--check"]) == 0
    assert "warning" not in capsys.readouterr().err
    assert main(["run", str(old), "--check"]) == 0
    warned = capsys.readouterr().err
    for key in ("axial-strain", "friction-angle", "radius-min"):
        assert f"scene key '{key}' is deprecated" in warned
    assert "'friction_angle' is deprecated: it is now 'contact_friction_angle' ([rad]" in warned
    with pytest.warns(RenamedWarning):
        was = spec_from_args(load_scene(old, out=tmp_path / "run").namespace)
    now = spec_from_args(load_scene(new, out=tmp_path / "run").namespace)
    assert was == now and now.material.parameters.contact_friction_angle == 0.3


@pytest.mark.parametrize("scene", sorted(p.name for p in EXAMPLES.glob("*.toml")))
def test_the_example_scenes_use_no_old_spelling(scene, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error", RenamedWarning)
        assert main(["run", str(EXAMPLES / scene), "--check"]) == 0
    assert "warning" not in capsys.readouterr().err


def test_a_material_file_of_old_names_is_read_as_the_new_ones(tmp_path, capsys):
    path = tmp_path / "mohr-coulomb.toml"
    path.write_text("E = 2e7\nnu = 0.25\nphi = 33.0\npsi = 3.0\n")
    from granular_material.cli.material_options import material_file_values

    with pytest.warns(RenamedWarning) as caught:
        values = material_file_values(path, "mohr-coulomb")
    assert sorted(str(w.message).split("`")[1] for w in caught) == ["E", "nu", "phi", "psi"]
    assert values == {"young": 2e7, "poisson": 0.25, "friction_angle": 33.0,
                      "dilation_angle": 3.0}
    assert json.dumps(values)  # plain values


@pytest.mark.parametrize(("argv", "old_names"), [
    (["--material", "mohr-coulomb", "--friction-angle", "33", "--young", "2e7"],
     {"friction_angle": "phi", "young": "E", "poisson": "nu", "dilation_angle": "psi",
      "critical_friction_angle": "phi_cs"}),
    (["--material", "dem", "--particles", "24", "--contact-friction-angle", "0.3"],
     {"contact_friction_angle": "friction_angle", "contact_young": "young"}),
])
def test_a_run_saved_under_the_old_names_resumes(argv, old_names, tmp_path, capsys):
    """A run whose checkpoint keeps its spec under the old field names (started by an older
    version, killed before it saved a step) resumes with the same options given in the new
    names, quietly; other values are still refused."""
    from granular_material.runs import RunCheckpoint

    out = tmp_path / "run"
    common = ["single-element", "--steps", "1", "--axial-strain", "0.001", "--device", "cpu",
              "--no-progress", *argv]
    assert main([*common, "--out", str(out)]) == 0
    checkpoint = RunCheckpoint(out / "checkpoint")
    record = checkpoint.read_options()
    parameters = record["spec"]["material"]["parameters"]
    record["spec"]["material"]["parameters"] = {old_names.get(k, k): v
                                                for k, v in parameters.items()}
    (out / "checkpoint" / "state.npz").unlink(missing_ok=True)
    checkpoint.write_options(record)
    capsys.readouterr()
    assert main([*common, "--resume", str(out)]) == 0
    assert "warning" not in capsys.readouterr().err
    (out / "checkpoint" / "state.npz").unlink(missing_ok=True)
    checkpoint.write_options(record)
    changed = [*common[:-1], "34" if argv[-1] == "2e7" else "0.35"]
    assert main([*changed, "--resume", str(out)]) == 2
