"""Materials by region in boundary-value scenes ([regions], [[materials]]): the layered
answer, a region's own unit weight, the same material in both regions equal to one
[material], regions from a mesh file's physical groups, a resume, and the refusals."""

from __future__ import annotations

import sys

import meshio
import numpy as np
import pandas as pd
import pytest
from run_helpers import run_table
from test_bvp_resume import _stop_at

from granular_material.results import read_points
from granular_material.runs.boundary_value.runner import build, run_boundary_value
from granular_material.runs.boundary_value.spec import bvp_from_dict
from granular_material.runs.spec import SpecError

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

#: a column 0.2 m wide and 0.5 m high, rollers on its sides, fixed at its base, pressed on
#: top by 20 kPa rising to ``{end}``, starting at 20 kPa; ``{materials}`` its material(s)
COLUMN = """test = "boundary-value"
steps = {steps}
[mesh]
{mesh}
[[conditions]]
type = "fixed"
boundary = "bottom"
[[conditions]]
type = "roller"
boundary = "left"
component = "x"
[[conditions]]
type = "roller"
boundary = "right"
component = "x"
[[conditions]]
type = "pressure"
boundary = "top"
value = 20e3
end = {end}
[initial]
state = "uniform"
pressure = 20e3
[newton]
formulation = "small-strain"
{materials}
"""
GENERATED = 'size = [0.2, 0.5]\nelements = [2, 4]\nelement = "quad8"'
LAYERS = '[regions]\nlower = "y <= 0.25"\nupper = "y >= 0.25"\n'


def _entry(region: str, name: str, parameters: str, extra: str = "") -> str:
    return (f'[[materials]]\nregion = "{region}"\nname = "{name}"\n{extra}'
            f'[materials.parameters]\n{parameters}\n')


def _elastic(young: float) -> str:
    return f"young = {young}\npoisson = 0.3"


MC = "young = 40e6\npoisson = 0.3\nfriction_angle = 15.0\ncohesion = 1e3"


def _spec(materials: str, end: float = 120e3, steps: int = 2, mesh: str = GENERATED,
          folder=".", **extra) -> object:
    data = tomllib.loads(COLUMN.format(materials=materials, end=end, steps=steps, mesh=mesh))
    data.update(extra)
    return bvp_from_dict(data, folder)


M = (1 - 0.3) / ((1 + 0.3) * (1 - 0.6))  # constrained modulus over E at ν = 0.3


def test_two_layers_settle_by_the_sum_of_their_compressions(tmp_path):
    e_lower, e_upper = 20e6, 80e6
    spec = _spec(LAYERS + _entry("lower", "linear-elastic", _elastic(e_lower))
                 + _entry("upper", "linear-elastic", _elastic(e_upper)))
    outcome = run_boundary_value(spec, out=tmp_path / "run")
    assert outcome.error is None
    dp = 100e3
    expected = -dp * 0.25 / (M * e_lower) - dp * 0.25 / (M * e_upper)
    assert outcome.steps["top_displacement_y"].iloc[-1] == pytest.approx(expected, rel=1e-9)
    points = read_points(tmp_path / "run")
    last = points[points.step == 2]
    assert set(last.region) == {"lower", "upper"}
    assert (last.region == np.where(last.y < 0.25, "lower", "upper")).all()
    # each point's stress is the one its own layer gives: σxx = ν/(1−ν) Δσyy + σ0
    for _, layer in last.groupby("region"):
        assert layer.syy.to_numpy() == pytest.approx(-120e3, rel=1e-9)
    # ParaView: each element's region, numbered in the alphabetical order of the names
    fields = (tmp_path / "run" / "fields.xdmf").read_text()
    assert fields.count('Name="region"') == 3  # steps 0, 1, 2
    summary = outcome.summary
    assert summary["material"] == "regions"
    assert summary["regions"]["lower"] == {"material": "linear-elastic", "unit_weight": 0.0,
                                           "gauss_points": 16}


@pytest.mark.filterwarnings("ignore::UserWarning")  # a uniform start out of equilibrium
def test_each_region_weighs_its_own_unit_weight():
    g_lower, g_upper, e = 20e3, 10e3, 30e6
    spec = _spec(LAYERS + _entry("lower", "linear-elastic", _elastic(e), f"unit_weight = "
                                 f"{g_lower}\n")
                 + _entry("upper", "linear-elastic", _elastic(e), f"unit_weight = {g_upper}\n"),
                 end=20e3, steps=1)
    outcome = run_boundary_value(spec)
    assert outcome.error is None
    # σv from the weight above: the upper layer compresses by γu h²/2M, the lower by
    # (γu h + γl h/2) h/M
    h, m = 0.25, M * e
    expected = -(g_upper * h * h / 2 + g_upper * h * h + g_lower * h * h / 2) / m
    assert outcome.steps["top_displacement_y"].iloc[-1] == pytest.approx(expected, rel=1e-9)
    assert outcome.steps["bottom_force_y"].iloc[-1] == pytest.approx(
        0.2 * (20e3 + g_lower * h + g_upper * h), rel=1e-9)


def test_one_material_in_both_regions_is_the_one_material_bit_for_bit(tmp_path):
    one = run_boundary_value(_spec('[material]\nname = "mohr-coulomb"\n[material.parameters]\n'
                                   + MC, end=150e3, steps=3), out=tmp_path / "one")
    two = run_boundary_value(_spec(LAYERS + _entry("lower", "mohr-coulomb", MC)
                                   + _entry("upper", "mohr-coulomb", MC), end=150e3, steps=3),
                             out=tmp_path / "two")
    assert one.error is None and two.error is None
    assert one.points.plastic_shear_strain.max() > 0  # it yielded
    np.testing.assert_array_equal(one.u, two.u)
    pd.testing.assert_frame_equal(one.points, two.points.drop(columns="region"),
                                  check_exact=True)
    costs = ["wall_time", "return_iterations"]  # the regions' return iterations add up
    pd.testing.assert_frame_equal(one.steps.drop(columns=costs),
                                  two.steps.drop(columns=costs), check_exact=True)


def _layered_file(path) -> str:
    """A 2 × 4 quad mesh of the column with physical groups "clay" (lower half), "sand"
    (upper half) and its four sides; its [mesh] table."""
    x, y = np.meshgrid(np.linspace(0, 0.2, 3), np.linspace(0, 0.5, 5))
    points = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    quads = [[3 * j + i, 3 * j + i + 1, 3 * (j + 1) + i + 1, 3 * (j + 1) + i]
             for j in range(4) for i in range(2)]
    lines = {"bottom": [[0, 1], [1, 2]], "top": [[12, 13], [13, 14]],
             "left": [[0, 3], [3, 6], [6, 9], [9, 12]],
             "right": [[2, 5], [5, 8], [8, 11], [11, 14]]}
    tags = {"clay": 1, "sand": 2, "bottom": 3, "top": 4, "left": 5, "right": 6}
    cells = [("quad", np.array(quads))] + [("line", np.array(v)) for v in lines.values()]
    physical = [np.array([1] * 4 + [2] * 4)] + [np.full(len(v), tags[k])
                                                for k, v in lines.items()]
    mesh = meshio.Mesh(points, cells, cell_data={"gmsh:physical": physical,
                                                 "gmsh:geometrical": physical},
                       field_data={k: np.array([t, 2 if t < 3 else 1]) for k, t in tags.items()})
    meshio.write(path, mesh, file_format="gmsh22", binary=False)
    return f'file = "{path.name}"'


def test_physical_groups_of_the_mesh_file_are_regions(tmp_path):
    mesh = _layered_file(tmp_path / "column.msh")
    e_clay, e_sand = 10e6, 50e6
    spec = _spec(_entry("clay", "linear-elastic", _elastic(e_clay))
                 + _entry("sand", "linear-elastic", _elastic(e_sand)), mesh=mesh,
                 folder=tmp_path)
    outcome = run_boundary_value(spec)
    expected = -100e3 * 0.25 * (1 / (M * e_clay) + 1 / (M * e_sand))
    assert outcome.steps["top_displacement_y"].iloc[-1] == pytest.approx(expected, rel=1e-9)
    # a [regions] entry may name a group under another name
    renamed = _spec('[regions]\nsoft = "clay"\n' + _entry("soft", "linear-elastic",
                                                          _elastic(e_clay))
                    + _entry("sand", "linear-elastic", _elastic(e_sand)), mesh=mesh,
                    folder=tmp_path)
    np.testing.assert_array_equal(run_boundary_value(renamed).u, outcome.u)


def test_a_stopped_regional_run_resumes_to_the_run_that_never_stopped(tmp_path, monkeypatch):
    def spec():
        return _spec(LAYERS + _entry("lower", "mohr-coulomb", MC)
                     + _entry("upper", "linear-elastic", _elastic(30e6)), end=150e3, steps=4)

    whole = run_boundary_value(spec(), out=tmp_path / "whole")
    with monkeypatch.context() as m:
        _stop_at(m, 3)
        stopped = run_boundary_value(spec(), out=tmp_path / "run")
    assert "interrupted after load step 2" in stopped.error
    resumed = run_boundary_value(spec(), out=tmp_path / "run", resume=True)
    assert resumed.error is None and 0 <= resumed.summary["resumed_from_step"] <= 2
    np.testing.assert_array_equal(whole.u, resumed.u)
    for name in ("steps.csv", "points.csv"):
        a, b = (run_table(tmp_path / run, name) for run in ("whole", "run"))
        pd.testing.assert_frame_equal(a.drop(columns=["wall_time"], errors="ignore"),
                                      b.drop(columns=["wall_time"], errors="ignore"),
                                      check_exact=True)


@pytest.mark.parametrize(("materials", "field", "match"), [
    (_entry("rock", "linear-elastic", ""), "materials.region",
     "'rock' is no region of \\[regions\\]"),
    ('[regions]\nall = "y >= 0"\n' + _entry("all", "linear-elastic", "")
     + _entry("all", "linear-elastic", ""), "materials.region", "given two materials"),
    (LAYERS + _entry("lower", "linear-elastic", ""), "regions.upper",
     "is given no material"),
    (LAYERS, "regions", "no \\[\\[materials\\]\\]"),
    ('[material]\nname = "linear-elastic"\n' + LAYERS + _entry("lower", "linear-elastic", "")
     + _entry("upper", "linear-elastic", ""), "material", "beside \\[\\[materials\\]\\]"),
    ('[regions]\nall = "y >= 0"\n[[materials]]\nregion = "all"\nname = "linear-elastic"\n'
     'colour = "red"\n', "materials.colour", "is not a key of \\[materials\\]"),
    ('[regions]\nall = "y >= 0"\n[[materials]]\nregion = "all"\n', "materials.name",
     "names its material"),
    ('[regions]\nall = "y >= 0"\n' + _entry("all", "linear-elastic", "stiffness = 1"),
     "materials.parameters.stiffness", "no parameter"),
    ('[regions]\nall = "y >= 0"\n' + _entry("all", "linear-elastic", "", "unit_weight = -1\n"),
     "materials.unit_weight", ">= 0"),
    ('[regions]\nall = 3\n', "regions.all", "must be a predicate"),
])
def test_bad_region_tables_are_refused_naming_the_key(materials, field, match):
    with pytest.raises(SpecError, match=match) as info:
        _spec(materials)
    assert info.value.field == field


@pytest.mark.parametrize(("regions", "field", "match"), [
    ('a = "y <= 0.35"\nb = "y >= 0.15"', "regions", "lies in two regions"),
    ('a = "y <= 0.15"\nb = "y >= 0.35"', "regions", "lie in no region"),
    ('a = "y <= 0.5"\nb = "y >= 9"', "regions.b", "selects no element"),
])
def test_regions_that_overlap_leave_cells_out_or_select_nothing_are_refused(regions, field,
                                                                            match):
    spec = _spec(f"[regions]\n{regions}\n" + _entry("a", "linear-elastic", "")
                 + _entry("b", "linear-elastic", ""))
    with pytest.raises(SpecError, match=match) as info:
        build(spec, allocate=False)
    assert info.value.field == field


def test_a_gravity_on_elements_outside_the_mesh_is_refused():
    from granular_material.errors import ParameterError
    from granular_material.fem import Fixed, Gravity, build_problem, rectangle_mesh

    data = rectangle_mesh(0.2, 0.5, 2, 4)
    with pytest.raises(ParameterError, match="names element 8; the mesh has 8"):
        build_problem(data, [Fixed("bottom"), Gravity(1e4, elements=np.array([0, 8]))])
    with pytest.raises(ParameterError, match="1-D array of element indices"):
        Gravity(1e4, elements=np.array([-1]))


def test_an_unknown_physical_group_is_refused_and_a_geostatic_start_of_two_weights_built(
        tmp_path):
    mesh = _layered_file(tmp_path / "column.msh")
    spec = _spec(_entry("clay", "linear-elastic", "") + _entry("rock", "linear-elastic", ""),
                 mesh=mesh, folder=tmp_path)
    with pytest.raises(SpecError, match="'rock' is neither a region of \\[regions\\] nor a "
                                        "physical group of the mesh's cells \\(it has clay, "
                                        "sand\\)"):
        build(spec, allocate=False)
    spec = _spec(LAYERS + _entry("lower", "linear-elastic", "", "unit_weight = 2e4\n")
                 + _entry("upper", "linear-elastic", ""),
                 initial={"state": "geostatic", "surcharge": 20e3})
    b = build(spec, allocate=False)  # each layer its own weight (the upper one 0 here)
    xy = b.problem.points
    sigma_v = 20e3 + 2e4 * np.maximum(0.25 - xy[:, 1], 0.0)
    np.testing.assert_allclose(-b.initial_stress[:, 1, 1], sigma_v, rtol=1e-12)
    assert b.initial["corrected_residual"] < 1e-12 and b.initial["lifted_points"] == 0


def test_a_dem_region_beside_a_linear_elastic_one_runs_with_the_noisy_defaults(tmp_path):
    dem = ('particles = 16\nseed = 1\ntangent = "kruyt-rothenburg"')
    spec = _spec(LAYERS + _entry("lower", "dem", dem) + _entry("upper", "linear-elastic",
                                                               _elastic(30e6)),
                 end=22e3, steps=1, mesh='size = [0.2, 0.5]\nelements = [1, 2]',
                 output={"device": "cpu"})
    assert spec.noisy
    b = build(spec)
    assert b.material.noisy and b.settings.stall_rtol > 0  # a noisy material's defaults
    outcome = run_boundary_value(spec, out=tmp_path / "run")
    assert outcome.error is None
    points = outcome.points[outcome.points.step == 1]
    lower = points[points.region == "lower"]
    assert lower.void_ratio.notna().all()  # the DEM's own field, where it is the material
    assert points[points.region == "upper"].void_ratio.isna().all()


def test_the_command_line_names_the_line_of_a_bad_key_in_a_region_s_parameters(tmp_path,
                                                                                capsys):
    from granular_material.cli import main

    text = COLUMN.format(materials=LAYERS + _entry("lower", "linear-elastic", _elastic(1e7))
                         + _entry("upper", "linear-elastic", "stiffness = 3"), end=30e3,
                         steps=1, mesh=GENERATED)
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    assert main(["run", str(scene), "--out", str(tmp_path / "run")]) == 2
    line = text.splitlines().index("stiffness = 3") + 1
    err = capsys.readouterr().err
    assert f"line {line}: materials.parameters.stiffness is no parameter" in err
    assert not (tmp_path / "run").exists()
    scene.write_text(text.replace("stiffness = 3", "young = 3e7"))
    assert main(["run", str(scene), "--check"]) == 0
    assert "materials lower: linear-elastic, upper: linear-elastic: checked" in (
        capsys.readouterr().out)
