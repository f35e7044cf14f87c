"""Adaptivity for the biaxial specimen: the run specification's ``adaptivity``, the biaxial
command's options, one RVE a point as the adaptive material's source (each point switching
to its own RVE), the summary, the steps table and a resume."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from run_helpers import StopAfterRecord

from granular_material.cli import main
from granular_material.errors import ParameterError
from granular_material.fem import MohrCoulomb, create_material
from granular_material.multiscale import DEMMaterial, adaptive
from granular_material.multiscale.adaptive import AdaptiveMaterial
from granular_material.multiscale.switching import SwitchCriterion
from granular_material.runs import from_dict, from_flat, run, to_dict, to_flat
from granular_material.runs.serial import to_toml
from granular_material.runs.spec import (
    AdaptivitySpec,
    MaterialSpec,
    OutputSpec,
    ProblemSpec,
    RunSpec,
    SpecError,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

#: a tiny specimen: 1 x 1 quad4 (4 points) of 16-disc RVEs, to 1 % in 4 steps
TINY = ["biaxial", "--elements", "1", "1", "--particles", "16", "--axial-strain", "0.01",
        "--steps", "4", "--device", "cpu", "--map-strain", "0.01", "--no-progress"]


def _calibration(folder: Path) -> Path:
    """A calibration.json (the twin without its DEM test: the tests stay short)."""
    path = folder / "calibration.json"
    path.write_text(json.dumps({"parameters": {
        "young": 40e6, "poisson": 0.2, "friction_angle": 30.0, "dilation_angle": 5.0,
        "cohesion": 0.0, "critical_friction_angle": 25.0, "softening_strain": 0.05},
        "pressure": 100e3}))
    return path


def _spec(out: Path | None, adaptivity: AdaptivitySpec | None) -> RunSpec:
    return from_flat({"test": "biaxial", "material": "dem", "elements": [1, 1],
                      "particles": 16, "axial_strain": 0.01, "steps": 4, "device": "cpu",
                      "map_strain": [0.01], "out": out, "checkpoint_every": 1,
                      **({} if adaptivity is None else {"adaptivity": True,
                                                        **to_dict_of(adaptivity)})})


def to_dict_of(adaptivity: AdaptivitySpec) -> dict:
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(adaptivity).items()}


# -- the run specification -------------------------------------------------------------------
@pytest.mark.parametrize("adaptivity", [
    None, AdaptivitySpec(), AdaptivitySpec(mobilised_fraction=None, shear_strain=0.004,
                                           neighbours="point", start="stress",
                                           switch="after-step"),
    AdaptivitySpec(calibration=Path("calibration.json"))])
def test_the_spec_round_trips_with_and_without_adaptivity(adaptivity):
    spec = RunSpec(problem=ProblemSpec(test="biaxial"), material=MaterialSpec(name="dem"),
                   adaptivity=adaptivity)
    assert from_dict(to_dict(spec)) == spec
    assert from_dict(json.loads(json.dumps(to_dict(spec)))) == spec
    assert from_flat(to_flat(spec)) == spec
    assert from_dict(tomllib.loads(to_toml(spec))) == spec
    assert to_flat(spec)["adaptivity"] is (adaptivity is not None)


def test_a_shear_strain_alone_is_the_only_threshold_and_settings_need_adaptivity():
    flat = {"test": "biaxial", "material": "dem"}
    spec = from_flat({**flat, "adaptivity": True, "shear_strain": 0.01})
    assert spec.adaptivity == AdaptivitySpec(mobilised_fraction=None, shear_strain=0.01)
    assert from_flat({**flat, "adaptivity": True}).adaptivity == AdaptivitySpec()
    assert from_flat(flat).adaptivity is None
    with pytest.raises(SpecError) as refused:
        from_flat({**flat, "start": "stress"})
    assert refused.value.field == "start" and "needs `adaptivity`" in str(refused.value)


@pytest.mark.parametrize("adaptivity", [
    AdaptivitySpec(), AdaptivitySpec(shear_strain=0.01),
    AdaptivitySpec(mobilised_fraction=None, shear_strain=0.01, start="stress")])
def test_an_adaptive_spec_s_command_line_makes_the_same_spec(adaptivity):
    import shlex

    from granular_material.cli import build_parser
    from granular_material.cli.fem import command_line, spec_from_args

    parser = build_parser()  # registers the commands' parsers
    spec = RunSpec(problem=ProblemSpec(test="biaxial"), material=MaterialSpec(name="dem"),
                   output=OutputSpec(progress=False), adaptivity=adaptivity)
    words = shlex.split(command_line(spec))[1:]
    assert "--adaptivity" in words
    assert spec_from_args(parser.parse_args([*words, "--no-progress"])) == spec


@pytest.mark.parametrize("changes, words", [
    ({"material": MaterialSpec(name="mohr-coulomb")}, "needs `material` dem"),
    ({"problem": ProblemSpec(test="single-element")}, "biaxial specimen's"),
    ({"backend": "mpi"}, "`backend` mpi"),
    ({"output": OutputSpec(track=("0",))}, "`track`"),
])
def test_the_spec_refuses_adaptivity_where_it_cannot_act(changes, words):
    given = {"problem": ProblemSpec(test="biaxial"), "material": MaterialSpec(name="dem"),
             "adaptivity": AdaptivitySpec(), **changes}
    with pytest.raises(SpecError, match=words) as refused:
        RunSpec(**given)
    assert refused.value.field == "adaptivity"


# -- the command's options -------------------------------------------------------------------
@pytest.mark.parametrize("argv, said", [
    (["--material", "mohr-coulomb", "--adaptivity"], "--adaptivity puts DEM RVEs"),
    (["--start", "stress"], "--start is a setting of adaptivity: it needs --adaptivity"),
    (["--adaptivity", "--mobilised-fraction", "1.5"], "--mobilised-fraction must be"),
    (["--adaptivity", "--calibration", "missing.json"], "is no file"),
])
def test_the_command_refuses_adaptivity_that_cannot_act(argv, said, tmp_path, capsys,
                                                        monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main([*TINY, *argv, "--out", str(tmp_path / "run")]) == 2
    assert said in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


# -- one RVE a point -------------------------------------------------------------------------
def _own_rves(n: int):
    dem = create_material("dem", particles=16, device="cpu", shards=1)
    dem.allocate(n)
    return dem.committed_rves(), dem.parameters


def test_each_point_switches_to_its_own_rve():
    """A source of one RVE a point: a switching point's RVE is its own, driven through its
    deformation (not a copy of the first); a source of another count is refused."""
    source, parameters = _own_rves(3)
    twin = MohrCoulomb(young=60e6, poisson=0.3, friction_angle=30.0, initial_stress=-100e3)
    material = AdaptiveMaterial(twin, 30.0, parameters, source,
                                SwitchCriterion(0.5, neighbours="point"), start="strain")
    material.allocate(3)
    grad = np.zeros((3, 2, 2))
    grad[:, 1, 1], grad[:, 0, 0] = -1e-3, 5e-4
    committed = 0
    for _ in range(10):
        response = material.evaluate(grad)
        if material.dem_points == 3:
            break
        material.commit()
        committed += 1
    assert material.dem_points == 3
    deformation = np.linalg.matrix_power(np.eye(2) + grad[0], committed)
    for point in range(3):
        alone = DEMMaterial.holding(source.take([point]), parameters)
        assert alone.evaluate((deformation - np.eye(2))[None]).ok
        alone.commit()
        np.testing.assert_array_equal(response.stress[point],
                                      alone.evaluate(grad[:1]).stress[0])
    assert len({float(s) for s in response.stress[:, 1, 1]}) == 3  # three packings
    wrong = AdaptiveMaterial(MohrCoulomb(young=60e6, poisson=0.3, friction_angle=30.0,
                                         initial_stress=-100e3), 30.0, parameters,
                             source.take([0, 1]))
    with pytest.raises(ParameterError) as refused:
        wrong.allocate(3)
    assert refused.value.field == "source"


# -- runs ------------------------------------------------------------------------------------
def test_an_adaptive_specimen_reports_its_dem_points(tmp_path, capsys):
    calibration = _calibration(tmp_path)
    out = tmp_path / "run"
    code = main([*TINY, "--adaptivity", "--mobilised-fraction", "0.5", "--calibration",
                 str(calibration), "--out", str(out), "--json"])
    summary = json.loads(capsys.readouterr().out)
    assert code == 0, summary["error"]
    steps = pd.read_csv(out / "steps.csv")
    assert steps["dem_points"].iloc[0] == 0 and steps["dem_points"].iloc[-1] == 4
    assert steps["dem_points"].is_monotonic_increasing
    said = summary["adaptivity"]
    assert said["dem_points_final"] == 4 and said["mobilised_fraction"] == 0.5
    assert said["twin"]["parameters"]["friction_angle"] == 30.0
    assert steps["switch_particle_steps"].sum() == sum(s["particle_steps"]
                                                       for s in said["switches"]) > 0
    # the twin's steps cost no DEM work; the steps after the switch do
    first = int(np.argmax(steps["dem_points"].to_numpy() > 0))
    assert (steps["particle_steps"].iloc[:first] == 0).all()
    assert (steps["particle_steps"].iloc[first:] > 0).all()
    # the run's own record gives the command line back, adaptivity included
    saved = json.loads((out / "checkpoint" / "options.json").read_text())
    assert from_dict(saved["spec"]).adaptivity.mobilised_fraction == 0.5


def test_without_adaptivity_the_steps_table_is_as_before(tmp_path):
    outcome = run(_spec(tmp_path / "run", None))
    assert outcome.result.error is None and "adaptivity" not in outcome.summary
    columns = pd.read_csv(tmp_path / "run" / "steps.csv").columns
    assert "dem_points" not in columns and "switch_particle_steps" not in columns


def test_a_stopped_adaptive_specimen_resumes_to_the_run_that_never_stopped(tmp_path,
                                                                          monkeypatch):
    adaptivity = AdaptivitySpec(mobilised_fraction=0.5, calibration=_calibration(tmp_path))
    whole = run(_spec(tmp_path / "whole", adaptivity))
    assert whole.result.error is None
    assert whole.summary["adaptivity"]["dem_points_final"] > 0
    spec = _spec(tmp_path / "part", adaptivity)
    stopped = run(spec, StopAfterRecord(3))
    assert stopped.interrupt is not None

    def made_again(*args, **kwargs):
        raise AssertionError("a resume prepared its RVEs and made its twin again")

    with monkeypatch.context() as m:  # made from the checkpoint: nothing prepared again
        m.setattr(adaptive, "calibrated_adaptive", made_again)
        m.setattr(DEMMaterial, "allocate", made_again)
        resumed = run(spec, resume=True)
    twins = [{k: v for k, v in o.summary["adaptivity"]["twin"].items() if k != "seconds"}
             for o in (whole, resumed)]
    assert twins[0] == twins[1]
    assert resumed.result.error is None and resumed.result.resumed_from is not None
    steps = whole.result.steps  # the checkpoint it resumed from held DEM points
    assert steps["dem_points"].iloc[resumed.result.resumed_from] > 0
    for name in ("steps.csv",):
        a = pd.read_csv(tmp_path / "whole" / name).drop(columns=["wall_time"])
        b = pd.read_csv(tmp_path / "part" / name).drop(columns=["wall_time"])
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    np.testing.assert_array_equal(whole.result.displacements, resumed.result.displacements)
    pd.testing.assert_frame_equal(whole.result.points, resumed.result.points,
                                  check_exact=True)
