"""Boundary-value scenes (test = "boundary-value"): read whole, run into a folder, checked
against closed forms (a column under its own weight, Prandtl's bearing capacity)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from granular_material.cli import main
from granular_material.results import read_points
from granular_material.runs.boundary_value.runner import build, run_boundary_value
from granular_material.runs.boundary_value.spec import bvp_from_dict

FOOTING = """
test = "boundary-value"
name = "footing"
steps = {steps}
[mesh]
size = [0.6, 0.4]
elements = {elements}
element = "tri6"
grading = [4.0, 0.25]
align_x = [0.05]
[boundaries]
footing = "y = top and x <= 0.05"
surface = "y = top and x >= 0.05"
[[conditions]]
type = "roller"
boundary = "left"
component = "x"
[[conditions]]
type = "roller"
boundary = "right"
component = "x"
[[conditions]]
type = "fixed"
boundary = "bottom"
[[conditions]]
type = "rigid"
boundary = "footing"
displacement = [0.0, {settlement}]
[[conditions]]
type = "pressure"
boundary = "surface"
value = 20e3
[initial]
state = "uniform"
pressure = 20e3
{material}
"""
ELASTIC = ('[material]\nname = "linear-elastic"\n[material.parameters]\nyoung = 60e6\n'
           'poisson = 0.3\n')


def _scene(tmp_path: Path, text: str, name: str = "scene.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_linear_elastic_footing_runs_into_its_folder(tmp_path, capsys):
    scene = _scene(tmp_path, FOOTING.format(steps=4, elements="[8, 6]", settlement=-0.001,
                                            material=ELASTIC))
    out = tmp_path / "run"
    assert main(["run", str(scene), "--out", str(out)]) == 0
    for name in ("steps.csv", "points.npy", "fields.xdmf", "load_displacement.png",
                 "mechanism.png", "summary.json", "scene.toml"):
        assert (out / name).is_file(), name
    steps = pd.read_csv(out / "steps.csv")
    assert list(steps["step"]) == [0, 1, 2, 3, 4]
    assert steps["footing_settlement"].iloc[-1] == pytest.approx(0.001)
    # uniform 20 kPa: the footing carries 20 kPa x B at step 0, elastic: linear after
    assert steps["footing_force_y"].iloc[0] == pytest.approx(-20e3 * 0.05, rel=1e-9)
    increments = np.diff(steps["footing_force_y"].to_numpy())
    assert increments == pytest.approx(increments[0], rel=1e-2)  # finite strain: near-linear
    assert steps["surface_force_y"].iloc[0] == pytest.approx(-20e3 * 0.55, rel=1e-9)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["initial_residual"]["relative"] < 1e-10
    # finite strain: one correction for the geometric nonlinearity, to the force test's 1e-4
    assert summary["error"] is None and summary["iterations"] == [2, 2, 2, 2]
    points = read_points(out)
    assert set(points["step"]) == {0, 1, 2, 3, 4}
    assert {"mean_pressure", "shear_strain", "rotation", "unconfined"} <= set(points)


def test_output_points_csv_writes_the_table_as_text_too(tmp_path, capsys):
    """[output] points_csv = true: points.csv beside points.npy, pandas' text of the same
    table; without it, an earlier run's points.csv in the folder is removed."""
    text = FOOTING.format(steps=2, elements="[4, 3]", settlement=-0.001, material=ELASTIC)
    out = tmp_path / "run"
    assert main(["run", str(_scene(tmp_path, text + "[output]\npoints_csv = true\n")),
                 "--out", str(out)]) == 0
    points = read_points(out)
    assert set(points["step"]) == {0, 1, 2} and (out / "points.npy").is_file()
    assert (out / "points.csv").read_text() == points.to_csv(index=False)
    assert main(["run", str(_scene(tmp_path, text, "plain.toml")), "--out", str(out)]) == 0
    assert not (out / "points.csv").exists()
    pd.testing.assert_frame_equal(read_points(out), points, check_exact=True)


def test_output_figures_false_draws_none(tmp_path, capsys):
    """[output] figures = false: the tables and summary, no figure."""
    text = FOOTING.format(steps=2, elements="[4, 3]", settlement=-0.001, material=ELASTIC)
    out = tmp_path / "run"
    assert main(["run", str(_scene(tmp_path, text + "[output]\nfigures = false\n")),
                 "--out", str(out)]) == 0
    assert not list(out.glob("*.png"))
    assert set(read_points(out)["step"]) == {0, 1, 2} and (out / "summary.json").is_file()
    assert main(["run", str(_scene(tmp_path, text, "plain.toml")), "--out", str(out)]) == 0
    assert {p.name for p in out.glob("*.png")} == {"load_displacement.png", "mechanism.png"}


def test_mohr_coulomb_footing_levels_off_near_prandtl(tmp_path):
    material = ('[material]\nname = "mohr-coulomb"\n[material.parameters]\nyoung = 60e6\n'
                'poisson = 0.3\nfriction_angle = 30.0\ndilation_angle = 30.0\n[newton]\n'
                'formulation = "small-strain"\n')
    spec = bvp_from_dict(__import__("tomllib").loads(FOOTING.format(
        steps=16, elements="[12, 8]", settlement=-0.004, material=material)))
    outcome = run_boundary_value(spec)
    assert outcome.error is None
    q = -outcome.steps["footing_force_y"].to_numpy() / 0.05
    phi = math.radians(30.0)
    n_q = math.exp(math.pi * math.tan(phi)) * math.tan(math.pi / 4 + phi / 2) ** 2
    # a coarse mesh overestimates the collapse load (measured: 1.13 on 12 x 8 tri6)
    assert 1.0 < q[-1] / (20e3 * n_q) < 1.25
    assert abs(q[-1] - q[-2]) < 0.01 * q[-1]  # a plateau


def test_column_under_its_own_weight_starts_in_equilibrium(tmp_path):
    text = """
test = "boundary-value"
steps = 2
[mesh]
size = [0.2, 1.0]
elements = [1, 5]
element = "quad8"
[[conditions]]
type = "roller"
boundary = "left"
component = "x"
[[conditions]]
type = "roller"
boundary = "right"
component = "x"
[[conditions]]
type = "fixed"
boundary = "bottom"
[[conditions]]
type = "pressure"
boundary = "top"
value = 10e3
[gravity]
unit_weight = 18e3
[initial]
state = "geostatic"
k0 = 0.42857142857142855
surcharge = 10e3
[material]
name = "linear-elastic"
[material.parameters]
young = 50e6
poisson = 0.3
"""
    spec = bvp_from_dict(__import__("tomllib").loads(text))
    outcome = run_boundary_value(spec)
    assert outcome.summary["initial_residual"]["relative"] < 1e-12
    # the loads are those of the initial state: nothing moves, the base carries them all
    assert np.abs(outcome.u).max() < 1e-12
    base = outcome.steps["bottom_force_y"].iloc[-1]
    assert base == pytest.approx((10e3 + 18e3 * 1.0) * 0.2, rel=1e-9)
    p = outcome.points
    depth = 1.0 - p["y"]
    assert p["syy"].to_numpy() == pytest.approx(-(10e3 + 18e3 * depth).to_numpy(), rel=1e-9)
    assert p["sxx"].to_numpy() == pytest.approx(0.3 / 0.7 * p["syy"].to_numpy(), rel=1e-9)


def test_dem_footing_smoke(tmp_path):
    material = ('[material]\nname = "dem"\n[material.parameters]\nparticles = 64\n'
                'seed = 1\n[output]\ndevice = "cpu"\n')
    spec = bvp_from_dict(__import__("tomllib").loads(FOOTING.format(
        steps=2, elements="[3, 2]", settlement=-0.0005, material=material)))
    outcome = run_boundary_value(spec)
    assert outcome.error is None
    summary = outcome.summary
    assert summary["initial_residual"]["norm"] <= summary["initial_residual"]["newton_atol"]
    q = -outcome.steps["footing_force_y"].to_numpy() / 0.05
    assert q[0] == pytest.approx(20e3, rel=0.05)
    assert q[-1] > q[0]
    assert summary["timing_s"]["preparation"] > 0


@pytest.mark.parametrize("change, key, message", [
    (('type = "fixed"', 'type = "glued"'), "conditions.type", "must be one of"),
    (('footing = "y = top and x <= 0.05"', 'footing = "y = top and x <= -1"'), "footing",
     "selects no boundary facet"),
    (("steps = 4", "steps = 0"), "steps", "must be an integer >= 1"),
    (('state = "uniform"\npressure = 20e3', 'state = "geostatic"\nsurcharge = 20e3\nk0 = -1'),
     "initial.k0", "must be > 0"),
    (("[mesh]", "[mesh]\ncolour = 3"), "mesh.colour", "is not a key of [mesh]"),
])
def test_a_scene_that_cannot_run_is_refused_naming_its_key(tmp_path, capsys, change, key,
                                                            message):
    text = FOOTING.format(steps=4, elements="[4, 3]", settlement=-0.001, material=ELASTIC)
    assert change[0] in text
    scene = _scene(tmp_path, text.replace(*change, 1))
    out = tmp_path / "run"
    assert main(["run", str(scene), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and key in err
    assert not (out / "steps.csv").exists()


def test_check_builds_the_problem_and_runs_nothing(tmp_path, capsys):
    scene = _scene(tmp_path, FOOTING.format(steps=4, elements="[4, 3]", settlement=-0.001,
                                            material=ELASTIC))
    assert main(["run", str(scene), "--check", "--out", str(tmp_path / "run")]) == 0
    assert "checked" in capsys.readouterr().out
    assert not (tmp_path / "run").exists()


EXAMPLES = Path(__file__).parents[1] / "examples" / "scenes"
BVP_SCENES = sorted(p for p in EXAMPLES.glob("*.toml") if "boundary-value" in p.read_text())


@pytest.mark.parametrize("path", BVP_SCENES, ids=[p.stem for p in BVP_SCENES])
def test_example_boundary_value_scenes_check(path, capsys):
    if "/usr/share/doc/yade" in path.read_text() and not Path(
            "/usr/share/doc/yade/examples/FEMxDEM/footing.msh").is_file():
        pytest.skip("Guo & Zhao's footing.msh ships with Debian's yade")
    assert main(["run", str(path), "--check"]) == 0
    assert "checked" in capsys.readouterr().out


def test_geostatic_dem_start_is_within_newtons_tolerance():
    """footing-geostatic.toml: 128 RVEs, each brought to its own K0 stress; the mesh's initial
    residual is below Newton's absolute tolerance (measured 53 N/m against 98)."""
    import tomllib

    from granular_material.fem import NewtonSolver
    from granular_material.runs.boundary_value.runner import _initial_residual, build

    scene = tomllib.loads((EXAMPLES / "footing-geostatic.toml").read_text())
    scene["output"]["progress"] = False
    built = build(bvp_from_dict(scene, EXAMPLES))
    solver = NewtonSolver(built.problem.basis, built.material, built.problem.loading,
                          built.settings)
    residual = _initial_residual(solver)
    assert residual["norm"] < residual["newton_atol"]
    sigma = built.initial_stress
    assert sigma[:, 0, 0] == pytest.approx(0.5 * sigma[:, 1, 1])  # K0 = 0.5


@pytest.mark.parametrize("section, key, value, field", [
    ("mesh", "size", "0.6", "mesh.size"),
    ("mesh", "elements", [0, 3], "mesh.elements"),
    ("initial", "pressure", "20e3", "initial.pressure"),
    ("output", "shards", 0, "output.shards"),
    ("output", "progress", "yes", "output.progress"),
    (None, "steps", "58", "steps"),
])
def test_a_value_of_the_wrong_type_or_range_is_refused_naming_its_key(section, key, value,
                                                                        field):
    import tomllib

    from granular_material.runs.spec import SpecError

    scene = tomllib.loads((EXAMPLES / "footing-gz2016-cpu.toml").read_text())
    (scene.setdefault(section, {}) if section else scene)[key] = value
    with pytest.raises(SpecError) as refused:
        bvp_from_dict(scene, EXAMPLES)
    assert refused.value.field == field


def test_steps_record_the_displacement_of_every_named_boundary(tmp_path):
    """A [boundaries] name without a condition gets its mean displacement in steps.csv; a
    generated side no condition uses gets none; the other columns are as without it."""
    text = FOOTING.format(steps=2, elements="[8, 6]", settlement=-0.001, material=ELASTIC)
    plain = run_boundary_value(bvp_from_dict(__import__("tomllib").loads(text)))
    marked = text.replace("[boundaries]\n", '[boundaries]\ncorner = "y = top and x >= 0.3"\n')
    spec = bvp_from_dict(__import__("tomllib").loads(marked))
    outcome = run_boundary_value(spec)
    steps = outcome.steps
    assert "top_displacement_y" not in steps and "corner_force_y" not in steps
    assert list(steps.columns) == [*plain.steps.columns, "corner_displacement_x",
                                   "corner_displacement_y"]
    pd.testing.assert_frame_equal(steps[plain.steps.columns].drop(columns="wall_time"),
                                  plain.steps.drop(columns="wall_time"))
    problem = build(spec, allocate=False).problem
    ux, uy = problem.boundary_displacement("corner", outcome.u)
    assert steps["corner_displacement_y"].iloc[-1] == uy and uy != 0.0
    assert steps["corner_displacement_x"].iloc[-1] == ux
    assert steps["corner_displacement_y"].iloc[0] == 0.0


def test_the_refusal_of_a_folder_says_what_fits_its_run(tmp_path, capsys):
    """A rerun into the folder of a run that failed is told it cannot be resumed (another
    folder, or its checkpoint deleted); of a run stopped part-way, to --resume it; a folder
    whose summary is older than its checkpoint (an earlier run's) counts as stopped."""
    material = ('[material]\nname = "mohr-coulomb"\n[material.parameters]\nyoung = 60e6\n'
                'poisson = 0.3\nfriction_angle = 0.0\ncohesion = 5e3\n[newton]\n'
                'formulation = "small-strain"\nmax_iterations = 2\nmax_cutbacks = 0\n')
    scene = _scene(tmp_path, FOOTING.format(steps=4, elements="[8, 6]", settlement=-0.02,
                                            material=material))
    out = tmp_path / "run"
    assert main(["run", str(scene), "--out", str(out)]) == 1  # Newton fails: a failed run
    summary = json.loads((out / "summary.json").read_text())
    assert "did not converge" in summary["error"]
    assert (out / "checkpoint" / "state.npz").is_file()
    capsys.readouterr()
    before = {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    assert main(["run", str(scene), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "failed (load step" in err and "cannot be resumed" in err
    assert "another folder" in err and "--resume" not in err
    assert {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()} == before
    # the same folder had the run been stopped by Ctrl-C: resume it
    summary["error"] = "interrupted after load step 1 of 4"
    (out / "summary.json").write_text(json.dumps(summary))
    assert main(["run", str(scene), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "stopped after load step" in err and "--resume" in err and "failed" not in err
    # a failed run's summary older than the checkpoint's state: a later run was killed
    summary["error"] = "load step 2 (load factor 0.25 -> 0.5) did not converge"
    (out / "summary.json").write_text(json.dumps(summary))
    state = (out / "checkpoint" / "state.npz").stat().st_mtime_ns
    os.utime(out / "summary.json", ns=(state - 10**9, state - 10**9))
    assert main(["run", str(scene), "--out", str(out)]) == 2
    assert "--resume" in capsys.readouterr().err


def test_a_cohesive_soil_starts_stress_free_and_dem_is_refused_that_start(tmp_path):
    """initial.pressure = 0: a Tresca clay footing starts stress-free (no residual, few
    iterations a step) and levels off above Prandtl's (2 + π) c; a DEM material needs a
    pressure > 0 to prepare its RVEs, refused naming the key."""
    import tomllib

    from granular_material.runs.spec import SpecError

    material = ('[material]\nname = "mohr-coulomb"\n[material.parameters]\nyoung = 10e6\n'
                'poisson = 0.3\nfriction_angle = 0.0\ncohesion = 10e3\n[newton]\n'
                'formulation = "small-strain"\n')
    text = FOOTING.format(steps=6, elements="[12, 8]", settlement=-0.004, material=material)
    text = text.replace("pressure = 20e3", "pressure = 0.0").replace("value = 20e3",
                                                                      "value = 0.0")
    outcome = run_boundary_value(bvp_from_dict(tomllib.loads(text)))
    assert outcome.error is None
    assert outcome.summary["initial_residual"]["norm"] == 0.0
    q = -outcome.steps["footing_force_y"].to_numpy() / 0.05
    assert q[0] == 0.0
    # measured: 1.14 × (2 + π) c on this 12 × 8 tri6 mesh
    assert 1.0 < q[-1] / ((2 + math.pi) * 10e3) < 1.25
    assert max(outcome.summary["iterations"]) <= 20  # measured: 16 (one cut-back), then 3-5
    scene = tomllib.loads((EXAMPLES / "footing-gz2016-cpu.toml").read_text())
    scene["initial"]["pressure"] = 0.0
    with pytest.raises(SpecError, match="cannot start dem: an RVE") as refused:
        bvp_from_dict(scene, EXAMPLES)
    assert refused.value.field == "initial.pressure"
