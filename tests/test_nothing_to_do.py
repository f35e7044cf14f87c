"""A load step where nothing moves is no failure: an increment that prescribes nothing from a
converged state is accepted as "nothing-to-do" on its one evaluation, whatever the
convergence test; a start out of equilibrium is said, with its residual relative to the load
(issue 61, kind 8)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from granular_material.cli import main
from granular_material.fem import NewtonSettings
from granular_material.fem.solver.convergence import (
    GO_ON,
    IDLE_RTOL,
    IterationState,
    Outcome,
    idle,
    nothing_prescribed,
)
from granular_material.runs.boundary_value.runner import (
    OutOfEquilibriumWarning,
    run_boundary_value,
)
from granular_material.runs.boundary_value.spec import bvp_from_dict

#: a footing over the whole top held at [0, 0] on a block that starts at a uniform 20 kPa, its
#: sides free: not in equilibrium at step 0
HELD = """test = "boundary-value"
steps = 3
[mesh]
size = [0.4, 0.2]
elements = [4, 2]
[boundaries]
base = "y = bottom"
footing = "y = top"
[[conditions]]
type = "fixed"
boundary = "base"
[[conditions]]
type = "rigid"
boundary = "footing"
displacement = [0.0, 0.0]
[initial]
state = "uniform"
pressure = 20e3
[material]
name = "{material}"
[newton]
convergence = "{test}"
predictor = "{predictor}"
"""


def _held(material: str = "mohr-coulomb", test: str = "force",
          predictor: str = "extrapolate") -> dict:
    import tomllib

    return tomllib.loads(HELD.format(material=material, test=test, predictor=predictor))


def test_nothing_prescribed_needs_a_converged_start_and_no_change() -> None:
    u, f = np.array([0.0, 1e-3]), np.array([5.0, -2.0])
    assert nothing_prescribed(np.zeros(2), u, f, f.copy(), converged=True)
    assert not nothing_prescribed(np.zeros(2), u, f, f.copy(), converged=False)  # the start
    assert not nothing_prescribed(np.array([0.0, 1e-9]), u, f, f, converged=True)
    assert not nothing_prescribed(np.zeros(2), u, f, f * (1 + 1e-9), converged=True)
    # the round-off of a load factor that scales the loads is no change
    assert nothing_prescribed(np.zeros(2), u, f, f * (1 + IDLE_RTOL / 10), converged=True)
    # all of it zero: a footing held at [0, 0] with no load
    assert nothing_prescribed(np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2), True)
    # the initial state: nothing to do where it is in equilibrium (to round-off, or atol)
    assert nothing_prescribed(np.zeros(2), u, f, f, False, r0=1e-9, force_scale=1e3)
    assert nothing_prescribed(np.zeros(2), u, f, f, False, r0=1e-3, force_scale=1e3,
                              atol=1e-2)
    assert not nothing_prescribed(np.zeros(2), u, f, f, False, r0=1.0, force_scale=1e3)


def test_the_idle_rule_accepts_the_first_evaluation_only() -> None:
    settings = NewtonSettings()
    state = IterationState(1, 1e-12, 3e-12, (3.0,), (), 0.0, idle=True)
    verdict = idle(state, settings)
    assert verdict.outcome is Outcome.CONVERGED and verdict.by == "nothing-to-do"
    assert idle(IterationState(2, 1e-12, 3e-12, (3.0, 3.0), (), 0.0, idle=True),
                settings) is GO_ON
    assert idle(IterationState(1, 1e-12, 3e-12, (3.0,), (), 0.0), settings) is GO_ON
    assert idle(IterationState(1, 1.0, float("nan"), (np.nan,), (), 0.0, idle=True),
                settings) is GO_ON  # a blown-up evaluation is no "nothing to do"


@pytest.mark.parametrize(("material", "test", "predictor"), [
    ("mohr-coulomb", "force", "extrapolate"),
    ("mohr-coulomb", "displacement", "extrapolate"),
    ("mohr-coulomb", "residual-displacement", "tangent"),
    ("linear-elastic", "force", "tangent"),
])
def test_a_footing_held_after_a_start_out_of_equilibrium_runs_to_its_end(
        tmp_path: Path, material: str, test: str, predictor: str) -> None:
    spec = bvp_from_dict(_held(material, test, predictor), tmp_path)
    with pytest.warns(OutOfEquilibriumWarning, match=r"not in equilibrium .* N/m, 0\.\d+ "
                                                    "times"):
        outcome = run_boundary_value(spec, out=tmp_path / "run")
    assert outcome.error is None, outcome.error
    steps = outcome.steps
    # step 1 brings the start to equilibrium; steps 2 and 3 have nothing to do: one
    # evaluation each, and nothing moves
    assert steps["iterations"].iloc[2:].tolist() == [1, 1]
    for column in ("footing_force_y", "base_force_y", "footing_displacement_y"):
        assert steps[column].iloc[3] == steps[column].iloc[1], column
    relative = outcome.summary["initial_residual"]["relative"]
    assert 0.01 < relative < 1
    written = pd.read_csv(tmp_path / "run" / "steps.csv")
    assert len(written) == 4


def test_the_command_line_says_the_start_is_out_of_equilibrium_and_exits_0(tmp_path):
    scene = tmp_path / "held.toml"
    scene.write_text(HELD.format(material="mohr-coulomb", test="force",
                                 predictor="extrapolate"))
    with pytest.warns(OutOfEquilibriumWarning, match="not in equilibrium with the loads at "
                                                    "step 0"):
        assert main(["run", str(scene), "--out", str(tmp_path / "run")]) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["error"] is None and summary["iterations"][1:] == [1, 1]


@pytest.mark.parametrize("test", ["force", "displacement", "residual-displacement"])
def test_a_footing_held_on_a_start_in_equilibrium_has_nothing_to_do(tmp_path: Path,
                                                                     test: str) -> None:
    data = _held(test=test)
    data["initial"] = {"state": "geostatic", "k0": 0.5}
    data["gravity"] = {"unit_weight": 18e3}
    data["boundaries"].update(left="x = left", right="x = right")
    data["conditions"] += [{"type": "roller", "boundary": side, "component": "x"}
                           for side in ("left", "right")]
    with warnings.catch_warnings():
        warnings.simplefilter("error", OutOfEquilibriumWarning)
        outcome = run_boundary_value(bvp_from_dict(data, tmp_path))
    assert outcome.error is None
    # every step, the first included: one evaluation, nothing moves (before: up to 106)
    assert outcome.summary["iterations"] == [1, 1, 1]
    assert np.abs(outcome.u).max() == 0.0


def test_a_start_in_equilibrium_says_nothing(tmp_path: Path) -> None:
    data = _held()
    data["initial"] = {"state": "geostatic", "k0": 0.5}
    data["gravity"] = {"unit_weight": 18e3}
    data["conditions"][1]["displacement"] = [0.0, -1e-4]
    data["boundaries"].update(left="x = left", right="x = right")
    data["conditions"] += [{"type": "roller", "boundary": side, "component": "x"}
                           for side in ("left", "right")]
    with warnings.catch_warnings():
        warnings.simplefilter("error", OutOfEquilibriumWarning)
        outcome = run_boundary_value(bvp_from_dict(data, tmp_path))
    assert outcome.error is None
    assert outcome.summary["initial_residual"]["relative"] < 1e-10


def test_a_step_that_fails_after_a_start_out_of_equilibrium_says_so(tmp_path: Path) -> None:
    # a footing on part of the top: the unloaded surface beside it at 20 kPa, cohesionless
    data = _held()
    data["boundaries"]["footing"] = "y = top and x <= 0.1"
    data["newton"].update(max_iterations=20, max_cutbacks=1)
    with pytest.warns(OutOfEquilibriumWarning):
        outcome = run_boundary_value(bvp_from_dict(data, tmp_path))
    assert outcome.error is not None and "did not converge" in outcome.error
    assert "the initial state was not in equilibrium with the loads" in outcome.error
