"""Conditions on named boundaries, and the problem they make with a mesh.

A boundary-value problem is a mesh with named boundaries
(:mod:`granular_material.fem.boundary_value.meshes`,
:mod:`granular_material.fem.boundary_value.boundaries`) and a list of conditions, each on one named
boundary (gravity on the whole body):

- :class:`Fixed`: u_x = u_y = 0 at every node of the boundary;
- :class:`Roller`: one component held at 0, the other free;
- :class:`Displacement`: one component prescribed, λ · ``end`` [m] at load factor λ;
- :class:`RigidBody`: a footing or a wall moved as one by λ · ``displacement``; rough: both
  components of every node prescribed; smooth: only the component along the motion (which
  must then be along x or y), the other free;
- :class:`Pressure`: a pressure [Pa], compression positive, normal to the boundary,
  constant or linear in λ from ``value`` to ``end``; under finite strain it follows the
  boundary's current length and normal (Nanson's formula, the ``follower`` of the
  :class:`~granular_material.fem.boundary_value.loading.Loading`); consistent nodal forces with the
  element's own shape functions;
- :class:`Gravity`: the body force −γ e_y [N/m³] on the reference configuration (per
  reference volume, so it needs no update under finite strain).

Gravity and pressures are constant in λ (applied in full from step 0) unless given an
``end``: then they go linearly from their value at λ = 0 to ``end`` at λ = 1 (a surcharge
raised, a flexible footing loaded by its pressure, gravity switched on or increased: load
control, which cannot pass a collapse load); prescribed displacements grow linearly with λ.
Conflicts: where two conditions prescribe the same dof, **the later in the list wins** (a
wall listed after the fixed base it stands on owns their shared node); equal values are no
conflict. A problem whose prescribed dofs leave a rigid-body motion free (a translation in x
or y, or a rotation) is refused, a :class:`~granular_material.errors.ParameterError` naming
it; so is one with a part of the mesh (elements joined by their facets, unconnected to the
rest) that the conditions leave free, the message naming the part.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from skfem import Basis, FacetBasis, LinearForm

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.biaxial import (
    ELEMENTS,
    confining_traction,
    follower_traction,
)
from granular_material.fem.boundary_value.loading import Loading
from granular_material.fem.boundary_value.meshes import MeshData, make_basis
from granular_material.fem.boundary_value.reactions import BoundaryDofs, boundary_dofs
from granular_material.fem.layout import to_points
from granular_material.typed_fields import conform_fields

__all__ = ["Condition", "Displacement", "Fixed", "Gravity", "Pressure", "Problem",
           "RigidBody", "Roller", "build_problem"]


def _component(value: int) -> int:
    if value not in (0, 1):
        raise ParameterError("component", f"must be 0 (x) or 1 (y), got {value!r}")
    return int(value)


def _length(name: str, value: float) -> float:
    if not math.isfinite(value):
        raise ParameterError(name, f"must be a finite displacement in m, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Fixed:
    """u_x = u_y = 0 on ``boundary``."""

    boundary: str

    def __post_init__(self) -> None:
        conform_fields(self)


@dataclass(frozen=True)
class Roller:
    """Displacement ``component`` (0: x, 1: y) held at 0 on ``boundary``; the other free."""

    boundary: str
    component: int

    def __post_init__(self) -> None:
        conform_fields(self)
        _component(self.component)


@dataclass(frozen=True)
class Displacement:
    """Displacement ``component`` (0: x, 1: y) of ``boundary`` prescribed: λ · ``end`` [m]."""

    boundary: str
    component: int
    end: float

    def __post_init__(self) -> None:
        conform_fields(self)
        _component(self.component)
        _length("end", self.end)


@dataclass(frozen=True)
class RigidBody:
    """``boundary`` moved as one rigid body by λ · ``displacement`` = (d_x, d_y) [m].

    Rough: both components of every node prescribed. Smooth: only the component along the
    motion, which must then be along x or y (one of d_x, d_y zero, the other not).
    """

    boundary: str
    displacement: tuple[float, float]
    rough: bool = True

    def __post_init__(self) -> None:
        conform_fields(self)  # a pair of finite numbers, rough true or false
        d = tuple(_length("displacement", float(v)) for v in self.displacement)
        if len(d) != 2:
            raise ParameterError("displacement", f"must be (dx, dy) [m], got "
                                                 f"{self.displacement!r}")
        object.__setattr__(self, "displacement", d)
        if not self.rough and (d[0] != 0.0) == (d[1] != 0.0):
            raise ParameterError("displacement", "of a smooth rigid body must be along x or "
                                                 f"y (one component nonzero), got {d!r}")

    @property
    def components(self) -> tuple[int, ...]:
        """The components it prescribes."""
        if self.rough:
            return (0, 1)
        return (0,) if self.displacement[0] != 0.0 else (1,)


@dataclass(frozen=True)
class Pressure:
    """A pressure [Pa], compression positive, normal to ``boundary`` (traction t = −p n, n
    the outward normal), on its current length under finite strain: ``value`` at λ = 0,
    linear in λ to ``end`` at λ = 1 (None: ``value`` throughout)."""

    boundary: str
    value: float
    end: float | None = None

    def __post_init__(self) -> None:
        conform_fields(self)  # finite numbers, end or none

    @property
    def at_end(self) -> float:
        """The pressure [Pa] at λ = 1."""
        return self.value if self.end is None else self.end


@dataclass(frozen=True)
class Gravity:
    """Body force −γ e_y over the body: unit weight γ = ``unit_weight`` [N/m³] (>= 0) at
    λ = 0, linear in λ to ``end`` at λ = 1 (None: ``unit_weight`` throughout; gravity
    switched on, or increased); ``elements``: the element indices it acts on (a region's
    own weight; None: the whole body). Gravities add up where they overlap."""

    unit_weight: float
    end: float | None = None
    elements: np.ndarray | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        conform_fields(self, skip=("elements",))
        for name, weight in (("unit_weight", self.unit_weight), ("end", self.end)):
            if weight is not None and not weight >= 0:
                raise ParameterError(name, f"must be >= 0 N/m³, got {weight!r}")
        if self.elements is not None:
            index = np.asarray(self.elements)
            if index.dtype.kind not in "iu" or index.ndim != 1 or index.size == 0 \
                    or index.min() < 0:
                raise ParameterError("elements", "must be a 1-D array of element indices "
                                                 f"(>= 0), got {self.elements!r}"[:200])
            index = np.unique(index.astype(np.int64))
            index.setflags(write=False)
            object.__setattr__(self, "elements", index)

    @property
    def at_end(self) -> float:
        """The unit weight [N/m³] at λ = 1."""
        return self.unit_weight if self.end is None else self.end


#: any of the conditions
Condition = Fixed | Roller | Displacement | RigidBody | Pressure | Gravity


@LinearForm
def _body_force(v, w):
    """∫ −γ v_y dV (``w.gamma`` in N/m³)."""
    return -w.gamma * v[1]


@dataclass(frozen=True)
class Problem:
    """The assembled pieces of a boundary-value problem.

    Attributes:
        mesh_data: the mesh and its named boundaries.
        conditions: the conditions, in the order given.
        basis: vector basis of the element, with the Gauss rule of the problem.
        loading: prescribed displacements and forces against the load factor.
        weights: integration weight (area [m²]) of every Gauss point, shape (n,).
        points: coordinates [m] of every Gauss point (reference), shape (n, 2).
        boundaries: name → the dofs of each named boundary of the mesh.
    """

    mesh_data: MeshData
    conditions: tuple[Condition, ...]
    basis: Basis
    loading: Loading
    weights: np.ndarray
    points: np.ndarray
    boundaries: dict[str, BoundaryDofs] = field(default_factory=dict)

    @property
    def loaded_boundaries(self) -> list[str]:
        """The boundaries that carry a condition, in the order of the conditions."""
        names = [c.boundary for c in self.conditions if not isinstance(c, Gravity)]
        return list(dict.fromkeys(names))

    def _dofs(self, name: str) -> BoundaryDofs:
        if name not in self.boundaries:
            raise ParameterError("boundary", f"{name!r} is not a boundary of the mesh (it has "
                                             f"{', '.join(sorted(self.boundaries)) or 'none'})")
        return self.boundaries[name]

    def boundary_force(self, name: str, nodal: np.ndarray) -> tuple[float, float]:
        """(F_x, F_y) [N/m] of the nodal vector ``nodal`` summed over the nodes of boundary
        ``name``. Of the solver's ``reaction`` (f_int − f_ext) it is the force the support
        exerts *on the body* there: a footing pressed into the ground gets F_y < 0, the
        base of a column under load F_y > 0 (the bearing force on the footing is −F)."""
        return self._dofs(name).force(nodal)

    def boundary_displacement(self, name: str, u: np.ndarray) -> tuple[float, float]:
        """Mean (u_x, u_y) [m] of the nodes of boundary ``name``."""
        return self._dofs(name).displacement(u)

    def force_tolerance(self, stress: float) -> float:
        """‖R‖₂ [N/m] that a stress error of ``stress`` [Pa] at every Gauss point leaves:
        τ · h · √n_free, h = √(area / elements) (as the biaxial problem's)."""
        h = math.sqrt(float(self.weights.sum()) / self.mesh_data.n_elements)
        n_free = self.basis.N - self.loading.dirichlet_dofs.size
        return float(stress * h * math.sqrt(n_free))

    def nodes(self) -> tuple[np.ndarray, np.ndarray, str, np.ndarray]:
        """Every node (midside and centre ones included), for output: (coordinates [m]
        (k, 2), connectivity in the VTK/meshio order, the meshio cell type, the (u_x, u_y)
        dofs of every node (2, k))."""
        element = self.mesh_data.element
        basis = self.basis
        if basis.facet_dofs.size == 0 and basis.interior_dofs.size == 0:
            kind = "triangle" if element == "tri3" else "quad"
            return basis.mesh.p.T, basis.mesh.t.T, kind, basis.nodal_dofs
        scalar = Basis(basis.mesh, ELEMENTS[element](), quadrature=basis.quadrature)
        k = np.arange(scalar.N)
        kind = {6: "triangle6", 8: "quad8", 9: "quad9"}[scalar.element_dofs.shape[0]]
        return scalar.doflocs.T, scalar.element_dofs.T, kind, np.vstack([2 * k, 2 * k + 1])


def _prescribed(conditions: Sequence[Condition], dofs: dict[str, BoundaryDofs],
                ) -> dict[int, tuple[float, int]]:
    """dof → (value at λ = 1 [m], component) of every prescribed dof, the later condition
    winning."""
    out: dict[int, tuple[float, int]] = {}
    for c in conditions:
        if isinstance(c, Fixed):
            settings = [(0, 0.0), (1, 0.0)]
        elif isinstance(c, Roller):
            settings = [(c.component, 0.0)]
        elif isinstance(c, Displacement):
            settings = [(c.component, c.end)]
        elif isinstance(c, RigidBody):
            settings = [(k, c.displacement[k]) for k in c.components]
        else:
            continue
        for component, value in settings:
            for dof in dofs[c.boundary].component(component):
                out[int(dof)] = (value, component)
    return out


def _parts(basis: Basis) -> list[np.ndarray]:
    """The elements of each connected part of the mesh (elements joined by a shared facet),
    largest first."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    t2f = basis.mesh.t2f  # (facets per element, nelems)
    n_el = t2f.shape[1]
    elements = np.repeat(np.arange(n_el), t2f.shape[0])
    graph = coo_matrix((np.ones(elements.size), (elements, n_el + t2f.T.ravel())),
                       shape=(n_el + basis.mesh.facets.shape[1],) * 2)
    _, labels = connected_components(graph, directed=False)
    labels = labels[:n_el]
    parts = [np.flatnonzero(labels == k) for k in np.unique(labels)]
    return sorted(parts, key=lambda part: -part.size)


def _check_each_part(basis: Basis, prescribed: dict[int, tuple[float, int]]) -> None:
    """ParameterError naming the first connected part of the mesh that the prescribed dofs
    leave free to move as a rigid body (a part held by nothing: a singular system)."""
    parts = _parts(basis)
    if len(parts) == 1:
        _check_rigid_modes(basis, prescribed)
        return
    p = basis.mesh.p
    for number, elements in enumerate(parts, start=1):
        dofs = np.unique(basis.element_dofs[:, elements])
        held = {int(d): prescribed[int(d)] for d in dofs if int(d) in prescribed}
        try:
            _check_rigid_modes(basis, held, dofs)
        except ParameterError as exc:
            nodes = np.unique(basis.mesh.t[:, elements])
            lo, hi = p[:, nodes].min(axis=1), p[:, nodes].max(axis=1)
            raise ParameterError("conditions", f"of part {number} of the mesh's {len(parts)} "
                                               f"unconnected parts ({elements.size} elements, "
                                               f"x {lo[0]:.4g} to {hi[0]:.4g} m, y {lo[1]:.4g} "
                                               f"to {hi[1]:.4g} m; first element "
                                               f"{int(elements[0])}) {exc.message}") from None


def _check_rigid_modes(basis: Basis, prescribed: dict[int, tuple[float, int]],
                       within: np.ndarray | None = None) -> None:
    """ParameterError when the prescribed dofs leave a translation or a rotation free (of
    the body, or of the part whose dofs are ``within``)."""
    if not prescribed:
        raise ParameterError("conditions", "prescribe no displacement: the body is free to "
                                           "move as a rigid body (add a Fixed or a Roller)")
    dofs = np.fromiter(prescribed, dtype=np.int64)
    comps = np.array([prescribed[int(d)][1] for d in dofs])
    for k, name in ((0, "u_x"), (1, "u_y")):
        if not np.any(comps == k):
            raise ParameterError("conditions", f"hold no {name} anywhere: the body is free to "
                                               f"translate in {'xy'[k]}")
    x = basis.doflocs[:, dofs]
    region = basis.doflocs[:, within] if within is not None else basis.mesh.p
    centre = region.mean(axis=1)
    size = float(np.ptp(region, axis=1).max())
    rows = np.zeros((dofs.size, 3))
    rows[comps == 0, 0] = 1.0
    rows[comps == 1, 1] = 1.0
    rows[comps == 0, 2] = -(x[1, comps == 0] - centre[1]) / size
    rows[comps == 1, 2] = (x[0, comps == 1] - centre[0]) / size
    if np.linalg.matrix_rank(rows, tol=1e-9 * math.sqrt(dofs.size)) < 3:
        raise ParameterError("conditions", "leave the body free to rotate (the prescribed "
                                           "components hold no rotation: e.g. every held u_x "
                                           "on one horizontal line and every held u_y at one "
                                           "point)")


def _follower(body: np.ndarray, pressures: list[tuple[FacetBasis, float]],
              ) -> Callable[[np.ndarray], np.ndarray]:
    """The nodal forces [N/m] of ``body`` and of each pressure [Pa] on its facets, on the
    configuration displaced by u [m]."""
    def on_current_boundary(u: np.ndarray) -> np.ndarray:
        out = body.copy()
        for fb, p in pressures:
            out += follower_traction.assemble(fb, p=p, u=fb.interpolate(u))
        return out
    return on_current_boundary


def _external_loads(mesh_data: MeshData, basis: Basis, conditions: Sequence[Condition],
                    ) -> tuple[np.ndarray, np.ndarray, Callable | None, Callable | None]:
    """The nodal forces [N/m] of gravity and the pressures at λ = 0 and λ = 1, and the
    followers of both (None where there is no pressure; the end one None where nothing
    changes in λ)."""
    mesh = mesh_data.mesh
    degree = max(int(getattr(basis.elem, "maxdeg", 1)), 1)
    gravities = [c for c in conditions if isinstance(c, Gravity)]
    if all(c.elements is None for c in gravities):  # one γ over the whole body
        weights: tuple[Any, Any] = (sum(c.unit_weight for c in gravities),
                                    sum(c.at_end for c in gravities))
        exact = Basis(mesh, basis.elem, intorder=2 * degree) if any(weights) else None
        bodies = [_body_force.assemble(exact, gamma=w) if w else np.zeros(basis.N)
                  for w in weights]
    else:  # γ by element (the regions' own weights)
        per_element = np.zeros((2, mesh.t.shape[1]))
        for c in gravities:
            if c.elements is not None and c.elements.max() >= mesh.t.shape[1]:
                raise ParameterError("elements", f"a Gravity names element "
                                                 f"{int(c.elements.max())}; the mesh has "
                                                 f"{mesh.t.shape[1]}")
            where = slice(None) if c.elements is None else c.elements
            per_element[0, where] += c.unit_weight
            per_element[1, where] += c.at_end
        exact = Basis(mesh, basis.elem, intorder=2 * degree)
        nqp = exact.X.shape[-1]
        bodies = [_body_force.assemble(exact, gamma=np.repeat(g[:, None], nqp, axis=1))
                  if g.any() else np.zeros(basis.N) for g in per_element]
        same = bool(np.array_equal(per_element[0], per_element[1]))
        weights = (0.0, 0.0) if same else (0.0, 1.0)  # whether γ changes with λ
    force_start, force_end = bodies[0].copy(), bodies[1].copy()
    pressures: list[tuple[FacetBasis, float, float]] = []
    outer = set(mesh.boundary_facets().tolist())
    for c in conditions:
        if not isinstance(c, Pressure):
            continue
        facets = mesh_data.boundaries[c.boundary]
        if not set(facets.tolist()) <= outer:
            raise ParameterError("boundary", f"{c.boundary!r} of a Pressure has facets inside "
                                             "the body: a pressure acts on the boundary only")
        fb = FacetBasis(mesh, basis.elem, facets=facets, intorder=2 * degree + 1)
        pressures.append((fb, c.value, c.at_end))
        force_start += confining_traction.assemble(fb, p=c.value)
        force_end += confining_traction.assemble(fb, p=c.at_end)
    if not pressures:
        return force_start, force_end, None, None
    follower = _follower(bodies[0], [(fb, start) for fb, start, _ in pressures])
    if weights[0] == weights[1] and all(end == start for _, start, end in pressures):
        return force_start, force_start.copy(), follower, None
    return force_start, force_end, follower, _follower(bodies[1], [(fb, end) for fb, _, end
                                                                   in pressures])


def build_problem(mesh_data: MeshData, conditions: Sequence[Condition],
                  gauss: int | None = None) -> Problem:
    """Basis, loading, Gauss weights and points, and boundary dofs of ``mesh_data`` under
    ``conditions`` (see the module docstring); ``gauss`` as
    :func:`~granular_material.fem.boundary_value.meshes.make_basis` takes it (None: the
    element's default, tri6 3 points, quad8 2 × 2)."""
    if not isinstance(mesh_data, MeshData):
        raise ParameterError("mesh_data", f"must be a MeshData (read_mesh, rectangle_mesh), "
                                          f"got {type(mesh_data).__name__}")
    if isinstance(conditions, str | bytes) or not isinstance(conditions, Iterable):
        raise ParameterError("conditions", f"must be a list of conditions, got "
                                           f"{type(conditions).__name__}")
    conditions = tuple(conditions)
    for c in conditions:
        if not isinstance(c, Fixed | Roller | Displacement | RigidBody | Pressure | Gravity):
            raise ParameterError("conditions", f"{c!r} is not a condition")
        if not isinstance(c, Gravity) and c.boundary not in mesh_data.boundaries:
            known = ", ".join(sorted(mesh_data.boundaries)) or "none"
            raise ParameterError("boundary", f"{c.boundary!r} of {type(c).__name__} is not a "
                                             f"named boundary of the mesh (it has {known})")
    basis = make_basis(mesh_data, gauss)
    dofs = {name: boundary_dofs(basis, facets) for name, facets in mesh_data.boundaries.items()}
    prescribed = _prescribed(conditions, dofs)
    _check_each_part(basis, prescribed)
    order = sorted(prescribed)
    force_start, force_end, follower, follower_end = _external_loads(mesh_data, basis,
                                                                      conditions)
    loading = Loading(
        dirichlet_dofs=np.asarray(order, dtype=np.int64),
        dirichlet_end=np.asarray([prescribed[d][0] for d in order], dtype=np.float64),
        force_start=force_start, force_end=force_end, follower=follower,
        follower_end=follower_end,
    )
    points = to_points(np.asarray(basis.global_coordinates()))
    return Problem(mesh_data, conditions, basis, loading, to_points(basis.dx), points, dofs)
