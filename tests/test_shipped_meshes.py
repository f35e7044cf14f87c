"""The meshes shipped with the slope and layered-footing scenes: they read as tri6 (the
reduced DEM slope's as tri3) with the regions and boundary names the scenes use, their
boundaries lie where the scenes' comments (and the Bishop check of docs/guide/own-ground.md)
put them, and the gmsh script beside each makes it again (where gmsh is installed)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from granular_material.fem.boundary_value.meshes import read_mesh

MESHES = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "meshes"

#: mesh → its regions, and each boundary with the test its nodes meet
EXPECTED = {
    "embankment": (
        {"embankment", "foundation"},
        {"base": lambda x, y: np.isclose(y, -5.0),
         "left": lambda x, y: np.isclose(x, 0.0),
         "right": lambda x, y: np.isclose(x, 50.0) & (y <= 0.0),
         "crest": lambda x, y: np.isclose(y, 10.0) & (x <= 15.0),
         "face": lambda x, y: np.isclose(y, (30.0 - x) / 1.5),
         "toe": lambda x, y: np.isclose(y, 0.0) & (x >= 30.0)}),
    "footing-layered": (
        {"upper", "lower"},
        {"footing": lambda x, y: np.isclose(y, 0.0) & (x <= 1.0),
         "surface": lambda x, y: np.isclose(y, 0.0) & (x >= 1.0),
         "left": lambda x, y: np.isclose(x, 0.0),
         "right": lambda x, y: np.isclose(x, 5.0),
         "base": lambda x, y: np.isclose(y, -4.0)}),
}


def _nodes(mesh, facets: np.ndarray) -> np.ndarray:
    return mesh.mesh.p[:, np.unique(mesh.mesh.facets[:, facets])]


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_a_shipped_mesh_has_its_regions_and_boundaries_where_they_belong(name):
    mesh = read_mesh(MESHES / f"{name}.msh")
    regions, boundaries = EXPECTED[name]
    assert mesh.element == "tri6" and mesh.n_elements <= 1500
    assert set(mesh.subdomains) == regions
    assert set(mesh.boundaries) == set(boundaries)
    for boundary, on in boundaries.items():
        x, y = _nodes(mesh, mesh.boundaries[boundary])
        assert on(x, y).all(), boundary
    # the regions split the mesh at the layers' meeting (y = 0 and y = -1)
    upper, level = {"embankment": ("embankment", 0.0), "footing-layered": ("upper", -1.0)}[name]
    centroid_y = mesh.mesh.p[1][mesh.mesh.t].mean(axis=0)
    inside = np.zeros(mesh.n_elements, dtype=bool)
    inside[mesh.subdomains[upper]] = True
    assert (centroid_y[inside] > level).all() and (centroid_y[~inside] < level).all()
    assert (np.sort(np.concatenate(list(mesh.subdomains.values())))
            == np.arange(mesh.n_elements)).all()


@pytest.mark.skipif(importlib.util.find_spec("gmsh") is None,
                    reason="gmsh (pip install gmsh) makes the meshes; it is no dependency")
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_the_script_beside_a_mesh_makes_it(name, tmp_path):
    spec = importlib.util.spec_from_file_location(f"mesh_{name}", MESHES / f"{name}.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    count = script.build(tmp_path / f"{name}.msh")
    made, shipped = read_mesh(tmp_path / f"{name}.msh"), read_mesh(MESHES / f"{name}.msh")
    assert count == made.n_elements == shipped.n_elements
    assert set(made.subdomains) == set(shipped.subdomains)
    assert {k: len(v) for k, v in made.boundaries.items()} == {
        k: len(v) for k, v in shipped.boundaries.items()}


#: the reduced DEM slope's boundaries (slope-dem-reduced.toml): 1 m high at 2:1 on 0.5 m
DEM_SLOPE = {"base": lambda x, y: np.isclose(y, -0.5),
             "left": lambda x, y: np.isclose(x, 0.0),
             "right": lambda x, y: np.isclose(x, 5.0) & (y <= 0.0),
             "crest": lambda x, y: np.isclose(y, 1.0) & (x <= 1.5),
             "face": lambda x, y: np.isclose(y, (3.5 - x) / 2.0),
             "toe": lambda x, y: np.isclose(y, 0.0) & (x >= 3.5)}


def test_the_reduced_dem_slope_mesh_is_coarse_tri3_with_its_boundaries():
    mesh = read_mesh(MESHES / "slope-dem.msh")
    assert mesh.element == "tri3" and mesh.n_elements <= 200  # one RVE per element
    assert set(mesh.subdomains) == {"soil"} and set(mesh.boundaries) == set(DEM_SLOPE)
    for boundary, on in DEM_SLOPE.items():
        x, y = _nodes(mesh, mesh.boundaries[boundary])
        assert on(x, y).all(), boundary


@pytest.mark.skipif(importlib.util.find_spec("gmsh") is None,
                    reason="gmsh (pip install gmsh) makes the meshes; it is no dependency")
def test_the_script_beside_the_reduced_dem_slope_makes_it(tmp_path):
    spec = importlib.util.spec_from_file_location("mesh_slope_dem", MESHES / "slope-dem.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    count = script.build(tmp_path / "slope-dem.msh")
    made, shipped = read_mesh(tmp_path / "slope-dem.msh"), read_mesh(MESHES / "slope-dem.msh")
    assert count == made.n_elements == shipped.n_elements
    assert {k: len(v) for k, v in made.boundaries.items()} == {
        k: len(v) for k, v in shipped.boundaries.items()}
