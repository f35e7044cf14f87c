"""A boundary-value scene in phases ([[phases]]): each phase from the state the one before
committed, loads as totals at a phase's end, prescribed displacements as increments; a failed
phase keeps the earlier ones' results; a resumed phased run equals the one that never
stopped; every key acts or is refused."""

from __future__ import annotations

import copy
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from run_helpers import run_table

from granular_material.fem import NewtonError
from granular_material.fem.boundary_value.loading import Loading
from granular_material.fem.solver.newton import NewtonSolver
from granular_material.results import read_points
from granular_material.runs.boundary_value.phases import phase_of_step
from granular_material.runs.boundary_value.runner import build, run_boundary_value
from granular_material.runs.boundary_value.spec import SCENE_KEYS, bvp_from_dict
from granular_material.runs.checkpoint import RunCheckpoint
from granular_material.runs.spec import SpecError

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

ELASTIC = {"name": "linear-elastic", "parameters": {"young": 20e6, "poisson": 0.3}}
MOHR_COULOMB = {"name": "mohr-coulomb",
                "parameters": {"young": 20e6, "poisson": 0.3, "friction_angle": 30.0,
                               "dilation_angle": 5.0, "cohesion": 5e3}}
ROLLERS = [{"type": "fixed", "boundary": "bottom"},
           {"type": "roller", "boundary": "left", "component": "x"}]


def _scene(material=ELASTIC, formulation="small-strain", **extra) -> dict:
    """A 1 m × 0.5 m block on a fixed base, held at its left side, under its own weight
    (geostatic start at a factor 0: stress-free), in two phases: gravity on with a
    surcharge raised on the top and the right side pulled out, then more of both."""
    scene = {
        "test": "boundary-value", "name": "block",
        "mesh": {"size": [1.0, 0.5], "elements": [3, 2], "element": "quad8"},
        "boundaries": {"strip": "y = top and x <= 0.34"},
        "gravity": {"unit_weight": 18e3}, "initial": {"state": "geostatic"},
        "material": material, "newton": {"formulation": formulation},
        "conditions": ROLLERS,
        "phases": [
            {"name": "gravity", "steps": 2, "gravity": {"factor": [0.0, 1.0]},
             "conditions": [{"type": "pressure", "boundary": "top", "value": 0.0,
                             "end": 10e3},
                            {"type": "displacement", "boundary": "right",
                             "component": "x", "value": 2e-4}]},
            {"name": "load", "steps": 3,
             "conditions": [{"type": "pressure", "boundary": "top", "value": 25e3},
                            {"type": "pressure", "boundary": "strip", "value": 15e3},
                            {"type": "displacement", "boundary": "right",
                             "component": "x", "value": 3e-4}]},
        ],
        "output": {"fields": False},
    }
    scene.update(extra)
    return scene


def test_two_linear_elastic_phases_end_where_one_phase_of_the_summed_loads_does():
    phased = run_boundary_value(bvp_from_dict(_scene()), out=None)
    one = _scene()
    del one["phases"]
    one.update(steps=4, gravity={"unit_weight": 18e3, "factor": [0.0, 1.0]},
               conditions=[*ROLLERS,
                           {"type": "pressure", "boundary": "top", "value": 0.0, "end": 25e3},
                           {"type": "pressure", "boundary": "strip", "value": 0.0,
                            "end": 15e3},
                           {"type": "displacement", "boundary": "right", "component": "x",
                            "value": 5e-4}])
    single = run_boundary_value(bvp_from_dict(one), out=None)
    assert phased.error is None and single.error is None
    assert list(phased.steps["step"]) == [0, 1, 2, 3, 4, 5]
    assert list(phased.steps["phase"]) == ["gravity"] * 3 + ["load"] * 3
    # the right side went 2e-4 in the first phase and 3e-4 more in the second
    right = phased.steps["right_displacement_x"].to_numpy()
    assert right[2] == pytest.approx(2e-4, rel=1e-12)
    assert right[-1] == pytest.approx(5e-4, rel=1e-12)
    scale = np.abs(single.u).max()
    np.testing.assert_allclose(phased.u, single.u, rtol=0, atol=1e-9 * scale)
    for column in ("sxx", "syy", "sxy"):
        a, b = phased.points[column].to_numpy(), single.points[column].to_numpy()
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * np.abs(b).max())
    summary = phased.summary
    assert [p["status"] for p in summary["phases"]] == ["completed", "completed"]
    assert summary["steps_planned"] == 5 and summary["failed_phase"] is None
    assert summary["phases"][1]["start_residual"] < 1e-9  # continuous loads: in balance


@pytest.mark.parametrize("formulation", ["updated-lagrangian", "small-strain"])
def test_a_reset_reports_from_the_phase_start_and_changes_nothing_else(formulation, tmp_path):
    """The configuration is where the first phase left it (updated-Lagrangian: x = X + u
    with the total u); only what is reported starts again from zero (the stress is the
    same bit for bit)."""
    runs = {}
    for reset in (False, True):
        scene = _scene(formulation=formulation)
        scene["phases"][1]["reset_displacements"] = reset
        runs[reset] = run_boundary_value(bvp_from_dict(scene), out=None)
    kept, reset = runs[False], runs[True]
    assert kept.error is None and reset.error is None
    # the follower pressures go on where the first phase left them: the start is in balance
    # but for the first phase's last converged residual (a jump in the load would be O(1))
    assert reset.summary["phases"][1]["start_residual"] < 1e-5
    for column in ("sxx", "syy", "sxy", "mean_pressure"):
        np.testing.assert_array_equal(kept.points[column], reset.points[column])
    start = kept.steps.iloc[2]  # the end of the first phase
    for column in ("right_displacement_x", "top_displacement_y"):
        np.testing.assert_allclose(reset.steps[column].iloc[3:],
                                   kept.steps[column].iloc[3:] - start[column],
                                   rtol=0, atol=1e-15)
        assert reset.steps[column].iloc[2] == kept.steps[column].iloc[2]  # before the reset
    # the strain reported is the deformation's since the reset: smaller than the total
    assert reset.points["shear_strain"].abs().max() < kept.points["shear_strain"].abs().max()
    if formulation == "small-strain":  # then exactly the total less the strain at the reset
        with_steps = run_boundary_value(bvp_from_dict(_scene(formulation=formulation)),
                                        out=tmp_path / "run")
        points = read_points(tmp_path / "run")
        at_reset = points[points["step"] == 2].reset_index(drop=True)
        for column in ("exx", "eyy", "exy"):
            np.testing.assert_allclose(reset.points[column].to_numpy(),
                                       (kept.points[column] - at_reset[column]).to_numpy(),
                                       rtol=0, atol=1e-15)
        assert with_steps.error is None


def test_a_failing_phase_keeps_the_earlier_phases_results(tmp_path, monkeypatch):
    original = NewtonSolver.step

    def fail_at_4(self, target, k):
        if k == 4:
            raise NewtonError(f"load step {k} did not converge (test)", list(self.records))
        return original(self, target, k)

    monkeypatch.setattr(NewtonSolver, "step", fail_at_4)
    outcome = run_boundary_value(bvp_from_dict(_scene()), out=tmp_path / "run")
    assert outcome.error.startswith("phase 2 ('load'): load step 4 did not converge")
    steps = pd.read_csv(tmp_path / "run" / "steps.csv")
    assert list(steps["step"]) == [0, 1, 2, 3]
    assert list(steps["phase"]) == ["gravity"] * 3 + ["load"]
    assert set(read_points(tmp_path / "run")["phase"]) == {"gravity", "load"}
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["failed_phase"] == "load"
    first, second = summary["phases"]
    assert first["status"] == "completed" and first["load_factor"] == 1.0
    assert second["status"] == "failed" and second["steps_done"] == 1
    assert second["load_factor"] == pytest.approx(1 / 3)
    assert "did not converge" in second["error"]
    assert (tmp_path / "run" / "mechanism.png").is_file()


def _stop_at(monkeypatch, step: int) -> None:
    original = NewtonSolver.step

    def step_or_stop(self, target, k):
        if k == step:
            raise KeyboardInterrupt
        return original(self, target, k)

    monkeypatch.setattr(NewtonSolver, "step", step_or_stop)


@pytest.mark.parametrize("stop", [3, 5], ids=["at-the-phase-start", "inside-the-phase"])
def test_a_phased_run_resumed_inside_a_phase_equals_the_one_that_never_stopped(
        tmp_path, monkeypatch, stop):
    scene = _scene(material=MOHR_COULOMB)
    scene["phases"][1]["reset_displacements"] = True
    scene["phases"][1]["steps"] = 4
    whole = run_boundary_value(bvp_from_dict(scene), out=tmp_path / "whole")
    assert whole.error is None
    with monkeypatch.context() as m:
        _stop_at(m, stop)
        m.setattr(RunCheckpoint, "due", lambda self, step, last: True)  # every step saved
        stopped = run_boundary_value(bvp_from_dict(scene), out=tmp_path / "run")
    assert [p["status"] for p in stopped.summary["phases"]] == ["completed", "stopped"]
    resumed = run_boundary_value(bvp_from_dict(scene), out=tmp_path / "run", resume=True)
    assert resumed.error is None and resumed.summary["resumed_from_step"] == stop - 1
    assert phase_of_step([2, 4], stop - 1) == (1, stop - 3)
    for name in ("steps.csv", "points.csv"):
        a = run_table(tmp_path / "whole", name).drop(columns=["wall_time"], errors="ignore")
        b = run_table(tmp_path / "run", name).drop(columns=["wall_time"], errors="ignore")
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    np.testing.assert_array_equal(whole.u, resumed.u)
    assert resumed.summary["phases"] == whole.summary["phases"]


def test_a_loading_with_a_dirichlet_start_adds_the_increment_and_without_is_as_before():
    dofs = np.array([0, 3])
    end = np.array([1e-3, -2e-3])
    f = np.zeros(4)
    plain = Loading(dofs, end, f, f)
    assert plain.at(0.25)[0].tolist() == (0.25 * end).tolist()
    start = np.array([5e-4, 1e-4])
    staged = Loading(dofs, end, f, f, dirichlet_start=start)
    np.testing.assert_array_equal(staged.at(0.0)[0], start)
    np.testing.assert_array_equal(staged.at(1.0)[0], start + end)
    with pytest.raises(ValueError, match="dirichlet_start"):
        Loading(dofs, end, f, f, dirichlet_start=np.zeros(3))


def _without_name(scene: dict, k: int) -> dict:
    out = copy.deepcopy(scene)
    del out["phases"][k]["name"]
    return out


def _phase(scene: dict, k: int, **changes) -> dict:
    out = copy.deepcopy(scene)
    out["phases"][k].update(changes)
    return out


BAD = [
    ("phases.colour", lambda s: _phase(s, 0, colour="red")),
    ("steps", lambda s: dict(s, steps=5)),
    ("gravity.factor", lambda s: dict(s, gravity={"unit_weight": 18e3, "factor": [0, 1]})),
    ("phases.gravity.factor", lambda s: _phase(s, 1, gravity={"factor": [1.0, 2.0]})),
    ("phases.gravity.factor", lambda s: _phase(s, 1, gravity={"factor": -1.0})),
    ("phases.gravity.unit_weight", lambda s: _phase(s, 1, gravity={"unit_weight": 1.0})),
    ("phases.conditions.end", lambda s: _phase(s, 1, conditions=[
        {"type": "pressure", "boundary": "top", "value": 1e3, "end": 2e3}])),
    ("phases.conditions.boundary", lambda s: _phase(s, 1, conditions=[
        {"type": "fixed", "boundary": "nowhere"}])),
    ("phases.conditions.colour", lambda s: _phase(s, 1, conditions=[
        {"type": "fixed", "boundary": "top", "colour": "red"}])),
    ("phases.name", lambda s: _phase(s, 1, name="gravity")),
    ("phases.name", lambda s: _without_name(s, 1)),
    ("phases.steps", lambda s: _phase(s, 1, steps=0)),
    ("phases.reset_displacements", lambda s: _phase(s, 1, reset_displacements="yes")),
    ("phases.reset_displacements", lambda s: _phase(s, 0, reset_displacements=True)),
    ("conditions.end", lambda s: dict(s, conditions=[
        *ROLLERS, {"type": "pressure", "boundary": "top", "value": 0.0, "end": 1e3}])),
    ("phases", lambda s: dict(s, phases=[])),
    ("newton.continuation", lambda s: dict(s, newton={"continuation": "arc-length"})),
]


@pytest.mark.parametrize("field, change", BAD, ids=[f"{f}-{k}" for k, (f, _) in
                                                    enumerate(BAD)])
def test_a_bad_phase_key_is_refused_naming_it(field, change):
    with pytest.raises(SpecError) as refused:
        bvp_from_dict(change(_scene()))
    assert refused.value.field == field


def test_a_phase_that_leaves_the_body_free_is_refused_naming_it_before_any_step():
    scene = _scene(conditions=[])
    scene["phases"][0]["conditions"] += ROLLERS
    with pytest.raises(SpecError, match=r"phase 2 \('load'\)") as refused:
        build(bvp_from_dict(scene), allocate=False)
    assert refused.value.field == "phases.conditions"


def test_every_phase_key_acts():
    base = bvp_from_dict(_scene())
    changes = {"name": "other", "steps": 4, "reset_displacements": True,
               "gravity": {"factor": 2.0},
               "conditions": [{"type": "pressure", "boundary": "top", "value": 1e3}]}
    assert set(changes) == SCENE_KEYS["phases"]
    assert set(changes["gravity"]) == SCENE_KEYS["phases.gravity"]
    for key, value in changes.items():
        assert bvp_from_dict(_phase(_scene(), 1, **{key: value})) != base, key


def test_the_example_scene_runs_its_two_phases(tmp_path):
    examples = Path(__file__).parents[1] / "examples" / "scenes"
    text = (examples / "phases-footing.toml").read_text()
    outcome = run_boundary_value(bvp_from_dict(tomllib.loads(text), examples),
                                 out=tmp_path / "run")
    assert outcome.error is None
    assert [p["status"] for p in outcome.summary["phases"]] == ["completed", "completed"]
    steps = outcome.steps
    strip = steps[steps["phase"] == "strip"]
    assert strip["strip_pressure"].iloc[-1] == pytest.approx(150e3)
    assert (steps[steps["phase"] == "gravity"]["strip_pressure"] == 0).all()
    # the strip settles under its load, measured from the phase's start
    assert 0 < strip["strip_displacement"].iloc[0] < strip["strip_displacement"].iloc[-1]
    assert (tmp_path / "run" / "load_displacement.png").is_file()


def test_a_support_dropped_is_released_and_one_added_holds_where_the_phase_finds_it():
    scene = _scene()
    scene["phases"][0]["conditions"] = [{"type": "roller", "boundary": "right",
                                         "component": "x"}]
    scene["phases"][1]["conditions"] = [{"type": "fixed", "boundary": "top"}]
    outcome = run_boundary_value(bvp_from_dict(scene), out=None)
    assert outcome.error is None
    steps = outcome.steps
    first, second = steps[steps["step"] <= 2], steps[steps["step"] >= 2]
    assert (first["right_displacement_x"].abs() < 1e-15).all()  # held by its roller
    top = first["top_displacement_y"].iloc[-1]
    assert top < -1e-6  # it settled under the weight, then is held there
    np.testing.assert_allclose(second["top_displacement_y"], top, rtol=1e-12)
    assert abs(second["right_displacement_x"].iloc[-1]) > 1e-7  # released: it moves
    assert outcome.summary["phases"][1]["start_residual"] > 0.01  # the released reaction


def test_the_command_line_names_the_line_of_a_bad_key_in_a_phase(tmp_path, capsys):
    from granular_material.cli import main

    examples = Path(__file__).parents[1] / "examples" / "scenes"
    lines = (examples / "phases-footing.toml").read_text().splitlines()
    at = next(k for k, line in enumerate(lines) if line.startswith("value = 150e3"))
    lines.insert(at + 1, "end = 200e3")
    scene = tmp_path / "bad.toml"
    scene.write_text("\n".join(lines) + "\n")
    assert main(["run", str(scene), "--check"]) == 2
    err = capsys.readouterr().err
    assert f"line {at + 2}: phases.conditions.end of phase 2 ('strip')" in err


def test_the_reported_gradient_after_a_reset_is_the_deformation_since():
    from granular_material.fem.kinematics import Kinematics
    from granular_material.runs.boundary_value.phases import reported_gradient

    rng = np.random.default_rng(3)
    grad_r = 0.1 * rng.standard_normal((5, 2, 2))  # at the reset
    grad_u = grad_r + 0.05 * rng.standard_normal((5, 2, 2))  # now
    eye = np.eye(2)
    finite = reported_gradient(Kinematics("updated-lagrangian"), grad_u, grad_r)
    np.testing.assert_allclose(eye + finite, (eye + grad_u) @ np.linalg.inv(eye + grad_r),
                               rtol=0, atol=1e-14)
    small = reported_gradient(Kinematics("small-strain"), grad_u, grad_r)
    np.testing.assert_array_equal(small, grad_u - grad_r)
    assert reported_gradient(Kinematics(), grad_u, None) is grad_u
