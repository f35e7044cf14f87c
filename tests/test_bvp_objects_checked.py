"""The boundary-value objects of granular_material.fem meet a hostile caller (issue 47): a value
of any type for any field of a condition, a mesh, a boundary expression or an initial state is
taken or is a ParameterError naming it (never a TypeError, AttributeError, OverflowError or a
process exit); a mesh or a stress field larger than the memory is refused before allocation,
with the estimate; no NaN or infinite stress comes out of the initial states."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.boundaries import select_boundaries, select_facets
from granular_material.fem.boundary_value.conditions import (
    Displacement,
    Fixed,
    Gravity,
    Pressure,
    RigidBody,
    Roller,
    build_problem,
)
from granular_material.fem.boundary_value.initial_stress import geostatic_stress, uniform_stress
from granular_material.fem.boundary_value.meshes import read_mesh, rectangle_mesh

ANY_VALUE = st.one_of(
    st.none(), st.booleans(), st.text(max_size=6), st.floats(), st.complex_numbers(),
    st.integers(-(10**400), 10**400), st.lists(st.floats(-10, 10), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))
VALID = {Fixed: {"boundary": "top"}, Roller: {"boundary": "left", "component": 0},
         Displacement: {"boundary": "top", "component": 1, "end": -0.01},
         RigidBody: {"boundary": "top", "displacement": (0.0, -0.01), "rough": True},
         Pressure: {"boundary": "top", "value": 1e5}, Gravity: {"unit_weight": 18e3}}
FIELDS = [(kind, f.name) for kind in VALID for f in dataclasses.fields(kind)]


@pytest.mark.parametrize(("kind", "name"), FIELDS, ids=[f"{k.__name__}.{n}" for k, n in FIELDS])
@given(value=ANY_VALUE)
@settings(max_examples=40, deadline=None)
def test_a_condition_takes_its_type_or_names_the_field(kind, name, value):
    try:
        condition = kind(**{**VALID[kind], name: value})
    except ParameterError as exc:
        assert exc.field == name or (name == "displacement" and exc.field == "displacement")
        return
    for field in dataclasses.fields(condition):  # what was taken is of the field's own type
        taken = getattr(condition, field.name)
        assert not isinstance(taken, complex | dict | list)
        assert taken is not None or field.default is None  # None only where it is the default


RECTANGLE = {"width": 1.0, "height": 1.0, "nx": 2, "ny": 2, "element": "quad4",
             "grading": None, "origin": (0.0, 0.0)}


@pytest.mark.parametrize("name", list(RECTANGLE))
@given(value=ANY_VALUE)
@settings(max_examples=30, deadline=None)
def test_a_rectangle_mesh_takes_its_type_or_names_the_argument(name, value):
    try:
        rectangle_mesh(**{**RECTANGLE, name: value})
    except ParameterError as exc:
        assert exc.field in (name, "nx", "ny"), exc


@pytest.mark.parametrize(("nx", "ny"), [(10**9, 1), (10**5, 10**5), (10**400, 1)])
def test_a_mesh_beyond_the_memory_is_refused_before_it_is_made(nx, ny):
    start = time.perf_counter()
    with pytest.raises(ParameterError, match=r"a mesh of .* rectangles needs about .*B of "
                                             r"memory"):
        rectangle_mesh(1.0, 1.0, nx, ny)
    assert time.perf_counter() - start < 1.0  # nothing was allocated (10**9 took 11 s to fail)


@pytest.mark.parametrize("text", ["hello\n", "", "$MeshFormat\n4.1 0 8\n"])
def test_a_file_that_is_no_mesh_is_a_parameter_error_not_an_exit(tmp_path, text):
    path = tmp_path / "bad.msh"
    path.write_text(text)
    # meshio exits (SystemExit) for the first; an empty file is said to be so
    with pytest.raises(ParameterError, match=r"bad.msh( is empty|: meshio cannot read it)"):
        read_mesh(path)


def _vtk(tmp_path, points: str, cells: str):
    path = tmp_path / "m.vtk"
    path.write_text("# vtk DataFile Version 2.0\nx\nASCII\nDATASET UNSTRUCTURED_GRID\n"
                    f"POINTS 3 float\n{points}\nCELLS 1 4\n{cells}\nCELL_TYPES 1\n5\n")
    return path


def test_a_mesh_whose_elements_name_missing_nodes_or_nan_nodes_is_refused(tmp_path):
    with pytest.raises(ParameterError, match="name nodes up to 7"):
        read_mesh(_vtk(tmp_path, "0 0 0\n1 0 0\n0 1 0", "3 0 1 7"))
    with pytest.raises(ParameterError, match="not finite"):
        read_mesh(_vtk(tmp_path, "0 0 0\nnan 0 0\n0 1 0", "3 0 1 2"))


@given(value=ANY_VALUE)
@settings(max_examples=40, deadline=None)
def test_a_boundary_expression_of_any_type_is_named(value):
    mesh = rectangle_mesh(1.0, 1.0, 2, 2)
    try:
        select_facets(mesh, value, "footing")
    except ParameterError as exc:
        assert exc.field == "footing"
    with pytest.raises(ParameterError, match="boundaries"):
        select_boundaries(mesh, [value])


def test_build_problem_names_what_is_not_a_mesh_or_a_list_of_conditions():
    mesh = rectangle_mesh(1.0, 1.0, 2, 2)
    with pytest.raises(ParameterError, match="mesh_data must be a MeshData"):
        build_problem(None, [Fixed("bottom")])
    with pytest.raises(ParameterError, match="conditions must be a list"):
        build_problem(mesh, None)


GEOSTATIC = {"surface_y": 1.0, "unit_weight": 18e3, "surcharge": 0.0, "k0": 0.5}


@pytest.mark.parametrize("name", list(GEOSTATIC))
@given(value=ANY_VALUE)
@settings(max_examples=40, deadline=None)
def test_a_geostatic_state_is_finite_or_a_named_refusal(name, value):
    points = np.array([[0.0, 0.0], [0.5, -2.0]])
    try:
        stress = geostatic_stress(points, **{**GEOSTATIC, name: value})
    except ParameterError as exc:
        assert exc.field == name or exc.field == "unit_weight"  # an overflow names the weight
        return
    assert np.isfinite(stress).all()


@pytest.mark.parametrize("points", [np.array([[0.0, np.nan]]), np.zeros((2, 2)) + 1j,
                                    np.array([["a", "b"]])])
def test_geostatic_points_must_be_finite_real_coordinates(points):
    with pytest.raises(ParameterError, match="points_xy"):
        geostatic_stress(points, 1.0, 18e3)


def test_a_geostatic_stress_beyond_any_float_is_refused():
    with pytest.raises(ParameterError, match="beyond any float"):
        geostatic_stress(np.array([[0.0, -1e10]]), 1.0, 1e300)


def test_uniform_stress_beyond_the_memory_is_refused_before_allocation():
    with pytest.raises(ParameterError, match=r"stress tensors needs about 3.2e\+13|32 TB"):
        uniform_stress(10**12, 1e5)
    with pytest.raises(ParameterError, match="p must be a finite number"):
        uniform_stress(3, None)
