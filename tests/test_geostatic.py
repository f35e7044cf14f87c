"""Geostatic and uniform initial stress, and the FEM in equilibrium at step 0
(fem/boundary_value/initial_stress.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from skfem import MeshQuad1

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.boundaries import select_boundaries
from granular_material.fem.boundary_value.conditions import (
    Fixed,
    Gravity,
    Pressure,
    Roller,
    build_problem,
)
from granular_material.fem.boundary_value.initial_stress import geostatic_stress, uniform_stress
from granular_material.fem.boundary_value.meshes import MeshData, read_mesh, rectangle_mesh
from granular_material.fem.materials.linear_elastic import LinearElastic
from granular_material.fem.solver.newton import NewtonSettings, NewtonSolver

FOOTING = Path("/usr/share/doc/yade/examples/FEMxDEM/footing.msh")
GAMMA, Q, K0 = 16e3, 20e3, 0.5


def test_geostatic_stress_values():
    xy = np.array([[0.0, 0.0], [0.3, -0.4], [0.1, -0.1]])
    sigma = geostatic_stress(xy, 0.0, GAMMA, Q, K0)
    sv = -(Q + GAMMA * np.array([0.0, 0.4, 0.1]))
    np.testing.assert_allclose(sigma[:, 1, 1], sv)
    np.testing.assert_allclose(sigma[:, 0, 0], K0 * sv)
    np.testing.assert_array_equal(sigma[:, 0, 1], 0.0)
    np.testing.assert_array_equal(sigma[:, 1, 0], 0.0)
    np.testing.assert_allclose(uniform_stress(3, Q), np.broadcast_to(-Q * np.eye(2), (3, 2, 2)))
    with pytest.raises(ParameterError, match="surface_y"):
        geostatic_stress(xy, -0.2, GAMMA, Q, K0)
    with pytest.raises(ParameterError, match="k0"):
        geostatic_stress(xy, 0.0, GAMMA, Q, 0.0)
    with pytest.raises(ParameterError, match="points_xy"):
        geostatic_stress(xy[:, :1], 0.0, GAMMA, Q, K0)
    with pytest.raises(ParameterError, match="unit_weight"):
        geostatic_stress(xy, 0.0, -1.0, Q, K0)


def _ground(data):
    return [Roller("left", 0), Roller("right", 0), Fixed("bottom"), Pressure("top", Q),
            Gravity(GAMMA)]


def _meshes():
    yield "tri6", rectangle_mesh(0.6, 0.4, 6, 4, "tri6", grading=(3.0, 0.5), origin=(0, -0.4))
    yield "quad8", rectangle_mesh(0.6, 0.4, 6, 4, "quad8", grading=(3.0, 0.5),
                                  origin=(0, -0.4))
    yield "quad9", rectangle_mesh(0.6, 0.4, 5, 3, "quad9", origin=(0, -0.4))
    yield "tri3", rectangle_mesh(0.6, 0.4, 5, 3, "tri3", origin=(0, -0.4))
    grid = rectangle_mesh(0.6, 0.4, 6, 4, "quad8", origin=(0, -0.4))
    p = grid.mesh.p.copy()
    inner = (p[0] > 1e-9) & (p[0] < 0.6 - 1e-9) & (p[1] > -0.4 + 1e-9) & (p[1] < -1e-9)
    p[:, inner] += np.random.default_rng(3).uniform(-0.02, 0.02, size=(2, int(inner.sum())))
    yield "quad8-distorted", MeshData(MeshQuad1(p, grid.mesh.t), "quad8", grid.boundaries)
    if FOOTING.exists():
        data = read_mesh(FOOTING)
        yield "footing.msh", select_boundaries(data, {"left": "x = left", "right": "x = right",
                                                      "bottom": "y = bottom", "top": "y = top"})


@pytest.mark.parametrize("formulation", ["small-strain", "updated-lagrangian"])
@pytest.mark.parametrize("name", ["tri6", "quad8", "quad9", "tri3", "quad8-distorted",
                                  "footing.msh"])
def test_geostatic_start_is_in_equilibrium(name, formulation):
    meshes = dict(_meshes())
    if name not in meshes:
        pytest.skip("YADE's FEMxDEM examples are not installed")
    problem = build_problem(meshes[name], _ground(meshes[name]))
    sigma0 = geostatic_stress(problem.points, 0.0, GAMMA, Q, K0)
    material = LinearElastic(young=30e6, poisson=0.3, initial_stress=sigma0)
    settings = NewtonSettings(formulation=formulation)
    solver = NewtonSolver(problem.basis, material, problem.loading, settings)
    f_ext = problem.loading.at(0.0, np.zeros(problem.basis.N))[1]
    free = np.setdiff1d(np.arange(problem.basis.N), problem.loading.dirichlet_dofs)
    residual = np.linalg.norm((solver.f_int - f_ext)[free])
    scale = np.linalg.norm(f_ext[free])
    # far below any Newton tolerance (rtol 0.005 of a step's load): equilibrium, not luck
    assert residual <= 1e-11 * scale
    # and without the initial stress the same loads leave a residual of their own size
    plain = NewtonSolver(problem.basis, LinearElastic(30e6, 0.3), problem.loading, settings)
    assert np.linalg.norm((plain.f_int - f_ext)[free]) > 0.5 * scale
    # a step taken from there moves nothing
    solver.run(1)
    assert np.abs(solver.u).max() < 1e-6 * GAMMA * 0.4 ** 2 / 30e6
    np.testing.assert_allclose(solver.response.stress, sigma0, atol=1e-6 * Q)


def test_geostatic_start_is_not_in_equilibrium_with_the_wrong_k0_on_the_sides():
    # the check can fail: a K0 stress held by pressures that do not match it leaves a residual
    data = rectangle_mesh(0.6, 0.4, 4, 3, "quad8", origin=(0, -0.4))
    problem = build_problem(data, [Fixed("bottom"), Pressure("left", Q), Pressure("right", Q),
                                   Pressure("top", Q), Gravity(GAMMA)])
    sigma0 = geostatic_stress(problem.points, 0.0, GAMMA, Q, K0)
    solver = NewtonSolver(problem.basis, LinearElastic(30e6, 0.3, sigma0), problem.loading)
    f_ext = problem.loading.at(0.0)[1]
    free = np.setdiff1d(np.arange(problem.basis.N), problem.loading.dirichlet_dofs)
    assert np.linalg.norm((solver.f_int - f_ext)[free]) > 0.05 * np.linalg.norm(f_ext[free])
