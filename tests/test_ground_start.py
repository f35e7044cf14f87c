"""The geostatic start of real ground (fem/boundary_value/ground.py): the overburden column
under a slope, a step and layers, its equilibrium correction, the floor; in a scene, K0 per
region, initial.minimum_pressure, the stress-free start and the fix a start out of
equilibrium names."""

from __future__ import annotations

import warnings

import meshio
import numpy as np
import pytest

from granular_material.errors import ParameterError
from granular_material.fem import NewtonSolver
from granular_material.fem.boundary_value.boundaries import select_boundaries, select_elements
from granular_material.fem.boundary_value.conditions import Fixed, Gravity, Roller, build_problem
from granular_material.fem.boundary_value.ground import (
    ground_stress,
    lift_to_floor,
    overburden,
    poisson_of_k0,
)
from granular_material.fem.boundary_value.initial_stress import geostatic_stress
from granular_material.fem.boundary_value.meshes import MeshData, rectangle_mesh
from granular_material.runs.boundary_value.runner import (
    OutOfEquilibriumWarning,
    _initial_residual,
    build,
    run_boundary_value,
)
from granular_material.runs.boundary_value.spec import bvp_from_dict
from granular_material.runs.spec import SpecError

#: the slope: 90 m wide, a crest at 15 m to x = 40 m, 1:1.5 down to a toe at 5 m from
#: x = 55 m; a foundation layer below y = 3 m (heavier, a higher K0) under the fill
WIDTH, CREST, TOE, HIGH, LOW, BASE = 90.0, 40.0, 55.0, 15.0, 5.0, 3.0
GAMMA_FILL, GAMMA_BASE, K0_FILL, K0_BASE = 18e3, 20e3, 0.5, 0.6
#: Newton's tolerance of a step (fem/solver/defaults.py: 5e-3 of the load)
NEWTON_TOL = 5e-3


def _surface(x):
    return np.interp(x, [0.0, CREST, TOE, WIDTH], [HIGH, HIGH, LOW, LOW])


def _slope(element: str = "quad8", nx: int = 36, rows: tuple[int, int] = (2, 8)) -> MeshData:
    """A rectangle mesh with its nodes moved: ``rows[0]`` rows of elements up to y = BASE, then
    ``rows[1]`` up to the sloping surface; its sides and base named."""
    n1, n2 = rows
    grid = rectangle_mesh(WIDTH, 1.0, nx, n1 + n2, element)
    p = grid.mesh.p.copy()
    row = np.rint(p[1] * (n1 + n2)).astype(int)
    p[1] = np.where(row <= n1, BASE * row / n1,
                    BASE + (_surface(p[0]) - BASE) * (row - n1) / n2)
    data = MeshData(type(grid.mesh)(p, grid.mesh.t), element)
    return select_boundaries(data, {"left": "x = left", "right": "x = right",
                                    "bottom": "y = bottom"})


def _column(x, y):
    """σv [Pa] of the layered column at (x, y)."""
    return (GAMMA_FILL * (_surface(x) - np.maximum(y, BASE))
            + GAMMA_BASE * np.maximum(BASE - y, 0.0))


def _layered_problem(data: MeshData):
    lower = select_elements(data, f"y < {BASE}")
    upper = np.setdiff1d(np.arange(data.n_elements), lower)
    problem = build_problem(data, [Roller("left", 0), Roller("right", 0), Fixed("bottom"),
                                   Gravity(GAMMA_FILL, elements=upper),
                                   Gravity(GAMMA_BASE, elements=lower)])
    gamma = np.full(data.n_elements, GAMMA_FILL)
    gamma[lower] = GAMMA_BASE
    k0 = np.full(data.n_elements, K0_FILL)
    k0[lower] = K0_BASE
    return problem, gamma, np.repeat(k0, problem.basis.X.shape[-1])


def _relative_residual(problem, sigma) -> float:
    from granular_material.fem.forms import internal_force

    _, f_ext = problem.loading.at(0.0)
    free = np.ones(f_ext.size, dtype=bool)
    free[problem.loading.dirichlet_dofs] = False
    residual = (f_ext - internal_force(problem.basis, sigma))[free]
    return float(np.linalg.norm(residual) / np.linalg.norm(f_ext[free]))


def test_a_layered_slope_starts_in_equilibrium_at_its_overburden():
    problem, gamma, k0 = _layered_problem(_slope())
    ground = ground_stress(problem, gamma, k0)
    xy = problem.points
    # the column is each point's overburden, layer by layer
    np.testing.assert_allclose(ground.sigma_v, _column(xy[:, 0], xy[:, 1]), rtol=1e-12)
    # the column state is not in equilibrium under the slope; the corrected one is, to
    # round-off (far below Newton's tolerance)
    assert not ground.level
    assert ground.residual_column > 0.05
    assert ground.residual < 1e-12 * 1e3 * NEWTON_TOL  # measured 9e-15
    assert _relative_residual(problem, ground.stress) == pytest.approx(ground.residual,
                                                                       abs=1e-13)
    # away from the slope's face σv is the column's within 1 %: under the crest and under
    # the toe's level ground, in both layers
    for x, y in [(2.0, 1.0), (2.0, 8.0), (5.0, 12.0), (87.0, 1.0), (88.0, 4.0)]:
        i = int(np.argmin(np.hypot(xy[:, 0] - x, xy[:, 1] - y)))
        assert -ground.stress[i, 1, 1] == pytest.approx(_column(*xy[i]), rel=0.01)
    # near the face it is not: the correction carries the weight towards it (shear)
    assert ground.correction > 0.05


def test_level_ground_keeps_the_k0_field_bit_for_bit():
    data = select_boundaries(rectangle_mesh(0.6, 0.4, 6, 4, "quad8", grading=(3.0, 0.5),
                                            origin=(0, -0.4)),
                             {"left": "x = left", "right": "x = right", "bottom": "y = bottom"})
    problem = build_problem(data, [Roller("left", 0), Roller("right", 0), Fixed("bottom"),
                                   Gravity(16e3)])
    ground = ground_stress(problem, 16e3, 0.5, 20e3)
    assert ground.level and ground.correction == 0.0
    np.testing.assert_array_equal(ground.stress,
                                  geostatic_stress(problem.points, 0.0, 16e3, 20e3, 0.5))
    # two K0s under the level surface are corrected (and then in equilibrium to round-off)
    k0 = np.where(problem.points[:, 1] < -0.2, 0.6, 0.5)
    layered = ground_stress(problem, 16e3, k0, 20e3)
    assert not layered.level and layered.residual < 1e-12


def test_a_stepped_surface_and_the_refusals():
    grid = rectangle_mesh(20.0, 10.0, 10, 5, "quad4")
    centre = grid.mesh.p[:, grid.mesh.t].mean(axis=1)
    sides = {"left": "x = left", "right": "x = right", "bottom": "y = bottom"}
    step = grid.mesh.remove_elements(np.flatnonzero((centre[0] > 10) & (centre[1] > 6)))
    data = select_boundaries(MeshData(step, "quad4"), sides)
    problem = build_problem(data, [Roller("left", 0), Roller("right", 0), Fixed("bottom"),
                                   Gravity(2e4)])
    ground = ground_stress(problem, 2e4, 0.5)
    xy = problem.points
    np.testing.assert_allclose(ground.sigma_v, 2e4 * (np.where(xy[:, 0] < 10, 10.0, 6.0)
                                                      - xy[:, 1]), rtol=1e-12)
    assert ground.residual_column > 0.05 and ground.residual < 1e-12
    # a point above the surface
    with pytest.raises(ParameterError, match=r"outside the body \(above its surface or "
                                             r"beside it\), the first at \(15, 7\) m"):
        overburden(step, np.array([[5.0, 5.0], [15.0, 7.0]]), 2e4)
    # a cavity: the vertical above the points under it leaves the body and enters it again
    cavity = grid.mesh.remove_elements(np.flatnonzero(
        (abs(centre[0] - 10) < 2) & (abs(centre[1] - 5) < 1)))
    data = select_boundaries(MeshData(cavity, "quad4"), sides)
    problem = build_problem(data, [Roller("left", 0), Roller("right", 0), Fixed("bottom"),
                                   Gravity(2e4)])
    with pytest.raises(ParameterError, match="leaves the body and enters it again") as info:
        ground_stress(problem, 2e4, 0.5)
    assert "cannot be found" in info.value.message


def test_the_floor_lifts_by_an_isotropic_pressure():
    sigma = np.array([[[-10e3, 2e3], [2e3, -20e3]], [[-5.0, 0.0], [0.0, -10.0]],
                      [[3.0, 1.0], [1.0, -8.0]]])
    lifted, index = lift_to_floor(sigma, 100.0)
    assert index.tolist() == [1, 2]
    np.testing.assert_array_equal(lifted[0], sigma[0])
    least = -np.linalg.eigvalsh(lifted)[:, 1]
    assert least[1:] == pytest.approx(100.0, rel=1e-8) and (least[1:] >= 100.0).all()
    deviator = lifted - np.trace(lifted, axis1=1, axis2=2)[:, None, None] / 2 * np.eye(2)
    before = sigma - np.trace(sigma, axis1=1, axis2=2)[:, None, None] / 2 * np.eye(2)
    np.testing.assert_allclose(deviator, before, atol=1e-9)
    assert poisson_of_k0(np.array([0.5, 1.0, 2.0])).tolist() == [1 / 3, 0.49, 0.49]


# -- in a scene -----------------------------------------------------------------------------

SCENE = """test = "boundary-value"
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
[newton]
formulation = "small-strain"
[regions]
base = "y <= {base}"
fill = "y >= {base}"
[[materials]]
region = "base"
name = "linear-elastic"
unit_weight = {g_base}
k0 = {k0_base}
[materials.parameters]
young = 50e6
poisson = 0.3
[[materials]]
region = "fill"
name = "linear-elastic"
unit_weight = {g_fill}
[materials.parameters]
young = 20e6
poisson = 0.3
"""


def _scene(tmp_path, initial: dict, region_k0: bool | None = None, **changes) -> object:
    """The slope scene (a mesh file) with ``initial`` as [initial] (a geostatic one with the
    fill's K0), the base's own k0 kept where ``region_k0`` (default: a geostatic start)."""
    import tomllib

    data = _slope("quad4", nx=18, rows=(1, 4))
    points = np.column_stack([data.mesh.p.T, np.zeros(data.mesh.p.shape[1])])
    meshio.write(tmp_path / "slope.msh", meshio.Mesh(points, [("quad", data.mesh.t.T)]),
                 file_format="gmsh22", binary=False)
    scene = tomllib.loads(SCENE.format(base=BASE, g_base=GAMMA_BASE, g_fill=GAMMA_FILL,
                                       k0_base=K0_BASE))
    geostatic = initial.get("state") == "geostatic"
    scene["initial"] = {**({"k0": K0_FILL} if geostatic else {}), **initial}
    if not (geostatic if region_k0 is None else region_k0):
        del scene["materials"][0]["k0"]
    scene.update(changes)
    return bvp_from_dict(scene, tmp_path)


def _residual(b, record: bool = True):
    solver = NewtonSolver(b.problem.basis, b.material, b.problem.loading, b.settings)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        residual = _initial_residual(solver, b.hint)
    said = [str(w.message) for w in caught if issubclass(w.category, OutOfEquilibriumWarning)]
    return residual, said


def test_a_layered_slope_scene_starts_in_equilibrium_and_its_floor_is_counted(tmp_path):
    spec = _scene(tmp_path, {"state": "geostatic"})
    b = build(spec)
    residual, said = _residual(b)
    assert residual["relative"] < 1e-10 and not said
    assert b.initial["column_residual"] > 0.05 and b.initial["lifted_points"] == 0
    assert b.initial["minimum_pressure"] == {"base": None, "fill": None}  # no RVEs: none
    xy = b.problem.points
    k = np.abs(b.initial_stress[:, 0, 0] / b.initial_stress[:, 1, 1])
    far = xy[:, 0] < 10  # under the crest: each layer's own K0, the fill's relieved by
    # the correction (the slope's thrust is shared by the side supports: measured 0.46)
    assert np.median(k[far & (xy[:, 1] < BASE)]) == pytest.approx(K0_BASE, rel=0.02)
    assert np.median(k[far & (xy[:, 1] > BASE)]) == pytest.approx(K0_FILL, rel=0.1)
    # a step taken from it moves nothing: the start carries its own weight
    outcome = run_boundary_value(spec, out=tmp_path / "run")
    assert outcome.error is None and np.abs(outcome.u).max() < 1e-9
    assert outcome.summary["initial"]["lifted_points"] == 0
    # a floor of 20 kPa lifts the points near the surface, and the summary counts them
    spec = _scene(tmp_path, {"state": "geostatic", "minimum_pressure": 20e3})
    b = build(spec)
    least = -np.linalg.eigvalsh(b.initial_stress)[:, 1]
    assert least.min() >= 20e3 and b.initial["lifted_points"] > 0
    assert b.initial["minimum_pressure"] == {"base": 20e3, "fill": 20e3}


def test_a_corrected_state_beyond_mohr_coulomb_names_the_stress_free_start(tmp_path):
    # the elastic state of a slope near its limit exceeds the strength near its face
    clay = {"name": "mohr-coulomb", "parameters": {"young": 30e6, "poisson": 0.3,
                                                   "friction_angle": 20.0, "cohesion": 10e3}}
    with pytest.raises(SpecError, match=r"outside the Mohr-Coulomb surface at \d+ of 360 "
                                        r"points.*start stress-free") as info:
        build(_scene(tmp_path, {"state": "geostatic"}, materials=None, regions=None,
                     material=clay, gravity={"unit_weight": GAMMA_FILL}))
    assert info.value.field == "initial.state"
    # the fix it names: stress-free, gravity ramped on (measured 1-3 iterations a step)
    outcome = run_boundary_value(_scene(
        tmp_path, {"state": "uniform", "pressure": 0.0}, materials=None, regions=None,
        material=clay, gravity={"unit_weight": GAMMA_FILL, "factor": [0.0, 1.0]}, steps=4))
    assert outcome.error is None and max(outcome.summary["iterations"]) <= 10


def test_a_start_out_of_equilibrium_names_the_fix(tmp_path):
    # gravity in full on a uniform start: ramp it, or start geostatic
    _, said = _residual(build(_scene(tmp_path, {"state": "uniform", "pressure": 50e3})))
    assert len(said) == 1 and "ramp it on with [gravity] factor = [0.0, 1.0]" in said[0]
    assert 'start geostatic (initial.state = "geostatic"' in said[0]
    # a level surface given on a slope: leave it out
    spec = _scene(tmp_path, {"state": "geostatic", "surface": HIGH},
                  materials=None, material={"name": "linear-elastic"},
                  gravity={"unit_weight": GAMMA_FILL}, regions=None)
    _, said = _residual(build(spec))
    assert len(said) == 1 and "leave initial.surface out" in said[0]
    assert "from 5 to 15 m" in said[0]
    # level ground with a surcharge its surface does not carry
    spec = _scene(tmp_path, {"state": "geostatic", "surcharge": 30e3},
                  mesh={"size": [10.0, 5.0], "elements": [2, 2]}, materials=None,
                  material={"name": "linear-elastic"}, gravity={"unit_weight": GAMMA_FILL},
                  regions=None)
    _, said = _residual(build(spec))
    assert len(said) == 1 and "make initial.surcharge the pressure on the ground surface" \
        in said[0]


def test_a_stress_free_start_for_a_continuum_and_not_for_rves(tmp_path):
    spec = _scene(tmp_path, {"state": "uniform", "pressure": 0.0},
                  gravity={"factor": [0.0, 1.0], "unit_weight": GAMMA_FILL})
    b = build(spec)
    assert not b.initial_stress.any()
    residual, said = _residual(b)
    assert residual["norm"] == 0.0 and not said  # no load at step 0, no stress
    outcome = run_boundary_value(spec)
    assert outcome.error is None
    base = outcome.points[(outcome.points.step == 1) & (outcome.points.x < 10)]
    assert base.syy.min() < -0.5 * GAMMA_BASE * BASE  # gravity on, the ground carries it
    # a cohesive Mohr–Coulomb soil starts stress-free too
    clay = {"name": "mohr-coulomb", "parameters": {"young": 30e6, "poisson": 0.3,
                                                   "friction_angle": 20.0, "cohesion": 10e3}}
    b = build(_scene(tmp_path, {"state": "uniform", "pressure": 0.0}, materials=None,
                     regions=None, material=clay,
                     gravity={"factor": [0.0, 1.0], "unit_weight": GAMMA_FILL}))
    assert b.material.n_points == b.problem.points.shape[0] and not b.initial_stress.any()
    # an RVE needs confinement: refused, naming why, alone or in a region
    for changes in ({"materials": None, "regions": None,
                     "material": {"name": "dem", "parameters": {"particles": 16}}},
                    {"materials": [{"region": "base", "name": "dem"},
                                   {"region": "fill", "name": "linear-elastic"}]}):
        with pytest.raises(SpecError, match="an RVE is a packing of discs, which carries "
                                            "stress only while it is confined") as info:
            _scene(tmp_path, {"state": "uniform", "pressure": 0.0}, **changes)
        assert info.value.field == "initial.pressure"


def test_k0_per_region_and_the_floor_are_checked(tmp_path):
    with pytest.raises(SpecError, match="a K0 per region is given in each region's "
                                        r"\[\[materials\]\] entry") as info:
        _scene(tmp_path, {"state": "geostatic", "k0": {"base": 0.6}})
    assert info.value.field == "initial.k0"
    with pytest.raises(SpecError, match="does nothing for a uniform initial state") as info:
        _scene(tmp_path, {"state": "uniform", "pressure": 10e3}, region_k0=True)
    assert info.value.field == "materials.k0"
    with pytest.raises(SpecError, match="the regions differ") as info:
        build(_scene(tmp_path, {"state": "geostatic", "surface": HIGH}), allocate=False)
    assert info.value.field == "initial.surface"
    dem = {"materials": None, "regions": None, "gravity": {"unit_weight": GAMMA_FILL},
           "material": {"name": "dem", "parameters": {"particles": 16}}}
    with pytest.raises(SpecError, match="below the lowest stress the RVEs are prepared at, "
                                        "15 Pa") as info:
        build(_scene(tmp_path, {"state": "geostatic", "minimum_pressure": 5.0}, **dem),
              allocate=False)
    assert info.value.field == "initial.minimum_pressure"
    b = build(_scene(tmp_path, {"state": "geostatic"}, **dem), allocate=False)
    assert b.initial["minimum_pressure"] == 15.0


DEM_SLOPE = """test = "boundary-value"
steps = 1
[mesh]
file = "dem-slope.msh"
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
unit_weight = "rve"
[initial]
state = "geostatic"
k0 = 0.7
minimum_pressure = 1e3
[material]
name = "dem"
[material.parameters]
particles = 16
seed = 1
[output]
device = "cpu"
"""


def _dem_slope(tmp_path) -> object:
    """A 3 × 2 quad4 slope 3 m wide, 1 m high at its crest (x <= 1 m), 0.8 m at its toe
    (x >= 2 m), 24 Gauss points of 16-disc RVEs."""
    import tomllib

    grid = rectangle_mesh(3.0, 1.0, 3, 2, "quad4")
    p = grid.mesh.p.copy()
    p[1] *= np.interp(p[0], [0.0, 1.0, 2.0, 3.0], [1.0, 1.0, 0.8, 0.8])
    points = np.column_stack([p.T, np.zeros(p.shape[1])])
    meshio.write(tmp_path / "dem-slope.msh", meshio.Mesh(points, [("quad", grid.mesh.t.T)]),
                 file_format="gmsh22", binary=False)
    return bvp_from_dict(tomllib.loads(DEM_SLOPE), tmp_path)


def test_a_dem_slope_starts_each_rve_at_its_own_stress_above_the_floor(tmp_path):
    """Measured: 2 of 24 points lifted to 1 kPa (under the crest's surface, where the
    corrected state mobilises 38° at 0.44 kPa: an RVE is not brought there), every RVE
    prepared at its point's stress, the start 1.5 % of the load from equilibrium (the lift
    and the servo's tolerance), and a step under its own weight in 4 iterations, moving
    8 µm; ~3 s."""
    spec = _dem_slope(tmp_path)
    b = build(spec)
    assert b.initial["lifted_points"] >= 1 and b.initial["minimum_pressure"] == 1e3
    sigma = b.initial_stress
    assert (-np.linalg.eigvalsh(sigma)[:, 1] >= 1e3).all()
    # each RVE at its own point's stress: its committed stress within the servo's tolerance
    solver = NewtonSolver(b.problem.basis, b.material, b.problem.loading, b.settings)
    stress = solver.response.stress
    sigma_v = -sigma[:, 1, 1]
    assert np.abs(stress - sigma).max(axis=(1, 2)).max() <= 0.03 * sigma_v.max()
    assert np.ptp(sigma_v) > 10e3  # the points start at their own stresses, not one
    # it carries its own weight: a step moves it by microns
    with pytest.warns(OutOfEquilibriumWarning, match=r"\d+ points were lifted to "
                                                    "initial.minimum_pressure"):
        outcome = run_boundary_value(spec)
    assert outcome.error is None and np.abs(outcome.u).max() < 1e-4
    assert outcome.summary["initial_residual"]["relative"] < 0.05


def test_rves_that_miss_their_geostatic_stress_name_the_floor(tmp_path, monkeypatch):
    import granular_material.runs.boundary_value.runner as runner

    def missed(*args, **kwargs):
        raise RuntimeError("1 of 24 points' RVEs did not reach their initial stress")

    monkeypatch.setattr(runner, "material_for_problem", missed)
    with pytest.raises(RuntimeError, match=r"initial\.minimum_pressure \[Pa\] lifts every "
                                           "point below it"):
        build(_dem_slope(tmp_path))
