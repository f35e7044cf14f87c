"""Meshes of a boundary-value problem: read from a file (through meshio) or generated.

Every mesh becomes a *straight-sided* scikit-fem mesh of its corner nodes (``MeshTri1`` or
``MeshQuad1``) and the name of its element in
:data:`~granular_material.fem.boundary_value.biaxial.ELEMENTS`;
the element adds the midside (and centre) nodes itself, as the biaxial problems do. A
quadratic element whose midside nodes lie at the midpoints of straight edges (and, quad9,
whose centre node is the mean of its corners) maps the same as its corners' linear map, so
nothing is lost; a curved element (a midside node off its chord) is refused, a
:class:`~granular_material.errors.ParameterError` naming the file.

File elements (meshio's names → ours): ``triangle`` → tri3, ``triangle6`` → tri6, ``quad``
→ quad4, ``quad8`` → quad8 (scikit-fem's serendipity ``ElementQuadS2``), ``quad9`` → quad9.
The node order of gmsh, VTK and meshio (corners counter-clockwise, then the midsides of edges
01, 12, 20 | 23, 30, then the centre) is checked through the midside positions; corners that
run clockwise are turned counter-clockwise (scikit-fem then sorts a triangle's corners, its
own convention; the integration weights are positive either way). Nodes
no element uses (gmsh's geometry points, the midside nodes) are dropped: ``MeshData.nodes``
maps each mesh point back to its node in the file.

Named boundaries come from the line cells (``line``, ``line3``) of the file: gmsh's physical
groups, named from ``$PhysicalNames`` or ``group-<tag>`` when the group has no name; lines in
no physical group (tag 0, as in Guo & Zhao's ``footing.msh``) are named after their geometric
entity, ``entity-<tag>``; other formats' cell sets by their own names. Groups of the
two-dimensional cells become ``subdomains`` (element indices) the same way. Boundaries are
facet indices of the scikit-fem mesh.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import meshio
import numpy as np
from skfem import Basis, MeshQuad1, MeshTri1
from skfem.mesh import Mesh

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.biaxial import (
    DEFAULT_GAUSS,
    TRIANGLE_RULES,
    TRIANGLES,
    element_of,
)
from granular_material.memory import available_memory, memory_refusal
from granular_material.typed_fields import conform

__all__ = ["MESHIO_ELEMENTS", "MeshData", "make_basis", "read_mesh", "rectangle_mesh"]

#: meshio's two-dimensional cell types → the element names of fem.problems.ELEMENTS
MESHIO_ELEMENTS = {"triangle": "tri3", "triangle6": "tri6", "quad": "quad4", "quad8": "quad8",
                   "quad9": "quad9"}
#: meshio's line cell types (the boundaries)
_LINES = ("line", "line3")
#: memory while a rectangle mesh is made, per rectangle of its grid [bytes]: its peak measured
#: (tracemalloc, 300 x 300) at 357 for quad4 and quad9, 503 for tri6 (two triangles), with room
_RECTANGLE_BYTES = 600
#: the edges of a triangle and a quadrilateral, corner to corner, in the file's node order
_EDGES = {3: ((0, 1), (1, 2), (2, 0)), 4: ((0, 1), (1, 2), (2, 3), (3, 0))}


@dataclass(frozen=True)
class MeshData:
    """A mesh with its element and named facets.

    Attributes:
        mesh: scikit-fem mesh of the corner nodes (``MeshTri1`` or ``MeshQuad1``), [m]:
            quadrilaterals counter-clockwise, triangles in scikit-fem's own order (corners
            sorted; its integration weights take ``|det J|``).
        element: the element's name, a key of
            :data:`~granular_material.fem.boundary_value.biaxial.ELEMENTS`.
        boundaries: name → facet indices of ``mesh`` (ascending, int64).
        subdomains: name → element indices of ``mesh`` (ascending, int64).
        nodes: for each mesh point, its node index in the file (0-based), shape (n_points,);
            the identity for a generated mesh.
        source: the file read, or a description of the generated mesh.
    """

    mesh: Mesh
    element: str
    boundaries: Mapping[str, np.ndarray] = field(default_factory=dict)
    subdomains: Mapping[str, np.ndarray] = field(default_factory=dict)
    nodes: np.ndarray | None = None
    source: str = ""

    @property
    def n_elements(self) -> int:
        """Elements of the mesh."""
        return int(self.mesh.t.shape[1])

    @property
    def bounding_box(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) [m] of the mesh's points."""
        p = self.mesh.p
        return (float(p[0].min()), float(p[0].max()), float(p[1].min()), float(p[1].max()))

    def with_boundaries(self, boundaries: Mapping[str, np.ndarray]) -> MeshData:
        """A copy with ``boundaries`` (name → facet indices) added; a name already there
        is replaced."""
        merged = dict(self.boundaries)
        merged.update({k: np.unique(np.asarray(v, dtype=np.int64)) for k, v in boundaries.items()})
        return MeshData(self.mesh, self.element, merged, self.subdomains, self.nodes, self.source)


def make_basis(mesh_data: MeshData, gauss: int | None = None) -> Basis:
    """The vector basis of the mesh's element with ``gauss`` Gauss points per direction
    (quadrilaterals) or per triangle (1, 3, 6, 7, 12), None for the element's default
    (:data:`~granular_material.fem.boundary_value.biaxial.DEFAULT_GAUSS`: tri6 3 points,
    quad8 2 × 2)."""
    element = mesh_data.element
    triangle = element in TRIANGLES
    n = DEFAULT_GAUSS[element] if gauss is None else gauss
    if triangle and n not in TRIANGLE_RULES:
        raise ParameterError("gauss", "of a triangle must be one of "
                                      f"{', '.join(map(str, TRIANGLE_RULES))}, got {gauss!r}")
    if not triangle and (int(n) != n or not 1 <= n <= 10):
        raise ParameterError("gauss", f"must be an integer in [1, 10], got {gauss!r}")
    if n == 1:  # the centroid, by hand (scikit-fem's least rules have more points)
        _check_degenerate(mesh_data)
        centre, weight = (1 / 3, 0.5) if triangle else (0.5, 1.0)
        return Basis(mesh_data.mesh, element_of(element),
                     quadrature=(np.full((2, 1), centre), np.full(1, weight)))
    intorder = TRIANGLE_RULES[n] if triangle else 2 * int(n) - 1
    _check_degenerate(mesh_data)
    try:
        basis = Basis(mesh_data.mesh, element_of(element), intorder=intorder)
    except Exception as exc:  # scikit-fem raises a bare Exception for it
        if "Jacobian" not in str(exc):
            raise
        raise ParameterError("mesh", f"{mesh_data.source}: an element's Jacobian is zero at a "
                                     "Gauss point (a degenerate or folded element)") from None
    expected = n if triangle else int(n) ** 2
    if basis.X.shape[-1] != expected:
        raise RuntimeError(f"intorder {intorder} gave {basis.X.shape[-1]} points per element, "
                           f"not {expected}")
    return basis


def _graded(length: float, n: int, ratio: float) -> np.ndarray:
    """n + 1 coordinates over [0, length] whose element sizes grow geometrically so that the
    last is ``ratio`` times the first."""
    if n == 1 or ratio == 1.0:
        return np.linspace(0.0, length, n + 1)
    q = ratio ** (1.0 / (n - 1))
    sizes = q ** np.arange(n)
    x = np.concatenate([[0.0], np.cumsum(sizes)])
    return length * x / x[-1]


def rectangle_mesh(width: float, height: float, nx: int, ny: int, element: str = "quad4",
                   grading: tuple[float, float] | None = None,
                   origin: tuple[float, float] = (0.0, 0.0)) -> MeshData:
    """A structured mesh of [x0, x0 + width] × [y0, y0 + height] [m] (``origin`` = (x0, y0)),
    nx × ny rectangles (each cut into two triangles for tri3/tri6), with the four sides
    named ``left``, ``right``, ``bottom`` and ``top``.

    ``grading`` = (rx, ry): the ratio of the last element's size to the first's along x (left
    to right) and along y (bottom to top), sizes growing geometrically; ``None`` or 1 for
    uniform. E.g. a footing at the top left is refined by ``(4.0, 0.25)``.
    """
    element_of(conform("element", element, str))
    width, height = conform("width", width, float), conform("height", height, float)
    for name, value in (("width", width), ("height", height)):
        if not (math.isfinite(value) and value > 0):
            raise ParameterError(name, f"must be a positive length in m, got {value!r}")
    nx, ny = conform("nx", nx, int), conform("ny", ny, int)
    for name, value in (("nx", nx), ("ny", ny)):
        if value < 1:
            raise ParameterError(name, f"must be an integer >= 1, got {value!r}")
    grading = conform("grading", grading, tuple[float, float] | None)
    origin = conform("origin", origin, tuple[float, float])
    rx, ry = (1.0, 1.0) if grading is None else grading
    for value in (rx, ry):
        if not (math.isfinite(value) and value > 0):
            raise ParameterError("grading", f"ratios must be positive numbers, got {grading!r}")
    refusal = memory_refusal(float(min(nx * ny * _RECTANGLE_BYTES, 10**300)),
                             f"a mesh of {nx} x {ny} rectangles", available_memory())
    if refusal:
        raise ParameterError("nx" if nx >= ny else "ny", refusal)
    xs = origin[0] + _graded(width, int(nx), float(rx))
    ys = origin[1] + _graded(height, int(ny), float(ry))
    if element in TRIANGLES:
        mesh = MeshTri1.init_tensor(xs, ys)
    else:
        grid = MeshQuad1.init_tensor(xs, ys)
        mesh = MeshQuad1(grid.p, _counter_clockwise(grid.p, grid.t))
    tol = 1e-9 * max(width, height)
    x0, y0 = origin
    sides = {"left": lambda p: np.abs(p[0] - x0) < tol,
             "right": lambda p: np.abs(p[0] - x0 - width) < tol,
             "bottom": lambda p: np.abs(p[1] - y0) < tol,
             "top": lambda p: np.abs(p[1] - y0 - height) < tol}
    boundaries = {name: mesh.facets_satisfying(test, boundaries_only=True).astype(np.int64)
                  for name, test in sides.items()}
    return MeshData(mesh, element, boundaries, {}, np.arange(mesh.p.shape[1]),
                    f"rectangle {width} x {height} m, {nx} x {ny} {element}")


def _signed_areas(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Signed area [m²] of each polygon of corners ``t`` (k, nelems) (shoelace)."""
    x, y = p[0][t], p[1][t]
    x, y = x - x[:1], y - y[:1]  # from the first corner: exact however far the mesh lies
    return 0.5 * np.sum(x * np.roll(y, -1, axis=0) - np.roll(x, -1, axis=0) * y, axis=0)


def _counter_clockwise(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The corners ``t`` (3 | 4, nelems) with every clockwise element reversed."""
    t = t.copy()
    flip = _signed_areas(p, t) < 0
    t[1:, flip] = t[1:, flip][::-1]
    return t


def _check_straight(points: np.ndarray, cells: np.ndarray, kind: str, source: str) -> None:
    """ParameterError unless every midside node of ``cells`` (nelems, nodes) lies at its
    edge's midpoint and a quad9's centre node at the mean of its corners."""
    corners = 3 if kind.startswith("triangle") else 4
    if cells.shape[1] == corners:
        return
    x = points[cells]  # (nelems, nodes, 2)
    size = np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
    expected = [0.5 * (x[:, a] + x[:, b]) for a, b in _EDGES[corners]]
    if kind == "quad9":
        expected.append(x[:, :4].mean(axis=1))
    off = np.stack([np.linalg.norm(x[:, corners + k] - e, axis=1)
                    for k, e in enumerate(expected)], axis=1).max(axis=1)
    bad = np.flatnonzero(off > 1e-6 * size)
    if bad.size:
        raise ParameterError("mesh", f"{source}: {bad.size} {kind} elements (first: {bad[0]}) "
                                     "have a midside node off the midpoint of its edge: "
                                     "curved elements, or a node order other than gmsh's "
                                     "(corners, then the midsides of edges 01, 12, ...), are "
                                     "not supported")


def _check_listed_once(t: np.ndarray, source: str) -> None:
    """ParameterError naming the first element of corners ``t`` (k, nelems) whose corners are
    another's (an element listed twice would be integrated twice)."""
    order = np.sort(t, axis=0).T
    _, first, counts = np.unique(order, axis=0, return_index=True, return_counts=True)
    if np.any(counts > 1):
        twice = np.flatnonzero(~np.isin(np.arange(order.shape[0]), first))
        same = int(np.flatnonzero((order == order[twice[0]]).all(axis=1))[0])
        raise ParameterError("mesh", f"{source}: element {int(twice[0])} has the corners of "
                                     f"element {same} (listed twice; {twice.size} such "
                                     "elements): each element must be listed once")


def _check_degenerate(mesh_data: MeshData) -> None:
    """ParameterError naming the first element whose area is zero, or too small beside the
    mesh's mean element for a float Jacobian (below 1e-12 of it)."""
    mesh = mesh_data.mesh
    areas = np.abs(_signed_areas(mesh.p, mesh.t))
    mean = float(areas.mean()) if areas.size else 0.0
    thin = np.flatnonzero(~(areas > 1e-12 * mean))
    if thin.size:
        k = int(thin[0])
        raise ParameterError("mesh", f"{mesh_data.source}: {thin.size} degenerate elements "
                                     f"(first: element {k}, area {areas[k]:.3g} m² beside a "
                                     f"mean of {mean:.3g} m²): their Jacobian is zero or lost "
                                     "in rounding (use a milder grading, or elements of "
                                     "less disparate sizes)")


def _group_names(m: meshio.Mesh, dim: int) -> dict[int, str]:
    """gmsh physical tag → name for the groups of dimension ``dim`` ($PhysicalNames)."""
    names = {}
    for name, value in (m.field_data or {}).items():
        value = np.asarray(value).reshape(-1)
        if value.size >= 2 and int(value[1]) == dim:
            names[int(value[0])] = str(name)
    return names


def _grouped(m: meshio.Mesh, types: tuple[str, ...], dim: int) -> dict[str, list[np.ndarray]]:
    """name → the cells (rows of node indices) of ``types`` in each named group."""
    out: dict[str, list[np.ndarray]] = {}
    physical = m.cell_data.get("gmsh:physical")
    geometrical = m.cell_data.get("gmsh:geometrical")
    names = _group_names(m, dim)
    for i, block in enumerate(m.cells):
        if block.type not in types:
            continue
        data = np.asarray(block.data)
        if physical is not None:
            tags = np.asarray(physical[i]).reshape(-1)
            entities = (np.asarray(geometrical[i]).reshape(-1) if geometrical is not None
                        else np.zeros_like(tags))
            for tag in np.unique(tags):
                rows = tags == tag
                if tag != 0:
                    out.setdefault(names.get(int(tag), f"group-{tag}"), []).append(data[rows])
                elif dim == 1:  # in no physical group: its geometric entity names it
                    for entity in np.unique(entities[rows]):
                        pick = rows & (entities == entity)
                        out.setdefault(f"entity-{entity}", []).append(data[pick])
        for name, sets in (m.cell_sets or {}).items():
            if name.startswith("gmsh:") or i >= len(sets) or sets[i] is None:
                continue
            index = np.asarray(sets[i], dtype=np.int64).reshape(-1)
            if index.size:
                out.setdefault(str(name), []).append(data[index])
    return out


def read_mesh(path: str | Path) -> MeshData:
    """Read a two-dimensional mesh file through meshio (gmsh ``.msh`` v2.2 and v4 with their
    physical groups, or any format meshio reads, with its cell sets): one element type among
    tri3, tri6, quad4, quad8, quad9 (:data:`MESHIO_ELEMENTS`), straight-sided; coordinates [m],
    z ignored. ParameterError naming the file for what cannot be used."""
    source = str(path)
    if Path(path).is_dir():
        raise ParameterError("mesh", f"{source} is a folder, not a mesh file")
    if Path(path).is_file() and Path(path).stat().st_size == 0:
        raise ParameterError("mesh", f"{source} is empty, not a mesh file")
    try:
        m = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio raises many types for an unreadable
        # file, and exits (SystemExit) when every reader of its suffix refused its content
        suffix = Path(path).suffix or "(none)"
        why = (str(exc) if str(exc) not in ("", "1") else
               f"its content is no mesh that meshio's readers of its suffix {suffix} take "
               "(a damaged or truncated file, or another format under that suffix)")
        raise ParameterError("mesh", f"{source}: meshio cannot read it: {why}") from None
    kinds = sorted({b.type for b in m.cells if b.type in MESHIO_ELEMENTS})
    others = sorted({b.type for b in m.cells if b.type not in MESHIO_ELEMENTS
                     and b.type not in _LINES and b.type != "vertex"})
    if len(kinds) != 1 or others:
        raise ParameterError("mesh", f"{source}: needs exactly one element type among "
                                     f"{', '.join(MESHIO_ELEMENTS)}; it has "
                                     f"{', '.join(kinds + others) or 'none'}")
    kind = kinds[0]
    points = np.asarray(m.points, dtype=np.float64)[:, :2]
    cells = np.concatenate([np.asarray(b.data, dtype=np.int64)
                            for b in m.cells if b.type == kind])
    if cells.size and (cells.min() < 0 or cells.max() >= len(points)):
        raise ParameterError("mesh", f"{source}: its elements name nodes up to {cells.max()} "
                                     f"(from {cells.min()}); it has {len(points)}")
    if not np.isfinite(points[np.unique(cells)]).all():
        raise ParameterError("mesh", f"{source}: its elements' nodes have coordinates that "
                                     "are not finite (NaN or infinite)")
    _check_straight(points, cells, kind, source)
    corners = 3 if kind.startswith("triangle") else 4
    used, inverse = np.unique(cells[:, :corners], return_inverse=True)
    t = inverse.reshape(-1, corners).T
    p = np.ascontiguousarray(points[used].T)
    t = _counter_clockwise(p, t)
    if np.any(np.abs(_signed_areas(p, t)) == 0.0):
        raise ParameterError("mesh", f"{source}: has elements of zero area")
    _check_listed_once(t, source)
    mesh = (MeshTri1 if corners == 3 else MeshQuad1)(p, np.ascontiguousarray(t))
    local = np.full(points.shape[0], -1, dtype=np.int64)
    local[used] = np.arange(used.size)
    boundaries = {name: _facets_of(mesh, local, np.concatenate(rows), name, source)
                  for name, rows in _grouped(m, _LINES, 1).items()}
    subdomains = {name: _elements_of(m, kind, rows, cells)
                  for name, rows in _grouped(m, (kind,), 2).items()}
    return MeshData(mesh, MESHIO_ELEMENTS[kind], boundaries, subdomains, used, source)


def _facets_of(mesh: Mesh, local: np.ndarray, lines: np.ndarray, name: str,
               source: str) -> np.ndarray:
    """Facet indices of ``mesh`` whose end nodes are those of the file's ``lines`` (rows of
    file node indices: two ends, then any midside node)."""
    ends = local[lines[:, :2]]
    if np.any(ends < 0):
        raise ParameterError("mesh", f"{source}: boundary {name!r} has nodes no element uses")
    facets = np.sort(mesh.facets, axis=0)
    key = {(int(a), int(b)): k for k, (a, b) in enumerate(facets.T)}
    found = [key.get((int(min(a, b)), int(max(a, b))), -1) for a, b in ends]
    missing = sum(1 for f in found if f < 0)
    if missing:
        raise ParameterError("mesh", f"{source}: {missing} lines of boundary {name!r} are not "
                                     "edges of its elements")
    return np.unique(np.asarray(found, dtype=np.int64))


def _elements_of(m: meshio.Mesh, kind: str, rows: list[np.ndarray],
                 cells: np.ndarray) -> np.ndarray:
    """Element indices (in the file's order of ``kind`` cells, which the mesh keeps) of the
    cells in ``rows``."""
    key = {tuple(c): k for k, c in enumerate(cells.tolist())}
    return np.unique(np.asarray([key[tuple(r)] for r in np.concatenate(rows).tolist()],
                                dtype=np.int64))
