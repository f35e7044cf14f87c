"""The arc-length continuation: past a peak and a snap-back, collapse found as a plateau,
and the factor of safety by strength reduction (fem.solver.continuation,
fem.solver.strength_reduction)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from granular_material.fem import (
    Fixed,
    Gravity,
    NewtonSolver,
    Pressure,
    Roller,
    build_problem,
    default_settings,
    rectangle_mesh,
)
from granular_material.fem.materials.linear_elastic import LinearElastic
from granular_material.fem.materials.mohr_coulomb import MohrCoulomb
from granular_material.fem.solver.continuation import (
    PLATEAU_STEPS,
    ContinuationState,
    arc_roots,
    next_length,
)
from granular_material.fem.solver.records import NewtonError
from granular_material.fem.solver.strength_reduction import strength_reduction
from granular_material.runs.boundary_value.runner import run_boundary_value

P = 100e3  # confining pressure [Pa]


def test_arc_roots_are_the_quadratic_roots_without_cancellation() -> None:
    roots = sorted(arc_roots(1.0, -3.0, 2.0))
    assert roots == pytest.approx([1.0, 2.0])
    small = sorted(arc_roots(1.0, 1e8, 1.0))  # one root near -1e-8: no cancellation
    assert small[1] == pytest.approx(-1e-8, rel=1e-12)
    assert arc_roots(1.0, 0.0, 1.0) == ()  # the arc misses the path
    assert arc_roots(0.0, 1.0, 1.0) == ()


def test_next_length_follows_the_iterations_within_a_factor_of_two() -> None:
    assert next_length(1.0, 6, 10.0) == pytest.approx(1.0)
    assert next_length(1.0, 1, 10.0) == pytest.approx(2.0)
    assert next_length(1.0, 100, 10.0) == pytest.approx(0.5)
    assert next_length(8.0, 1, 10.0) == pytest.approx(10.0)


def test_a_plateau_is_a_collapse_and_its_value_the_peak_before_it() -> None:
    path = ContinuationState()
    values = [0.5, 0.8, 0.9, 0.95]
    for k, v in enumerate(values, 1):
        path.commit(k, v, v - (values[k - 2] if k > 1 else 0.0), 1.0)
    assert path.collapse is None
    for k in range(5, 5 + PLATEAU_STEPS):  # the parameter stalls while the path runs on
        path.commit(k, 0.95 + 1e-4 * (k - 4), 1e-4, 1.0)
    assert path.collapse is not None
    assert path.collapse["value"] == pytest.approx(0.9505)  # the peak when found
    assert path.collapse["step"] == 4 + PLATEAU_STEPS
    again = ContinuationState.from_dict(path.as_dict())
    assert again == path


def _element(top_end: float, material, continuation: str, cutbacks: int = 6
             ) -> NewtonSolver:
    """One quad4 element under a lateral pressure P and a top pressure from P to
    ``top_end`` [Pa] (λ from 0 to 1), rollers on the left and the bottom."""
    mesh = rectangle_mesh(1.0, 1.0, 1, 1, "quad4")
    problem = build_problem(mesh, [Roller("left", 0), Roller("bottom", 1),
                                   Pressure("right", P), Pressure("top", P, end=top_end)])
    settings = replace(default_settings("mohr-coulomb"), continuation=continuation,
                       max_cutbacks=cutbacks)
    return NewtonSolver(problem.basis, material, problem.loading, settings)


def _softening() -> MohrCoulomb:
    return MohrCoulomb(young=50e6, poisson=0.3, friction_angle=30.0, dilation_angle=0.0,
                       critical_friction_angle=25.0, softening_strain=0.02,
                       initial_stress=np.broadcast_to(-P * np.eye(2), (4, 2, 2)).copy())


def test_load_control_stops_at_the_peak_and_arc_length_passes_it() -> None:
    # plane strain, c = 0: σ1/σ3 = (1 + sin φ)/(1 − sin φ) = 3 at the peak, so the top
    # pressure peaks at 3P, λ = 2/3 of the way from P to 4P; then the strength softens to
    # φcs = 25° (σ1/σ3 = 2.46) and stays there
    with pytest.raises(NewtonError):
        _element(4 * P, _softening(), "load").run(10)
    solver = _element(4 * P, _softening(), "arc-length")
    solver.run(10)
    path = solver.continuation
    assert path.peak == pytest.approx(2 / 3, rel=0.02)
    assert min(path.values[path.values.index(path.peak):]) < path.peak - 0.05  # came down
    assert solver.stopped_by == "collapse"  # on the critical state's plateau
    kp_cs = (1 + math.sin(math.radians(25))) / (1 - math.sin(math.radians(25)))
    assert solver.load_factor == pytest.approx((kp_cs - 1) / 3, rel=0.02)
    # the cut-backs allowed do not move the path (none were needed)
    more = _element(4 * P, _softening(), "arc-length", cutbacks=12)
    more.run(10)
    assert more.continuation.values == path.values


def test_arc_length_on_a_linear_body_ends_at_the_load_of_load_control() -> None:
    def elastic() -> LinearElastic:
        return LinearElastic(young=50e6, poisson=0.3,
                             initial_stress=np.broadcast_to(-P * np.eye(2), (4, 2, 2)).copy())
    by_load = _element(2 * P, elastic(), "load")
    by_load.run(4)
    by_arc = _element(2 * P, elastic(), "arc-length")
    by_arc.run(4)
    assert by_arc.stopped_by == "completed"
    assert by_arc.load_factor == 1.0
    assert np.allclose(by_arc.u, by_load.u, rtol=1e-5, atol=0)  # Newton's tolerance


def _slope(gravity_end: float, continuation: str, cutbacks: int = 6) -> NewtonSolver:
    """A slope 10 m high at 1:1.5 on a 5 m foundation (crest x ≤ 10 m, toe at x = 25 m),
    16 × 4 quad8 mapped under the ground surface, Mohr–Coulomb c = 10 kPa, φ = 20°, ψ = 0,
    from a stress-free start under gravity switched on to ``gravity_end`` [N/m³]."""
    mesh = rectangle_mesh(40.0, 1.0, 16, 4, "quad8")
    x = mesh.mesh.p[0]
    mesh.mesh.p[1] *= np.where(x <= 10, 15.0, np.where(x >= 25, 5.0, 15.0 - (x - 10) / 1.5))
    problem = build_problem(mesh, [Roller("left", 0), Roller("right", 0), Fixed("bottom"),
                                   Gravity(0.0, end=gravity_end)])
    n = problem.basis.nelems * problem.basis.X.shape[-1]
    soil = MohrCoulomb(young=100e6, poisson=0.3, friction_angle=20.0, dilation_angle=0.0,
                       cohesion=10e3, initial_stress=np.zeros((n, 2, 2)))
    settings = replace(default_settings("mohr-coulomb"), formulation="small-strain",
                       continuation=continuation, max_cutbacks=cutbacks)
    return NewtonSolver(problem.basis, soil, problem.loading, settings)


def _bishop_ground():
    from granular_material.limit_equilibrium import Ground, Layer
    return Ground(surface=((0, 15), (10, 15), (25, 5), (40, 5)),
                  layers=(Layer(0.0, 10e3, 20.0, 20e3),), base=0.0)


def test_strength_reduction_of_a_slope_finds_bishops_factor() -> None:
    from granular_material.limit_equilibrium import critical_circle

    bishop = critical_circle(_bishop_ground()).result.factor  # 1.143
    found = []
    for cutbacks in (6, 12):
        solver = _slope(20e3, "load", cutbacks)
        solver.run(4)
        result = strength_reduction(solver, factor_end=2.0, steps=20)
        assert result.stopped_by == "collapse"
        assert solver.material.strength_factor == pytest.approx(result.factors[-1])
        found.append(result.factor_of_safety)
    assert found[0] == pytest.approx(bishop, rel=0.03)  # 1.15 on this coarse mesh
    assert found[1] == found[0]  # the cut-backs allowed do not move it


def test_the_gravity_increase_factor_of_a_slope_is_bishops() -> None:
    from granular_material.limit_equilibrium import gravity_increase_factor

    bishop = gravity_increase_factor(_bishop_ground(), grid=8)[0]  # 1.461
    solver = _slope(2 * 20e3, "arc-length")
    solver.run(10)
    assert solver.stopped_by == "collapse"
    assert 2 * solver.continuation.collapse["value"] == pytest.approx(bishop, rel=0.03)


def test_a_stopped_arc_length_footing_resumes_to_the_run_that_never_stopped(
        tmp_path, monkeypatch) -> None:
    from test_bvp_resume import MOHR_COULOMB, _spec, _tables

    scene = MOHR_COULOMB + 'continuation = "arc-length"\n'
    whole = run_boundary_value(_spec(scene, 4, "[6, 4]", -0.004), out=tmp_path / "whole")
    assert whole.error is None
    path = whole.summary["continuation"]
    assert path["model"] == "arc-length" and path["stopped_by"] == "completed"
    assert whole.steps["load_factor"].iloc[-1] == 1.0
    original = NewtonSolver.arc_step

    def step_or_stop(self, parameter, start, step, most, end=1.0):
        if step == 3:
            raise KeyboardInterrupt
        return original(self, parameter, start, step, most, end)

    with monkeypatch.context() as m:
        m.setattr(NewtonSolver, "arc_step", step_or_stop)
        stopped = run_boundary_value(_spec(scene, 4, "[6, 4]", -0.004), out=tmp_path / "run")
    assert "interrupted" in stopped.error
    resumed = run_boundary_value(_spec(scene, 4, "[6, 4]", -0.004), out=tmp_path / "run",
                                 resume=True)
    assert resumed.error is None
    for a, b in zip(_tables(tmp_path / "whole"), _tables(tmp_path / "run"), strict=True):
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    np.testing.assert_array_equal(whole.u, resumed.u)
    assert resumed.summary["continuation"] == path


ELEMENT_SCENE = """test = "boundary-value"
steps = 4
[mesh]
size = [1.0, 1.0]
elements = [1, 1]
element = "quad4"
[[conditions]]
type = "roller"
boundary = "left"
component = "x"
[[conditions]]
type = "roller"
boundary = "bottom"
component = "y"
[[conditions]]
type = "pressure"
boundary = "right"
value = 100e3
[[conditions]]
type = "pressure"
boundary = "top"
value = 100e3
end = 200e3
[initial]
state = "uniform"
pressure = 100e3
[material]
name = "{material}"
[material.parameters]
young = 50e6
poisson = 0.3
{strength}
[newton]
{newton}
[strength_reduction]
factor_end = 3.0
steps = 20
"""
MC = "friction_angle = 30.0\ndilation_angle = 0.0"


def _scene(material: str = "mohr-coulomb", strength: str = MC, newton: str = ""):
    import tomllib

    from granular_material.runs.boundary_value.spec import bvp_from_dict
    return bvp_from_dict(tomllib.loads(ELEMENT_SCENE.format(material=material,
                                                            strength=strength,
                                                            newton=newton)))


def test_a_scene_reduces_the_strength_after_its_loading(tmp_path) -> None:
    outcome = run_boundary_value(_scene(), out=tmp_path / "run")
    assert outcome.error is None
    found = outcome.summary["strength_reduction"]
    expected = math.tan(math.radians(30)) / math.tan(math.asin(1 / 3))
    # one homogeneous element yields everywhere at once: no path past it to follow, so
    # the reduction ends on Newton's failure there (and says F is a bound)
    assert found["stopped_by"] in ("collapse", "failed")
    assert found["factor_of_safety"] == pytest.approx(expected, rel=0.01)
    steps = outcome.steps
    assert (steps.loc[steps["step"] <= 4, "strength_factor"] == 1.0).all()
    assert steps["strength_factor"].iloc[-1] > 1.5
    assert (tmp_path / "run" / "strength_reduction.png").exists()


@pytest.mark.parametrize(("material", "strength", "newton", "field"), [
    ("linear-elastic", "", "", "strength_reduction"),
    ("mohr-coulomb", MC, 'continuation = "arc-length"', "newton.continuation"),
])
def test_a_strength_reduction_that_cannot_act_is_refused(material, strength, newton,
                                                         field) -> None:
    from granular_material.runs.spec import SpecError
    with pytest.raises(SpecError) as info:
        _scene(material, strength, newton)
    assert info.value.field == field


def test_a_strength_reduction_stopped_part_way_resumes_to_the_one_never_stopped(
        tmp_path, monkeypatch) -> None:
    from test_bvp_resume import _tables

    from granular_material.runs import checkpoint

    whole = run_boundary_value(_scene(), out=tmp_path / "whole")
    original = NewtonSolver.arc_step

    def step_or_stop(self, parameter, start, step, most, end=1.0):
        if step == 7:  # the third step of the reduction
            raise KeyboardInterrupt
        return original(self, parameter, start, step, most, end)

    with monkeypatch.context() as m:
        m.setattr(NewtonSolver, "arc_step", step_or_stop)
        # a save after every step (by elapsed time a loaded machine may skip them all)
        m.setattr(checkpoint.RunCheckpoint, "due", lambda self, step, last_step: True)
        stopped = run_boundary_value(_scene(), out=tmp_path / "run")
    assert "interrupted" in stopped.error
    resumed = run_boundary_value(_scene(), out=tmp_path / "run", resume=True)
    assert resumed.error is None
    assert resumed.summary["resumed_from_step"] > 4  # inside the reduction
    for a, b in zip(_tables(tmp_path / "whole"), _tables(tmp_path / "run"), strict=True):
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert resumed.summary["strength_reduction"] == whole.summary["strength_reduction"]


@pytest.mark.parametrize(("key", "value"), [("factor_end", 1.0), ("steps", 0),
                                            ("factor", 2.0)])
def test_a_strength_reduction_key_out_of_bounds_or_unknown_is_refused_naming_it(key, value
                                                                                 ) -> None:
    import tomllib

    from granular_material.runs.boundary_value.spec import bvp_from_dict
    from granular_material.runs.spec import SpecError
    data = tomllib.loads(ELEMENT_SCENE.format(material="mohr-coulomb", strength=MC,
                                              newton=""))
    data["strength_reduction"][key] = value
    with pytest.raises(SpecError) as info:
        bvp_from_dict(data)
    assert info.value.field.startswith("strength_reduction")
    assert key in str(info.value)


def test_a_collapse_sought_in_finite_strain_warns_and_in_small_strain_does_not(
        recwarn) -> None:
    from granular_material.runs.boundary_value.runner import FiniteStrainCollapseWarning
    with pytest.warns(FiniteStrainCollapseWarning, match="small-strain"):
        run_boundary_value(_scene(), out=None)  # the commands' default: updated-Lagrangian
    recwarn.clear()
    run_boundary_value(_scene(newton='formulation = "small-strain"\nmax_cutbacks = 2'),
                       out=None)
    assert not [w for w in recwarn if w.category is FiniteStrainCollapseWarning]


def test_a_phased_scene_reduces_the_strength_after_its_last_phase(tmp_path) -> None:
    import tomllib

    from granular_material.runs.boundary_value.spec import bvp_from_dict
    data = tomllib.loads(ELEMENT_SCENE.format(material="mohr-coulomb", strength=MC,
                                              newton=""))
    top = data["conditions"].pop()  # the top's pressure, loaded in the second phase
    del data["steps"]
    data["phases"] = [{"name": "confined", "steps": 2,
                       "conditions": [{"type": "pressure", "boundary": "top",
                                       "value": top["value"]}]},
                      {"name": "loaded", "steps": 2,
                       "conditions": [{"type": "pressure", "boundary": "top",
                                       "value": top["end"]}]}]
    outcome = run_boundary_value(bvp_from_dict(data), out=tmp_path / "run")
    assert outcome.error is None
    phases = outcome.steps["phase"].tolist()
    assert phases[-1] == "strength-reduction" and phases[4] == "loaded"
    assert [p["status"] for p in outcome.summary["phases"]] == ["completed", "completed"]
    expected = math.tan(math.radians(30)) / math.tan(math.asin(1 / 3))
    assert outcome.summary["strength_reduction"]["factor_of_safety"] == pytest.approx(
        expected, rel=0.01)
