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
    assert path.collapse["value"] == pytest.approx(0.9501)
    assert path.collapse["step"] == 5
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


def test_strength_reduction_finds_the_mobilised_friction() -> None:
    # σ1/σ3 = 2 under φ = 30°, c = 0: sin φ_mob = 1/3, so F = tan 30° / tan φ_mob = 1.633
    material = MohrCoulomb(young=50e6, poisson=0.3, friction_angle=30.0,
                           dilation_angle=0.0,
                           initial_stress=np.broadcast_to(-P * np.eye(2), (4, 2, 2)).copy())
    solver = _element(2 * P, material, "load")
    solver.run(4)
    result = strength_reduction(solver, factor_end=3.0, steps=20)
    expected = math.tan(math.radians(30)) / math.tan(math.asin(1 / 3))
    assert result.stopped_by == "collapse"
    assert result.factor_of_safety == pytest.approx(expected, rel=0.01)
    assert material.strength_factor == pytest.approx(result.factors[-1])


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
