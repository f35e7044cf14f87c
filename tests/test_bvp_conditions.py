"""Named boundaries by predicate and the conditions of boundary-value problems
(fem/boundary_value/: boundaries.py, conditions.py, reactions.py)."""

from __future__ import annotations

import numpy as np
import pytest

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.boundaries import (
    parse_predicate,
    select_boundaries,
    select_facets,
)
from granular_material.fem.boundary_value.conditions import (
    Displacement,
    Fixed,
    Gravity,
    Pressure,
    RigidBody,
    Roller,
    build_problem,
)
from granular_material.fem.boundary_value.meshes import rectangle_mesh
from granular_material.fem.materials.linear_elastic import LinearElastic
from granular_material.fem.solver.newton import NewtonSettings, NewtonSolver

E, NU = 40e6, 0.3
SMALL = NewtonSettings(formulation="small-strain")


def _ends(data, facets):
    return data.mesh.p[:, data.mesh.facets[:, facets]].reshape(2, -1)


def test_predicates_select_boundary_facets():
    data = rectangle_mesh(0.4, 0.2, 8, 4, "quad8")
    np.testing.assert_array_equal(select_facets(data, "x = 0"), data.boundaries["left"])
    np.testing.assert_array_equal(select_facets(data, "x == right"), data.boundaries["right"])
    np.testing.assert_array_equal(select_facets(data, "y=top"), data.boundaries["top"])
    foot = select_facets(data, "y = top and x <= 0.1", "footing")
    assert foot.size == 2 and _ends(data, foot)[0].max() == pytest.approx(0.1)
    wall = select_facets(data, "x >= 0.4 and y >= 0.05")
    assert wall.size == 3 and _ends(data, wall)[1].min() == pytest.approx(0.05)
    both = select_facets(data, "x = left or x = right")
    assert both.size == 8
    # strict: facets touching x = 0.1 are left out of x < 0.1
    assert select_facets(data, "y = top and x < 0.1").size == 1
    # interior facets are never selected
    assert select_facets(data, "x = 0.2 or y = 0").size == data.boundaries["bottom"].size
    named = select_boundaries(data, {"footing": "y = top and x <= 0.1"})
    assert set(named.boundaries) == {"left", "right", "bottom", "top", "footing"}


@pytest.mark.parametrize("expr, match", [
    ("z = 0", "not a coordinate"), ("x = top", "not a bound of x"), ("x ~ 0", "cannot read"),
    ("x = 0 and", "expected"), ("x = 0 xor y = 0", "expected 'and' or 'or'"),
    ("x = foo", "neither a number"), ("", "empty"),
])
def test_predicate_grammar_errors(expr, match):
    with pytest.raises(ParameterError, match=match) as info:
        parse_predicate(expr, "wall")
    assert info.value.field == "wall"


def test_a_boundary_that_selects_nothing_names_itself_and_its_expression():
    data = rectangle_mesh(1.0, 1.0, 2, 2)
    with pytest.raises(ParameterError, match="footing selects no boundary facet: 'y = 2'"):
        select_facets(data, "y = 2", "footing")


@pytest.mark.parametrize("element", ["quad8", "quad9", "tri6", "quad4"])
def test_column_under_its_own_weight(element):
    # laterally confined column, rollers on the sides, fixed base: σv = −γ·depth,
    # σh = ν/(1−ν)·σv, top settlement γH²/(2M), M = E(1−ν)/((1+ν)(1−2ν)); exact for the
    # quadratic elements (u_y is quadratic in y); quad4 has exact nodal values (1D linear
    # elements) and a stress exact at the element centres only
    width, height, gamma = 0.3, 2.0, 20e3
    data = rectangle_mesh(width, height, 2, 5, element)
    problem = build_problem(data, [Roller("left", 0), Roller("right", 0), Fixed("bottom"),
                                   Gravity(gamma)])
    solver = NewtonSolver(problem.basis, LinearElastic(E, NU), problem.loading, SMALL)
    solver.run(1)
    m = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
    ux, uy = problem.boundary_displacement("top", solver.u)
    assert ux == pytest.approx(0.0, abs=1e-15)
    assert uy == pytest.approx(-gamma * height ** 2 / (2 * m), rel=1e-10)
    sigma = solver.response.stress
    depth = height - problem.points[:, 1]
    if element == "quad4":
        centre_depth = depth.reshape(-1, 4).mean(axis=1)
        np.testing.assert_allclose(sigma[:, 1, 1].reshape(-1, 4).mean(axis=1),
                                   -gamma * centre_depth, rtol=1e-9)
    else:
        np.testing.assert_allclose(sigma[:, 1, 1], -gamma * depth, rtol=1e-9, atol=1e-6)
        np.testing.assert_allclose(sigma[:, 0, 0], NU / (1 - NU) * sigma[:, 1, 1], rtol=1e-9,
                                   atol=1e-6)
        np.testing.assert_allclose(sigma[:, 0, 1], 0.0, atol=1e-6)
    # the base carries the weight: reaction γ·W·H upwards
    fx, fy = problem.boundary_force("bottom", solver.reaction)
    assert fy == pytest.approx(gamma * width * height, rel=1e-10)
    assert fx == pytest.approx(0.0, abs=1e-9 * fy)


@pytest.mark.parametrize("formulation", ["small-strain", "updated-lagrangian"])
def test_reaction_of_a_column_under_a_pressure(formulation):
    width, height, p = 0.2, 0.5, 100e3
    data = rectangle_mesh(width, height, 2, 4, "quad8")
    problem = build_problem(data, [Fixed("bottom"), Roller("left", 0), Roller("right", 0),
                                   Pressure("top", p)])
    assert problem.loading.follower is not None
    assert problem.loaded_boundaries == ["bottom", "left", "right", "top"]
    solver = NewtonSolver(problem.basis, LinearElastic(E, NU), problem.loading,
                          NewtonSettings(formulation=formulation))
    solver.run(2)
    fx, fy = problem.boundary_force("bottom", solver.reaction)
    # the base carries the load p·W (the current width: rollers keep it)
    assert fy == pytest.approx(p * width, rel=1e-9)
    assert fx == pytest.approx(0.0, abs=1e-6 * p * width)
    # the rollers hold the lateral stress ν/(1−ν)·p over the height (small strain)
    left = problem.boundary_force("left", solver.reaction)[0]
    right = problem.boundary_force("right", solver.reaction)[0]
    assert left == pytest.approx(-right, rel=1e-9)
    if formulation == "small-strain":
        assert left == pytest.approx(NU / (1 - NU) * p * height, rel=1e-9)
        m = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
        assert problem.boundary_displacement("top", solver.u)[1] == pytest.approx(
            -p * height / m, rel=1e-9)


def test_follower_pressure_acts_on_the_current_length():
    width, p = 0.2, 50e3
    data = rectangle_mesh(width, 0.1, 3, 2, "tri6")
    problem = build_problem(data, [Fixed("bottom"), Pressure("top", p)])
    f0 = problem.loading.at(0.0)[1]
    np.testing.assert_allclose(problem.loading.follower(np.zeros(problem.basis.N)), f0,
                               atol=1e-9)
    u = np.zeros(problem.basis.N)
    u[0::2] = 0.25 * problem.basis.doflocs[0, 0::2]  # the body 25 % wider
    fx, fy = problem.boundary_force("top", problem.loading.follower(u))
    assert fy == pytest.approx(-p * width * 1.25, rel=1e-12)
    assert fx == pytest.approx(0.0, abs=1e-12 * p * width)
    assert problem.boundary_force("top", f0)[1] == pytest.approx(-p * width, rel=1e-12)


@pytest.mark.parametrize("formulation", ["small-strain", "updated-lagrangian"])
def test_a_pressure_with_an_end_rises_linearly_with_the_load_factor(formulation):
    # a laterally confined column under a top pressure raised from p0 to p1 in 4 steps: the
    # base carries p(λ)·W at every step (the rollers keep the width); in small strain the
    # top settles by p(λ)·H/M (Loading.follower_end under finite strain)
    width, height, p0, p1 = 0.2, 0.5, 20e3, 100e3
    data = rectangle_mesh(width, height, 2, 4, "quad8")
    problem = build_problem(data, [Fixed("bottom"), Roller("left", 0), Roller("right", 0),
                                   Pressure("top", p0, end=p1)])
    loading = problem.loading
    assert loading.follower_end is not None
    zero = np.zeros(problem.basis.N)
    for lam in (0.0, 0.25, 1.0):
        for u in (None, zero):
            load = problem.boundary_force("top", loading.at(lam, u)[1])[1]
            assert load == pytest.approx(-(p0 + lam * (p1 - p0)) * width, rel=1e-12)
    seen: list[tuple[float, float, float]] = []

    def record(solver, _record):
        seen.append((solver.load_factor,
                     problem.boundary_force("bottom", solver.reaction)[1],
                     problem.boundary_displacement("top", solver.u)[1]))

    solver = NewtonSolver(problem.basis, LinearElastic(E, NU), loading,
                          NewtonSettings(formulation=formulation))
    solver.run(4, on_step=record)
    m = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
    assert [lam for lam, _, _ in seen] == pytest.approx([0.25, 0.5, 0.75, 1.0])
    for lam, base, settlement in seen:
        p = p0 + lam * (p1 - p0)
        assert base == pytest.approx(p * width, rel=1e-9)
        assert settlement == pytest.approx(-p * height / m,
                                           rel=1e-9 if formulation == "small-strain" else 1e-2)
    # an end equal to the value is a constant pressure
    assert build_problem(data, [Fixed("bottom"), Pressure("top", p0, end=p0)]
                         ).loading.follower_end is None


@pytest.mark.parametrize("formulation", ["small-strain", "updated-lagrangian"])
def test_gravity_with_an_end_rises_linearly_under_a_constant_pressure(formulation):
    # gravity raised from γ to 2γ under a constant top pressure q (a follower under finite
    # strain): the base carries (q + γ(λ)·H)·W at every step; in small strain the top
    # settles by q·H/M + γ(λ)·H²/(2M)
    width, height, q, gamma = 0.3, 1.0, 10e3, 18e3
    data = rectangle_mesh(width, height, 1, 4, "quad8")
    problem = build_problem(data, [Roller("left", 0), Roller("right", 0), Fixed("bottom"),
                                   Pressure("top", q), Gravity(gamma, end=2 * gamma)])
    assert problem.loading.follower_end is not None
    seen: list[tuple[float, float, float]] = []

    def record(solver, _record):
        seen.append((solver.load_factor,
                     problem.boundary_force("bottom", solver.reaction)[1],
                     problem.boundary_displacement("top", solver.u)[1]))

    solver = NewtonSolver(problem.basis, LinearElastic(E, NU), problem.loading,
                          NewtonSettings(formulation=formulation))
    solver.run(2, on_step=record)
    m = E * (1 - NU) / ((1 + NU) * (1 - 2 * NU))
    for lam, base, settlement in seen:
        weight = gamma * (1 + lam)
        assert base == pytest.approx((q + weight * height) * width, rel=1e-9)
        assert settlement == pytest.approx(-(q * height + weight * height ** 2 / 2) / m,
                                           rel=1e-9 if formulation == "small-strain" else 1e-2)
    with pytest.raises(ParameterError, match="end must be >= 0"):
        Gravity(gamma, end=-1.0)


def test_a_pressure_end_must_be_finite():
    with pytest.raises(ParameterError, match="end must be a finite number"):
        Pressure("top", 1e3, end=float("nan"))


@pytest.mark.parametrize("rough", [True, False])
def test_rigid_body_rough_ties_x_smooth_does_not(rough):
    d = -1e-3
    data = rectangle_mesh(0.2, 0.1, 4, 2, "quad8")
    problem = build_problem(data, [Fixed("bottom"), RigidBody("top", (0.0, d), rough=rough)])
    top = problem.boundaries["top"]
    held = set(problem.loading.dirichlet_dofs.tolist())
    assert set(top.y.tolist()) <= held
    assert set(top.x.tolist()) <= held if rough else not set(top.x.tolist()) & held
    solver = NewtonSolver(problem.basis, LinearElastic(E, NU), problem.loading, SMALL)
    solver.run(1)
    np.testing.assert_allclose(solver.u[top.y], d, rtol=1e-12)
    spread = solver.u[top.x]
    if rough:
        np.testing.assert_array_equal(spread, 0.0)
    else:  # the block bulges out under the smooth platen: its corners move apart
        right = top.locations[0] == top.locations[0].max()
        assert spread[right][0] > 1e-6 * abs(d)
        assert solver.u[top.x][top.locations[0] == 0.0][0] < -1e-6 * abs(d)
    fx, fy = problem.boundary_force("top", solver.reaction)
    # the reaction is the force the support exerts on the body: the footing pushes down
    assert fy < 0 and abs(fx) < 1e-6 * abs(fy)


def test_smooth_rigid_body_must_move_along_an_axis():
    with pytest.raises(ParameterError, match="along x or y"):
        RigidBody("wall", (1e-3, 1e-3), rough=False)
    assert RigidBody("wall", (1e-3, 0.0), rough=False).components == (0,)


def test_later_condition_wins_on_a_shared_dof():
    data = rectangle_mesh(0.4, 0.2, 4, 2, "quad8")
    data = select_boundaries(data, {"base": "x = right and y <= 0.1",
                                    "wall": "x = right and y >= 0.1"})
    problem = build_problem(data, [Fixed("left"), Fixed("bottom"), Fixed("base"),
                                   RigidBody("wall", (2e-3, 0.0), rough=False)])
    loading = problem.loading
    value = dict(zip(loading.dirichlet_dofs.tolist(), loading.dirichlet_end.tolist(),
                     strict=True))
    shared = np.intersect1d(problem.boundaries["base"].x, problem.boundaries["wall"].x)
    assert shared.size == 1 and value[int(shared[0])] == 2e-3
    assert all(value[int(k)] == 2e-3 for k in problem.boundaries["wall"].x)
    # smooth wall: its u_y free, but where the base holds it
    free_y = set(problem.boundaries["wall"].y.tolist()) - set(problem.boundaries["base"].y.tolist())
    assert free_y and not free_y & set(value)


@pytest.mark.parametrize("conditions, match", [
    ([Pressure("top", 1e3)], "prescribe no displacement"),
    ([Roller("left", 0), Roller("right", 0)], "translate in y"),
    ([Roller("bottom", 1)], "translate in x"),
    ([Roller("bottom", 0), Roller("left", 1)], "rotate"),
])
def test_rigid_body_modes_are_refused(conditions, match):
    data = rectangle_mesh(0.2, 0.1, 2, 2, "quad4")
    with pytest.raises(ParameterError, match=match):
        build_problem(data, conditions)


def test_unknown_boundaries_and_bad_values_are_refused():
    data = rectangle_mesh(0.2, 0.1, 2, 2, "tri3")
    with pytest.raises(ParameterError, match="'footing' of Fixed is not a named boundary"):
        build_problem(data, [Fixed("footing")])
    with pytest.raises(ParameterError, match="component"):
        Roller("left", 2)
    with pytest.raises(ParameterError, match="unit_weight"):
        Gravity(-1.0)
    with pytest.raises(ParameterError, match="end"):
        Displacement("top", 1, float("nan"))
    problem = build_problem(data, [Fixed("bottom"), Displacement("top", 1, -1e-3)])
    with pytest.raises(ParameterError, match="'wall' is not a boundary"):
        problem.boundary_force("wall", np.zeros(problem.basis.N))
    assert problem.points.shape == (problem.weights.size, 2)
    coords, cells, kind, dofs = problem.nodes()
    assert kind == "triangle" and cells.shape[1] == 3 and dofs.shape == (2, coords.shape[0])
