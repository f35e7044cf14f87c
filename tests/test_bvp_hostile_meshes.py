"""Hostile meshes are refused before the first step, naming what is wrong: an element listed
twice, a part of the body held by nothing, degenerate elements (issue 61, kinds 3, 4 and 9's
"Zero Jacobian determinant")."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest
import tomllib
from run_helpers import PRESSED_BLOCK

from granular_material.cli import main
from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.conditions import Fixed, Roller, build_problem
from granular_material.fem.boundary_value.meshes import make_basis, read_mesh, rectangle_mesh
from granular_material.runs.boundary_value.runner import build, run_boundary_value
from granular_material.runs.boundary_value.spec import bvp_from_dict

SCENE = """test = "boundary-value"
steps = 2
[mesh]
{mesh}
[boundaries]
{boundaries}
{conditions}
"""
BLOCK = PRESSED_BLOCK.format(base="base")


def _blocks(path: Path, offsets=(0.0,), kind: str = "quad", twice: tuple[int, ...] = (),
            rotate: bool = False) -> Path:
    """2 × 2 blocks of 0.4 × 0.2 m at x = each of ``offsets`` [m] (quad4, or tri3 with
    ``kind = "triangle"``); the elements of ``twice`` listed once more (``rotate``: their
    corners starting from the second)."""
    points, cells = [], []
    for x0 in offsets:
        x, y = np.meshgrid(np.linspace(x0, x0 + 0.4, 3), np.linspace(0, 0.2, 3))
        base = len(points)
        points += [(a, b, 0.0) for a, b in zip(x.ravel(), y.ravel(), strict=True)]
        for i in range(2):
            for j in range(2):
                a, b = base + 3 * j + i, base + 3 * j + i + 1
                c, d = base + 3 * (j + 1) + i + 1, base + 3 * (j + 1) + i
                cells += [[a, b, c, d]] if kind == "quad" else [[a, b, c], [a, c, d]]
    for k in twice:
        cells.append(cells[k][1:] + cells[k][:1] if rotate else list(cells[k]))
    meshio.write(path, meshio.Mesh(np.array(points), [(kind, np.array(cells))]),
                 file_format="gmsh22", binary=False)
    return path


@pytest.mark.parametrize("kind, twice, rotate", [
    ("quad", (0,), False), ("quad", (3,), True), ("triangle", (5,), False),
    ("triangle", (0, 2), True)])
def test_an_element_listed_twice_is_refused_naming_it(tmp_path, capsys, kind, twice, rotate):
    path = _blocks(tmp_path / "m.msh", kind=kind, twice=twice, rotate=rotate)
    n = 4 if kind == "quad" else 8
    with pytest.raises(ParameterError) as refused:
        read_mesh(path)
    assert f"element {n} has the corners of element {twice[0]}" in str(refused.value)
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.format(mesh='file = "m.msh"', conditions=BLOCK,
                                  boundaries='base = "y = bottom"\ntop = "y = top"'))
    for check in ([], ["--check"]):
        assert main(["run", str(scene), "--out", str(tmp_path / "run"), *check]) == 2
        assert "listed twice" in capsys.readouterr().err
    assert not (tmp_path / "run" / "steps.csv").exists()  # no step (scene.toml: kind 6's)


PARTS = {
    "held by nothing": "",
    "a roller only": '[[conditions]]\ntype = "roller"\nboundary = "far"\ncomponent = "y"\n',
    "held at one line in x": ('[[conditions]]\ntype = "roller"\nboundary = "far_left"\n'
                              'component = "y"\n[[conditions]]\ntype = "roller"\n'
                              'boundary = "far_base_left"\ncomponent = "x"\n'),
}


@pytest.mark.parametrize("case", list(PARTS))
def test_a_part_of_the_body_the_conditions_leave_free_is_refused_naming_it(tmp_path, capsys,
                                                                           case):
    _blocks(tmp_path / "m.msh", offsets=(0.0, 1.0))
    boundaries = ('base = "y = bottom and x <= 0.5"\ntop = "y = top and x <= 0.5"\n'
                  'far = "y = bottom and x >= 0.9"\nfar_left = "x = 1.0"\n'
                  'far_base_left = "y = bottom and x >= 0.9 and x <= 1.25"')
    text = SCENE.format(mesh='file = "m.msh"', boundaries=boundaries,
                        conditions=BLOCK + PARTS[case])
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    with pytest.raises(ParameterError) as refused:
        build(bvp_from_dict(tomllib.loads(text), tmp_path), allocate=False)
    assert "part 2 of the mesh's 2 unconnected parts" in str(refused.value)
    assert "x 1 to 1.4 m" in str(refused.value)
    assert main(["run", str(scene), "--out", str(tmp_path / "run")]) == 2
    assert "part 2" in capsys.readouterr().err
    assert not (tmp_path / "run" / "steps.csv").exists()


def test_unconnected_parts_each_held_run(tmp_path):
    _blocks(tmp_path / "m.msh", offsets=(0.0, 1.0))
    text = SCENE.format(mesh='file = "m.msh"', boundaries='base = "y = bottom"\ntop = "y = top"',
                        conditions=BLOCK)
    both = run_boundary_value(bvp_from_dict(tomllib.loads(text), tmp_path))
    _blocks(tmp_path / "m.msh")
    one = run_boundary_value(bvp_from_dict(tomllib.loads(text), tmp_path))
    assert both.error is None and one.error is None
    force = one.steps["top_force_y"].iloc[-1]
    assert force < 0  # pressed down
    assert both.steps["top_force_y"].iloc[-1] == pytest.approx(2 * force, rel=1e-9)


def test_a_mesh_of_one_part_keeps_the_messages_of_old():
    mesh = rectangle_mesh(0.4, 0.2, 2, 1)
    build_problem(mesh, [Fixed("bottom")])  # one part: accepted
    with pytest.raises(ParameterError, match="translate in y"):
        build_problem(mesh, [Roller("bottom", 0)])  # one part: the message of old


@pytest.mark.parametrize("grading", ["[1e-17, 1.0]", "[1.0, 1e-17]", "[1e-300, 1e-300]"])
@pytest.mark.parametrize("check", [[], ["--check"]])
def test_degenerate_elements_of_a_grading_are_refused_not_a_traceback(tmp_path, capsys,
                                                                      grading, check):
    text = SCENE.format(mesh=f"size = [0.4, 0.2]\nelements = [20, 3]\ngrading = {grading}",
                        boundaries="", conditions=BLOCK.replace('"base"', '"bottom"'))
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    assert main(["run", str(scene), "--out", str(tmp_path / "run"), *check]) == 2
    err = capsys.readouterr().err
    assert "degenerate elements" in err and "Traceback" not in err
    assert not (tmp_path / "run" / "steps.csv").exists()


def test_a_sliver_element_in_a_file_is_refused(tmp_path):
    points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 1e-14, 0]])
    cells = np.array([[0, 1, 2], [0, 2, 3], [0, 4, 1]])
    meshio.write(tmp_path / "s.msh", meshio.Mesh(points, [("triangle", cells)]),
                 file_format="gmsh22", binary=False)
    mesh = read_mesh(tmp_path / "s.msh")
    with pytest.raises(ParameterError, match=r"degenerate elements \(first: element 2"):
        make_basis(mesh)


def test_a_mesh_far_from_the_origin_is_not_degenerate():
    mesh = rectangle_mesh(0.4, 0.2, 4, 2, origin=(1e12, 1e12))
    assert build_problem(mesh, [Fixed("bottom")]).basis.nelems == 8
