"""The continuum start (fem/boundary_value/continuum_start.py, runs/boundary_value/continuum.py):
the loads at step 0 carried by each material's linear-elastic twin, floored, capped and
settled; in a scene, RVEs prepared at their own points' stresses and a settling step."""

from __future__ import annotations

import dataclasses
import warnings

import meshio
import numpy as np
import pytest
import tomllib

from granular_material.fem import NewtonSolver
from granular_material.fem.boundary_value.continuum_start import (
    cap_friction,
    mobilised_friction,
    settle,
)
from granular_material.fem.boundary_value.meshes import rectangle_mesh
from granular_material.fem.forms import internal_force
from granular_material.runs.boundary_value.continuum import ContinuumStartWarning, settles
from granular_material.runs.boundary_value.runner import (
    _initial_residual,
    build,
    run_boundary_value,
)
from granular_material.runs.boundary_value.spec import bvp_from_dict
from granular_material.runs.spec import SpecError

SLOPE = """test = "boundary-value"
steps = 1
[mesh]
file = "slope.msh"
[boundaries]
left = "x = left"
right = "x = right"
bottom = "y = bottom"
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
[gravity]
unit_weight = {gamma}
[initial]
state = "continuum"
minimum_pressure = 1e3
{initial}
[material]
name = "{name}"
[material.parameters]
{parameters}
[output]
device = "cpu"
"""
SAND = "young = 20e6\npoisson = 0.3\nfriction_angle = 30.0\ncohesion = 0.0"
RVES = "particles = 16\nseed = 1\ntangent = \"kruyt-rothenburg\""


def _slope(tmp_path, name: str = "mohr-coulomb", parameters: str = SAND,
           gamma: str = "20e3", initial: str = "", nx: int = 6, ny: int = 4,
           toe: float = 0.8) -> object:
    """A quad4 slope 3 m wide, 1 m high at its crest (x <= 1 m), ``toe`` [m] at its toe
    (x >= 2 m): its scene."""
    grid = rectangle_mesh(3.0, 1.0, nx, ny, "quad4")
    p = grid.mesh.p.copy()
    p[1] *= np.interp(p[0], [0.0, 1.0, 2.0, 3.0], [1.0, 1.0, toe, toe])
    points = np.column_stack([p.T, np.zeros(p.shape[1])])
    meshio.write(tmp_path / "slope.msh", meshio.Mesh(points, [("quad", grid.mesh.t.T)]),
                 file_format="gmsh22", binary=False)
    text = SLOPE.format(name=name, parameters=parameters, gamma=gamma, initial=initial)
    return bvp_from_dict(tomllib.loads(text), tmp_path)


def _residual(b) -> float:
    """‖f_ext − f_int‖/‖f_ext‖ of the built start over the free dofs."""
    _, force = b.problem.loading.at(0.0)
    free = np.ones(force.size, dtype=bool)
    free[b.problem.loading.dirichlet_dofs] = False
    r = force - internal_force(b.problem.basis, b.initial_stress)
    return float(np.linalg.norm(r[free]) / np.linalg.norm(force[free]))


def test_the_cap_keeps_the_mean_stress_and_the_principal_directions():
    rng = np.random.default_rng(3)
    a = rng.uniform(-50e3, -5e3, 40)
    b = rng.uniform(-50e3, -5e3, 40)
    c = rng.uniform(-20e3, 20e3, 40)
    sigma = np.stack([np.stack([a, c], -1), np.stack([c, b], -1)], -2)
    capped, which = cap_friction(sigma, 25.0)
    phi = mobilised_friction(sigma)
    assert set(which) == set(np.flatnonzero(phi > 25.0)) and which.size
    assert np.allclose(mobilised_friction(capped)[which], 25.0)
    assert np.array_equal(np.delete(capped, which, 0), np.delete(sigma, which, 0))
    assert np.allclose(np.trace(capped, axis1=1, axis2=2), np.trace(sigma, axis1=1, axis2=2))
    # the same principal directions: the deviators are parallel
    dev = sigma[which] - 0.5 * np.trace(sigma[which], axis1=1, axis2=2)[:, None, None] * np.eye(2)
    dcap = capped[which] - 0.5 * np.trace(capped[which], axis1=1, axis2=2)[:, None, None] \
        * np.eye(2)
    cross = dev[:, 0, 0] * dcap[:, 0, 1] - dev[:, 0, 1] * dcap[:, 0, 0]
    assert np.allclose(cross, 0.0, atol=1e-6 * np.abs(dev).max() ** 2)


def test_a_continuum_start_is_in_equilibrium_within_its_floor_and_cap(tmp_path):
    """Measured: the elastic state 0 of the load from equilibrium, 4 of 96 points below the
    1 kPa floor and 21 above the cap of 21° (0.7 × 30°): limited, 0.04 of the load off;
    settled to below 1e-6 of it, every point within both limits."""
    spec = _slope(tmp_path)
    with pytest.warns(ContinuumStartWarning, match=r"points below the floor .* settled back"):
        b = build(spec, allocate=False)
    info = b.initial
    assert info["twin"] == {"young": 20e6, "poisson": 0.3, "friction_angle": 30.0}
    assert info["elastic_below_floor"] > 0 and info["elastic_beyond_cap"] > 0
    assert info["limited_residual"] > 1e-2 and info["settled_residual"] < 1e-6
    assert _residual(b) == pytest.approx(info["settled_residual"], rel=1e-6, abs=1e-12)
    sigma = b.initial_stress
    assert (-np.linalg.eigvalsh(sigma)[:, 1] >= 1e3 * (1 - 1e-6)).all()
    assert (mobilised_friction(sigma) <= 0.7 * 30.0 + 1e-6).all()
    # the elastic state alone: in equilibrium to round-off, the same E-independent stress
    _, force = b.problem.loading.at(0.0)
    elastic = settle(b.problem.basis, force, b.problem.loading.dirichlet_dofs, 20e6, 0.3)
    stiffer = settle(b.problem.basis, force, b.problem.loading.dirichlet_dofs, 80e6, 0.3)
    assert elastic.residual_limited < 1e-12 and elastic.iterations == 0
    assert np.allclose(elastic.stress, stiffer.stress, rtol=1e-9, atol=1e-6)
    # a linear-elastic material has no strength: its points are floored, not capped
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ContinuumStartWarning)
        b = build(_slope(tmp_path, "linear-elastic", "young = 20e6\npoisson = 0.3"),
                  allocate=False)
    assert b.initial["twin"]["friction_angle"] is None and b.initial["at_cap"] == 0
    # a slope steeper than the cap (31° against 21°) cannot settle: what is left is said
    with pytest.warns(ContinuumStartWarning):
        b = build(_slope(tmp_path, toe=0.4), allocate=False)
    assert b.initial["settled_residual"] > 1e-3 and b.initial["at_cap"] > 0


def test_a_continuum_start_refuses_keys_it_does_not_take(tmp_path):
    with pytest.raises(SpecError) as refused:
        _slope(tmp_path, initial="strength_fraction = 0.0")
    assert refused.value.field == "initial.strength_fraction"
    with pytest.raises(SpecError) as refused:
        _slope(tmp_path, initial="k0 = 0.5")
    assert refused.value.field == "initial.k0"
    with pytest.raises(SpecError) as refused:
        _slope(tmp_path, initial="surcharge = 1e3")
    assert refused.value.field == "initial.surcharge"
    # a cohesive Mohr–Coulomb soil is not capped: a start outside its strength is refused
    clay = "young = 20e6\npoisson = 0.3\nfriction_angle = 10.0\ncohesion = 1e3"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ContinuumStartWarning)
        with pytest.raises(SpecError, match="Its friction cap acts on cohesionless materials "
                                            "only") as refused:
            build(_slope(tmp_path, parameters=clay, toe=0.2))
    assert refused.value.field == "initial.state"


def test_a_dem_slope_starts_its_rves_at_the_continuum_stress_and_settles(tmp_path):
    """Measured (16-disc RVEs, 24 points): the twin calibrated in ~1 s; every RVE within the
    servo's 1 % of its target (2 % with the sharing of packings); the start's own residual
    below 1e-6 of the load, the RVEs' ~1 % of it; step 1 settles it at the start's load
    factor; ~5 s."""
    spec = _slope(tmp_path, "dem", RVES, gamma='"rve"', nx=3, ny=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ContinuumStartWarning)
        b = build(spec)
    twin = b.initial["twin"]
    assert 10.0 < twin["friction_angle"] < 60.0 and 0.0 < twin["poisson"] < 0.5
    assert b.initial["settled_residual"] < 1e-6
    sigma = b.initial_stress
    solver = NewtonSolver(b.problem.basis, b.material, b.problem.loading, b.settings)
    scale = np.maximum(np.abs(sigma[:, 0, 0]), np.abs(sigma[:, 1, 1]))
    error = np.abs(solver.response.stress - sigma).max(axis=(1, 2)) / scale
    # the servo's tolerance, 1 % of each target's scale, and the sharing of one RVE by
    # targets within 2 % (each missed by at most 1 %)
    assert error.max() <= 0.02 + 1e-9
    # the start's RVEs are ~1 % of the load from equilibrium: step 1 settles them
    residual = _initial_residual(solver)
    assert residual["norm"] > residual["newton_atol"] and settles(spec, residual, False)
    record = solver.equilibrate(1)
    assert record.iterations <= 10 and solver.load_factor == 0.0
    assert not settles(spec, residual, True)  # a resumed run has taken it already


@pytest.mark.parametrize("saved", [0, 2])
def test_a_continuum_run_settles_first_and_resumes_to_the_run_that_never_stopped(
        tmp_path, monkeypatch, saved):
    """Step 1 keeps the load factor (the settling), the load steps follow; a run stopped in
    its load steps resumes to the same tables, from its initial state (settling again) or
    from step 2 (the settling not taken twice)."""
    import pandas as pd

    from granular_material.runs.checkpoint import RunCheckpoint

    def spec():
        return dataclasses.replace(_slope(tmp_path), steps=3, gravity_factor=(1.0, 1.5))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole = run_boundary_value(spec(), out=tmp_path / "whole")
        assert whole.error is None
        assert list(whole.steps["load_factor"]) == pytest.approx([0.0, 0.0, 1 / 3, 2 / 3, 1.0])
        original = NewtonSolver.step

        def step_or_stop(self, target, k):
            if k == 3:
                raise KeyboardInterrupt
            return original(self, target, k)

        with monkeypatch.context() as m:
            m.setattr(NewtonSolver, "step", step_or_stop)
            m.setattr(RunCheckpoint, "due", lambda self, step, last: step == saved)
            stopped = run_boundary_value(spec(), out=tmp_path / "run")
        assert stopped.error is not None and len(stopped.steps) == 3
        resumed = run_boundary_value(spec(), out=tmp_path / "run", resume=True)
    assert resumed.error is None and resumed.summary["resumed_from_step"] == saved
    np.testing.assert_array_equal(whole.u, resumed.u)
    a, b = (pd.read_csv(tmp_path / run / "steps.csv") for run in ("whole", "run"))
    pd.testing.assert_frame_equal(a.drop(columns=["wall_time"]), b.drop(columns=["wall_time"]),
                                  check_exact=True)
