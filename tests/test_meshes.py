"""Mesh files and generated meshes of boundary-value problems (fem/boundary_value/meshes.py)."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.boundaries import select_facets
from granular_material.fem.boundary_value.loading import Loading
from granular_material.fem.boundary_value.meshes import make_basis, read_mesh, rectangle_mesh
from granular_material.fem.boundary_value.reactions import boundary_dofs
from granular_material.fem.forms import gauss_points_grad
from granular_material.fem.materials.linear_elastic import LinearElastic, isotropic_tangent
from granular_material.fem.solver.newton import NewtonSettings, NewtonSolver

FOOTING = Path("/usr/share/doc/yade/examples/FEMxDEM/footing.msh")
E, NU = 50e6, 0.25
#: gmsh element type numbers: (line, cell) of each element
GMSH_TYPES = {"tri3": (1, 2), "tri6": (8, 9), "quad4": (1, 3), "quad8": (8, 16),
              "quad9": (8, 10)}
SIDES = {"bottom": 1, "right": 2, "top": 3, "left": 4}


def _patch(element: str, distort: bool = True, shear: float = 0.0):
    """A 2 × 2 patch of [0, 2] × [0, 1.5] (four quads, or eight triangles): corner, midside
    and centre node coordinates (k, 2), the cells (gmsh order, as rows of node indices),
    and per side its lines (rows: two ends, then the midside node if quadratic). One cell
    runs clockwise; an unused node (a geometry point) is first."""
    xs, ys = np.array([0.0, 0.9, 2.0]), np.array([0.0, 0.8, 1.5])
    corner = np.array([[x, y] for y in ys for x in xs])
    if distort:
        corner[4] = [1.15, 0.62]
    corner[:, 0] += shear * corner[:, 1]
    nodes = [np.array([5.0, 5.0]), *corner]  # node 0 unused
    cid = lambda i, j: 1 + 3 * j + i  # noqa: E731
    quads = [[cid(i, j), cid(i + 1, j), cid(i + 1, j + 1), cid(i, j + 1)]
             for j in range(2) for i in range(2)]
    if element.startswith("tri"):
        cells = []
        for q in quads:
            cells += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    else:
        cells = quads
    cells[1] = [cells[1][0], *cells[1][1:][::-1]]  # clockwise
    quadratic = element in ("tri6", "quad8", "quad9")
    mid: dict[tuple[int, int], int] = {}

    def midside(a: int, b: int) -> int:
        key = (min(a, b), max(a, b))
        if key not in mid:
            mid[key] = len(nodes)
            nodes.append(0.5 * (nodes[a] + nodes[b]))
        return mid[key]

    full = []
    for c in cells:
        row = list(c)
        if quadratic:
            row += [midside(c[k], c[(k + 1) % len(c)]) for k in range(len(c))]
        if element == "quad9":
            nodes.append(np.mean([nodes[k] for k in c], axis=0))
            row.append(len(nodes) - 1)
        full.append(row)
    side_corners = {"bottom": [(cid(0, 0), cid(1, 0)), (cid(1, 0), cid(2, 0))],
                    "right": [(cid(2, 0), cid(2, 1)), (cid(2, 1), cid(2, 2))],
                    "top": [(cid(2, 2), cid(1, 2)), (cid(1, 2), cid(0, 2))],
                    "left": [(cid(0, 2), cid(0, 1)), (cid(0, 1), cid(0, 0))]}
    lines = {name: [[a, b, midside(a, b)] if quadratic else [a, b] for a, b in pairs]
             for name, pairs in side_corners.items()}
    return np.array(nodes), full, lines


def _write_v2(path: Path, element: str, nodes, cells, lines, named: bool = True) -> Path:
    line_type, cell_type = GMSH_TYPES[element]
    out = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat"]
    if named:
        out += ["$PhysicalNames", "5"] + [f'1 {t} "{n}"' for n, t in SIDES.items()]
        out += ['2 5 "soil"', "$EndPhysicalNames"]
    out += ["$Nodes", str(len(nodes))] + [f"{k + 1} {float(x)!r} {float(y)!r} 0" for k, (x, y) in
                                          enumerate(nodes)] + ["$EndNodes"]
    rows = []
    for name, group in lines.items():
        rows += [(line_type, SIDES[name], SIDES[name], row) for row in group]
    rows += [(cell_type, 5, 1, row) for row in cells]
    out += ["$Elements", str(len(rows))]
    out += [f"{k + 1} {t} 2 {phys} {geo} " + " ".join(str(n + 1) for n in row)
            for k, (t, phys, geo, row) in enumerate(rows)]
    path.write_text("\n".join([*out, "$EndElements", ""]))
    return path


def _write_v4(path: Path, element: str, nodes, cells, lines) -> Path:
    line_type, cell_type = GMSH_TYPES[element]
    lo, hi = nodes[1:].min(axis=0), nodes[1:].max(axis=0)
    box = f"{float(lo[0])!r} {float(lo[1])!r} 0 {float(hi[0])!r} {float(hi[1])!r} 0"
    out = ["$MeshFormat", "4.1 0 8", "$EndMeshFormat", "$PhysicalNames", "5"]
    out += [f'1 {t} "{n}"' for n, t in SIDES.items()] + ['2 5 "soil"', "$EndPhysicalNames"]
    out += ["$Entities", "0 4 1 0"]
    out += [f"{t} {box} 1 {t} 0" for t in SIDES.values()]
    out += [f"1 {box} 1 5 4 1 2 3 4", "$EndEntities"]
    n = len(nodes)
    out += ["$Nodes", f"1 {n} 1 {n}", f"2 1 0 {n}"] + [str(k + 1) for k in range(n)]
    out += [f"{float(x)!r} {float(y)!r} 0" for x, y in nodes] + ["$EndNodes"]
    total = sum(len(g) for g in lines.values()) + len(cells)
    out += ["$Elements", f"5 {total} 1 {total}"]
    tag = 1
    for name, group in lines.items():
        out.append(f"1 {SIDES[name]} {line_type} {len(group)}")
        for row in group:
            out.append(f"{tag} " + " ".join(str(k + 1) for k in row))
            tag += 1
    out.append(f"2 1 {cell_type} {len(cells)}")
    for row in cells:
        out.append(f"{tag} " + " ".join(str(k + 1) for k in row))
        tag += 1
    path.write_text("\n".join([*out, "$EndElements", ""]))
    return path


def _linear_patch(mesh_data, gauss=None):
    """Solve the patch with every boundary node at u = A x + b: (basis, u, stress, exact u)."""
    a = np.array([[1.0e-3, -0.4e-3], [0.7e-3, -2.0e-3]])
    b = np.array([1e-4, -3e-4])
    basis = make_basis(mesh_data, gauss)
    outer = boundary_dofs(basis, mesh_data.mesh.boundary_facets())
    dofs = np.concatenate([outer.x, outer.y])
    x = basis.doflocs
    exact = np.empty(basis.N)
    exact[0::2] = a[0] @ x[:, 0::2] + b[0]
    exact[1::2] = a[1] @ x[:, 1::2] + b[1]
    loading = Loading(dofs, exact[dofs], np.zeros(basis.N), np.zeros(basis.N))
    material = LinearElastic(young=E, poisson=NU)
    solver = NewtonSolver(basis, material, loading, NewtonSettings(formulation="small-strain"))
    solver.run(1)
    return basis, solver.u, solver.response.stress, exact, a


@pytest.mark.parametrize("element", list(GMSH_TYPES))
@pytest.mark.parametrize("version", ["2.2", "4.1"])
def test_patch_test_on_a_file_mesh(tmp_path, element, version):
    nodes, cells, lines = _patch(element)
    write = _write_v2 if version == "2.2" else _write_v4
    data = read_mesh(write(tmp_path / f"patch-{element}.msh", element, nodes, cells, lines))
    assert data.element == element
    assert data.n_elements == len(cells)
    assert sorted(data.boundaries) == sorted(SIDES)
    assert data.subdomains["soil"].tolist() == list(range(len(cells)))
    assert data.mesh.p.shape[1] == 9  # the corners; the unused node and the midsides gone
    np.testing.assert_array_equal(data.mesh.p.T, nodes[data.nodes])
    for name, group in lines.items():  # each side's facets end at that side's nodes
        ends = {tuple(nodes[k]) for row in group for k in row[:2]}
        got = {tuple(p) for p in data.mesh.p[:, data.mesh.facets[:, data.boundaries[name]]]
               .reshape(2, -1).T}
        assert got == ends
    basis, u, stress, exact, a = _linear_patch(data)
    detj = basis.mapping.detDF(basis.X)
    if element.startswith("quad"):  # corners turned counter-clockwise
        assert np.all(detj > 0)
    assert np.all(basis.dx > 0)
    np.testing.assert_allclose(basis.dx.sum(), 3.0, rtol=1e-12)
    np.testing.assert_allclose(u, exact, atol=1e-15)
    eps = 0.5 * (a + a.T)
    sigma = np.einsum("ijkl,kl->ij", isotropic_tangent(*LinearElastic(E, NU).parameters.lame),
                      eps)
    np.testing.assert_allclose(stress, np.broadcast_to(sigma, stress.shape), rtol=1e-9,
                               atol=1e-9 * np.abs(sigma).max())


@pytest.mark.parametrize("element, distort, shear", [("tri6", True, 0.0),
                                                     ("quad9", True, 0.0),
                                                     ("quad8", False, 0.4)])
def test_quadratic_fields_are_reproduced(tmp_path, element, distort, shear):
    # tri6 on straight triangles and quad9 on any bilinear quadrilateral hold every quadratic
    # field; quad8 (serendipity) only on parallelograms (Arnold, Boffi & Falk 2002)
    nodes, cells, lines = _patch(element, distort, shear)
    data = read_mesh(_write_v2(tmp_path / "q.msh", element, nodes, cells, lines))
    basis = make_basis(data, 3)
    x, y = basis.doflocs[:, 0::2]
    u = np.empty(basis.N)
    u[0::2] = 0.3 * x ** 2 - 0.2 * x * y + 0.1 * y ** 2
    u[1::2] = -0.4 * x * y + 0.25 * y ** 2 + 0.05 * x ** 2
    grad = gauss_points_grad(basis, u)
    gx, gy = np.asarray(basis.global_coordinates()).reshape(2, -1)
    expected = np.stack([np.stack([0.6 * gx - 0.2 * gy, -0.2 * gx + 0.2 * gy], -1),
                         np.stack([-0.4 * gy + 0.1 * gx, -0.4 * gx + 0.5 * gy], -1)], 1)
    np.testing.assert_allclose(grad, expected, atol=1e-12)


def test_unnamed_groups_and_geometric_entities(tmp_path):
    nodes, cells, lines = _patch("tri3")
    data = read_mesh(_write_v2(tmp_path / "u.msh", "tri3", nodes, cells, lines, named=False))
    assert sorted(data.boundaries) == ["group-1", "group-2", "group-3", "group-4"]
    assert "group-5" in data.subdomains


def test_curved_or_misordered_elements_are_refused(tmp_path):
    nodes, cells, lines = _patch("tri6")
    nodes = nodes.copy()
    nodes[cells[0][3]] += [0.0, 0.05]  # a midside node off its chord
    with pytest.raises(ParameterError, match="midside node"):
        read_mesh(_write_v2(tmp_path / "c.msh", "tri6", nodes, cells, lines))
    nodes, cells, lines = _patch("quad8")
    cells[2] = cells[2][:4] + cells[2][5:] + cells[2][4:5]  # midsides rotated by one
    with pytest.raises(ParameterError, match="midside node"):
        read_mesh(_write_v2(tmp_path / "m.msh", "quad8", nodes, cells, lines))
    with pytest.raises(ParameterError, match="meshio cannot read"):
        read_mesh(tmp_path / "absent.msh")


@pytest.mark.skipif(not FOOTING.exists(), reason="YADE's FEMxDEM examples are not installed")
def test_footing_msh_of_guo_and_zhao_loads():
    data = read_mesh(FOOTING)
    assert data.element == "tri6" and data.n_elements == 2500
    basis = make_basis(data)
    assert basis.nelems * basis.X.shape[-1] == 7500
    np.testing.assert_allclose(basis.dx.sum(), 0.6 * 0.4, rtol=1e-12)
    assert data.bounding_box == pytest.approx((0.0, 0.6, -0.4, 0.0), abs=1e-12)
    # no physical groups in the file: its twelve lines named after their geometric entities
    assert sorted(data.boundaries, key=lambda n: int(n.split("-")[1])) == [
        f"entity-{k}" for k in range(1, 13)]
    top = data.mesh.p[:, data.mesh.facets[:, data.boundaries["entity-1"]]]
    np.testing.assert_allclose(top[1], 0.0, atol=1e-12)
    footing = select_facets(data, "y = top and x <= 0.05", "footing")
    assert footing.size == 5
    ends = data.mesh.p[:, data.mesh.facets[:, footing]]
    assert ends[0].min() == pytest.approx(0.0) and ends[0].max() == pytest.approx(0.05)


@pytest.mark.parametrize("element", ["quad4", "quad8", "tri6"])
def test_rectangle_mesh_sides_and_grading(element):
    data = rectangle_mesh(0.6, 0.4, 6, 4, element, grading=(4.0, 0.25), origin=(0.0, -0.4))
    assert data.bounding_box == pytest.approx((0.0, 0.6, -0.4, 0.0))
    xs = np.unique(data.mesh.p[0])
    dx = np.diff(xs)
    assert dx[-1] / dx[0] == pytest.approx(4.0)
    dy = np.diff(np.unique(data.mesh.p[1]))
    assert dy[-1] / dy[0] == pytest.approx(0.25)
    for name, (axis, value) in {"left": (0, 0.0), "right": (0, 0.6), "bottom": (1, -0.4),
                                "top": (1, 0.0)}.items():
        ends = data.mesh.p[:, data.mesh.facets[:, data.boundaries[name]]]
        np.testing.assert_allclose(ends[axis], value, atol=1e-12)
        assert data.boundaries[name].size == (6 if axis else 4)
    basis = make_basis(data)
    np.testing.assert_allclose(basis.dx.sum(), 0.24, rtol=1e-12)
    with pytest.raises(ParameterError, match="grading"):
        rectangle_mesh(1, 1, 2, 2, element, grading=(0.0, 1.0))


def test_cell_sets_of_other_formats(tmp_path):
    # meshio's Abaqus reader keeps element sets as cell sets: lines → boundaries, cells →
    # subdomains
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    none = np.array([], dtype=int)
    mesh = meshio.Mesh(points, [("line", np.array([[0, 1]])),
                                ("triangle", np.array([[0, 1, 2], [0, 2, 3]]))],
                       cell_sets={"bottom": [np.array([0]), none],
                                  "soil": [none, np.array([0, 1])]})
    meshio.write(tmp_path / "m.inp", mesh)
    data = read_mesh(tmp_path / "m.inp")
    assert data.element == "tri3" and list(data.boundaries) == ["bottom"]
    np.testing.assert_array_equal(_ends(data, data.boundaries["bottom"])[1], 0.0)
    assert data.subdomains["soil"].tolist() == [0, 1]


def _ends(data, facets):
    return data.mesh.p[:, data.mesh.facets[:, facets]].reshape(2, -1)
