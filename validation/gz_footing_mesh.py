"""The coarse tri6 mesh of Guo & Zhao's footing (gmsh 2.2 through meshio) and their footing
force computed from any code's Gauss stresses.

Their ``footing.py`` projects the Gauss stresses onto the nodes with escript's default
``Projector`` (reduced order: the linear shape functions of the corner nodes; lumped mass)
and integrates the traction σ·n of that field over the footing base
(:func:`footing_traction_force`). The force the supports put on the footing's nodes, the
nodal reaction our code reports, is the internal force ∫ σ ∇N over the elements at the base
(:func:`footing_nodal_reaction`), here from either code's stresses.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["HALF_WIDTH", "SETTLEMENT_PER_STEP", "SURCHARGE", "X_LINES", "Y_LINES",
           "FootingMesh", "footing_mesh", "footing_nodal_reaction", "footing_traction_force",
           "lumped_nodal_stress", "match_elements", "read_gmsh22", "write_gmsh22"]

#: their footing's half-width B [m]
HALF_WIDTH = 0.05
#: settlement a load step [m] and surcharge [Pa] of their script
SETTLEMENT_PER_STEP = 0.25e-3
SURCHARGE = 20e3
#: grid lines of the coarse mesh [m]: 8 × 5 cells, a node at the footing's edge x = B
X_LINES = (0.0, 0.025, 0.05, 0.075, 0.1, 0.15, 0.25, 0.4, 0.6)
Y_LINES = (-0.4, -0.2, -0.1, -0.05, -0.025, 0.0)


@dataclass(frozen=True)
class FootingMesh:
    """A tri6 mesh of the half domain: ``points`` (n, 2) [m]; ``triangles`` (ne, 6) node
    indices in gmsh order (corners counter-clockwise, then the midsides of 0-1, 1-2, 2-0);
    ``lines`` (nb, 3) the boundary's line3 edges (ends, then midside)."""

    points: np.ndarray
    triangles: np.ndarray
    lines: np.ndarray

    @property
    def corners(self) -> np.ndarray:
        """The (ne, 3) corner nodes of every triangle."""
        return self.triangles[:, :3]


def footing_mesh(x_lines: tuple[float, ...] = X_LINES,
                 y_lines: tuple[float, ...] = Y_LINES) -> FootingMesh:
    """The rectangle spanned by the increasing grid lines ``x_lines`` × ``y_lines`` [m], each
    cell cut into two tri6 along its diagonal from lower left to upper right."""
    xs, ys = np.asarray(x_lines, float), np.asarray(y_lines, float)
    if xs.size < 2 or ys.size < 2 or np.any(np.diff(xs) <= 0) or np.any(np.diff(ys) <= 0):
        raise ValueError("grid lines must be increasing, at least two each way")
    # a (2 nx + 1) × (2 ny + 1) grid of nodes holds the corners and every midside
    gx = np.concatenate([np.ravel(np.column_stack([xs[:-1], 0.5 * (xs[:-1] + xs[1:])])),
                         xs[-1:]])
    gy = np.concatenate([np.ravel(np.column_stack([ys[:-1], 0.5 * (ys[:-1] + ys[1:])])),
                         ys[-1:]])
    nx, ny = gx.size, gy.size
    index = np.full((nx, ny), -1)
    used = np.zeros((nx, ny), dtype=bool)
    used[::2, :] = True
    used[:, ::2] = True
    used[1::2, 1::2] = True  # the cell's diagonal midside
    index[used] = np.arange(int(used.sum()))
    ii, jj = np.nonzero(used)
    order = np.argsort(index[used])
    points = np.column_stack([gx[ii[order]], gy[jj[order]]])
    tris = []
    for i in range(0, nx - 1, 2):
        for j in range(0, ny - 1, 2):
            a, b, c, d = (i, j), (i + 2, j), (i + 2, j + 2), (i, j + 2)
            for p, q, r in ((a, b, c), (a, c, d)):
                mids = [((s[0] + t[0]) // 2, (s[1] + t[1]) // 2)
                        for s, t in ((p, q), (q, r), (r, p))]
                tris.append([index[n] for n in (p, q, r, *mids)])
    lines = []
    for side in ([(i, 0) for i in range(nx)], [(nx - 1, j) for j in range(ny)],
                 [(i, ny - 1) for i in range(nx - 1, -1, -1)],
                 [(0, j) for j in range(ny - 1, -1, -1)]):
        for k in range(0, len(side) - 1, 2):
            lines.append([index[side[k]], index[side[k + 2]], index[side[k + 1]]])
    return FootingMesh(points, np.asarray(tris, dtype=np.int64), np.asarray(lines, np.int64))


def write_gmsh22(mesh: FootingMesh, path: str | Path) -> Path:
    """Write ``mesh`` as an ASCII gmsh 2.2 file (triangle6 in physical group 1, the boundary's
    line3 in group 2), the format escript's ``ReadGmsh`` and ours read."""
    import meshio

    path = Path(path)
    nl, nt = len(mesh.lines), len(mesh.triangles)
    out = meshio.Mesh(
        np.column_stack([mesh.points, np.zeros(len(mesh.points))]),
        [("line3", mesh.lines), ("triangle6", mesh.triangles)],
        cell_data={"gmsh:physical": [np.full(nl, 2), np.full(nt, 1)],
                   "gmsh:geometrical": [np.full(nl, 2), np.full(nt, 1)]})
    meshio.write(path, out, file_format="gmsh22", binary=False)
    return path


def read_gmsh22(path: str | Path) -> FootingMesh:
    """The :class:`FootingMesh` of a file written by :func:`write_gmsh22`."""
    import meshio

    m = meshio.read(path)
    return FootingMesh(np.asarray(m.points[:, :2], float),
                       np.asarray(m.cells_dict["triangle6"], np.int64),
                       np.asarray(m.cells_dict["line3"], np.int64))


def lumped_nodal_stress(points: np.ndarray, corners: np.ndarray, gauss_xy: np.ndarray,
                        stress: np.ndarray) -> np.ndarray:
    """Gauss stresses [Pa] (ne·nq, 2, 2) projected onto the corner nodes as escript's default
    ``Projector`` does (linear shape functions, lumped mass): σ_a = Σ λ_a(q) w_q σ_q /
    Σ λ_a(q) w_q over the points q of the triangles at node a, w_q = area/nq (the equal
    weights of both codes' 3-point rules), λ the barycentric coordinates of the point at
    ``gauss_xy`` (ne·nq, 2) [m] in its triangle (point p lies in triangle p // nq)."""
    stress = np.asarray(stress, float).reshape(-1, 2, 2)
    ne = len(corners)
    nq = len(stress) // ne
    if nq * ne != len(stress) or len(gauss_xy) != len(stress):
        raise ValueError(f"{len(stress)} stresses and {len(gauss_xy)} points for {ne} "
                         "triangles")
    xy = points[corners]  # (ne, 3, 2)
    t = np.stack([xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]], axis=2)  # (ne, 2, 2)
    area = 0.5 * np.abs(np.linalg.det(t))
    rel = np.asarray(gauss_xy, float) - np.repeat(xy[:, 0], nq, axis=0)
    local = np.linalg.solve(np.repeat(t, nq, axis=0), rel[:, :, None])[:, :, 0]
    lam = np.column_stack([1.0 - local.sum(axis=1), local])  # (ne·nq, 3)
    if lam.min() < -1e-9:
        bad = int(np.argmin(lam.min(axis=1)))
        raise ValueError(f"Gauss point {bad} at {gauss_xy[bad]} lies outside triangle "
                         f"{bad // nq} (points must be ordered element by element)")
    w = lam * np.repeat(area / nq, nq)[:, None]
    nodes = np.repeat(corners, nq, axis=0)
    mass = np.zeros(len(points))
    rhs = np.zeros((len(points), 2, 2))
    np.add.at(mass, nodes.ravel(), w.ravel())
    np.add.at(rhs, nodes.ravel(), (w[:, :, None, None] * stress[:, None]).reshape(-1, 2, 2))
    out = np.full((len(points), 2, 2), np.nan)
    has = mass > 0
    out[has] = rhs[has] / mass[has, None, None]
    return out


def match_elements(mesh: FootingMesh, gauss_xy: np.ndarray, nq: int = 3) -> np.ndarray:
    """The triangle of ``mesh`` of each element of a code's Gauss points ``gauss_xy``
    (ne·nq, 2) [m], ordered element by element: the triangle whose centroid is nearest the
    centroid of the element's points (both codes' rules are symmetric, so the two agree).
    ValueError unless the match is one to one."""
    centres = np.asarray(gauss_xy, float).reshape(-1, nq, 2).mean(axis=1)
    ours = mesh.points[mesh.corners].mean(axis=1)
    dist = np.linalg.norm(centres[:, None] - ours[None], axis=2)
    match = dist.argmin(axis=1)
    if len(match) != len(ours) or len(set(match.tolist())) != len(match) \
            or dist.min(axis=1).max() > 1e-6:
        raise ValueError("the Gauss points do not match the mesh's triangles one to one")
    return match


def footing_traction_force(mesh: FootingMesh, gauss_xy: np.ndarray, stress: np.ndarray,
                           half_width: float = HALF_WIDTH, nq: int = 3,
                           ) -> tuple[np.ndarray, float]:
    """Their footing force [N/m] (2,): the traction σ·n (n = (0, 1), the top's outward
    normal) of the lumped nodal stress (:func:`lumped_nodal_stress`), linear along each edge,
    integrated over the top edges with x ≤ ``half_width`` [m]; and the base's length [m].
    ``gauss_xy`` (ne·nq, 2) [m] and ``stress`` (ne·nq, 2, 2) [Pa] element by element in
    any element order (:func:`match_elements`). Reference geometry (theirs integrates on
    the updated mesh)."""
    match = match_elements(mesh, gauss_xy, nq)
    order = np.argsort(match)
    xy = np.asarray(gauss_xy, float).reshape(-1, nq, 2)[order].reshape(-1, 2)
    sig = np.asarray(stress, float).reshape(-1, nq, 2, 2)[order].reshape(-1, 2, 2)
    nodal = lumped_nodal_stress(mesh.points, mesh.corners, xy, sig)
    p = mesh.points
    top = p[:, 1].max()
    force, length = np.zeros(2), 0.0
    for a, b, _ in mesh.lines:
        ends = p[[a, b]]
        if np.all(np.abs(ends[:, 1] - top) < 1e-9) and np.all(ends[:, 0] <= half_width + 1e-9):
            span = float(abs(ends[1, 0] - ends[0, 0]))
            force += span * 0.5 * (nodal[a] + nodal[b]) @ np.array([0.0, 1.0])
            length += span
    return force, length


def _tri6_gradients(points: np.ndarray, nodes: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """∇N [1/m] (nq, 6, 2) of one tri6 (``nodes`` in gmsh order) at barycentric ``lam``
    (nq, 3); straight sides (the corners' affine map)."""
    l1, l2, l3 = lam.T
    z = np.zeros_like(l1)
    # ∂N/∂λ (nq, 6, 3): N = λi(2λi − 1) at the corners, 4 λi λj at the midsides
    d = np.stack([np.stack([4 * l1 - 1, z, z], 1), np.stack([z, 4 * l2 - 1, z], 1),
                  np.stack([z, z, 4 * l3 - 1], 1), np.stack([4 * l2, 4 * l1, z], 1),
                  np.stack([z, 4 * l3, 4 * l2], 1), np.stack([4 * l3, z, 4 * l1], 1)], 1)
    local = np.stack([d[:, :, 1] - d[:, :, 0], d[:, :, 2] - d[:, :, 0]], axis=2)
    xy = points[nodes[:3]]
    jac = np.column_stack([xy[1] - xy[0], xy[2] - xy[0]])
    return local @ np.linalg.inv(jac)


def footing_nodal_reaction(mesh: FootingMesh, gauss_xy: np.ndarray, stress: np.ndarray,
                           surcharge: float = 0.0, half_width: float = HALF_WIDTH,
                           nq: int = 3) -> np.ndarray:
    """The nodal reaction [N/m] (2,) of the footing base (the top nodes with x ≤
    ``half_width``): Σ_a (∫ σ ∇N_a − f_ext,a) over those nodes, the internal force with the
    code's own Gauss points ``gauss_xy`` (ne·nq, 2) [m] (equal weights area/nq) less the
    consistent share of the ``surcharge`` [Pa] (compression positive) on the top edges
    beyond the base that falls on the base's edge node (what our code reports as
    ``footing_force``). Its x component holds the left roller's reaction at the corner node
    too. Reference geometry; elements in any order (:func:`match_elements`)."""
    match = match_elements(mesh, gauss_xy, nq)
    xy = np.asarray(gauss_xy, float).reshape(-1, nq, 2)
    sig = np.asarray(stress, float).reshape(-1, nq, 2, 2)
    p = mesh.points
    base = np.abs(p[:, 1] - p[:, 1].max()) < 1e-9
    base &= p[:, 0] <= half_width + 1e-9
    force = np.zeros(2)
    for k, tri in enumerate(match):
        nodes = mesh.triangles[tri]
        on = base[nodes]
        if not on.any():
            continue
        corners = p[nodes[:3]]
        jac = np.column_stack([corners[1] - corners[0], corners[2] - corners[0]])
        local = np.linalg.solve(jac, (xy[k] - corners[0]).T).T
        lam = np.column_stack([1.0 - local.sum(axis=1), local])
        grads = _tri6_gradients(p, nodes, lam)  # (nq, 6, 2)
        w = 0.5 * abs(np.linalg.det(jac)) / nq
        force += w * np.einsum("qij,qaj->i", sig[k], grads[:, on])
    for line in mesh.lines:  # the surcharge's load on the base's nodes: ∫ N ds (−q n)
        ends = p[line[:2]]
        if np.all(np.abs(ends[:, 1] - p[:, 1].max()) < 1e-9) and \
                np.all(ends[:, 0] >= half_width - 1e-9):
            span = float(np.linalg.norm(ends[1] - ends[0]))
            share = np.array([span / 6.0, span / 6.0, 2.0 * span / 3.0])[base[line]].sum()
            force[1] += surcharge * share
    return force
