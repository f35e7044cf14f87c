"""Named boundaries chosen by a predicate on the coordinates, e.g. ``"y = top and x <= 0.05"``.

Grammar (no ``eval``)::

    expression := clause ( ("and" | "or") clause )*      "and" binds tighter than "or"
    clause     := coordinate operator value
    coordinate := "x" | "y"
    operator   := "=" | "==" | "<=" | ">=" | "<" | ">"
    value      := a number [m] | "left" | "right" (x) | "bottom" | "top" (y)

``left``/``right``/``bottom``/``top`` are the bounds of the mesh's bounding box. Comparisons
allow a tolerance of 10⁻³ of the shortest facet: ``x = 0`` holds within it, ``x <= 0.05``
up to 0.05 + tol, ``x < 0.05`` below 0.05 − tol. A boundary facet is selected when both its
end nodes satisfy the expression (for the half-planes and lines of this grammar its midside
node then does too); interior facets are never selected. The same grammar chooses the
elements of a region (:func:`select_elements`): those whose centroid satisfies it.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

import numpy as np
from skfem.mesh import Mesh

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.meshes import MeshData
from granular_material.typed_fields import conform

__all__ = ["parse_predicate", "select_boundaries", "select_elements", "select_facets"]

_TOKEN = re.compile(r"\s*(<=|>=|==|=|<|>|[A-Za-z_]+|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")
_OPERATORS = ("=", "==", "<=", ">=", "<", ">")
_NAMES = {"left": (0, "min"), "right": (0, "max"), "bottom": (1, "min"), "top": (1, "max")}
#: a clause: (coordinate 0 | 1, operator, number or side name)
Clause = tuple[int, str, float | str]


def _tokens(expr: str, field: str) -> list[str]:
    out, pos = [], 0
    text = expr.strip()
    while pos < len(text):
        match = _TOKEN.match(text, pos)
        if match is None:
            raise ParameterError(field, f"cannot read {expr!r} at {text[pos:]!r}")
        out.append(match.group(1))
        pos = match.end()
    return out


def parse_predicate(expr: str, field: str = "boundary") -> list[list[Clause]]:
    """The expression ``expr`` as a disjunction of conjunctions of clauses; ParameterError
    naming ``field`` for anything outside the grammar (module docstring)."""
    tokens = _tokens(expr, field)
    if not tokens:
        raise ParameterError(field, "is an empty expression")
    groups: list[list[Clause]] = [[]]
    k = 0
    while True:
        if k + 3 > len(tokens):
            raise ParameterError(field, f"{expr!r}: expected 'x|y <op> value' at the end")
        coord, op, value = tokens[k:k + 3]
        if coord.lower() not in ("x", "y"):
            raise ParameterError(field, f"{expr!r}: {coord!r} is not a coordinate (x or y)")
        if op not in _OPERATORS:
            raise ParameterError(field, f"{expr!r}: {op!r} is not one of "
                                        f"{' '.join(_OPERATORS)}")
        axis = 0 if coord.lower() == "x" else 1
        if value.lower() in _NAMES:
            if _NAMES[value.lower()][0] != axis:
                raise ParameterError(field, f"{expr!r}: {value!r} is not a bound of {coord}")
            parsed: float | str = value.lower()
        else:
            try:
                parsed = float(value)
            except ValueError:
                raise ParameterError(field, f"{expr!r}: {value!r} is neither a number nor "
                                            "left, right, bottom, top") from None
        groups[-1].append((axis, "=" if op == "==" else op, parsed))
        k += 3
        if k == len(tokens):
            return groups
        joint = tokens[k].lower()
        if joint == "or":
            groups.append([])
        elif joint != "and":
            raise ParameterError(field, f"{expr!r}: expected 'and' or 'or', got {tokens[k]!r}")
        k += 1


def _holds(points: np.ndarray, groups: list[list[Clause]], bounds: np.ndarray,
           tol: float) -> np.ndarray:
    """Which of ``points`` (2, k) satisfy the parsed expression."""
    result = np.zeros(points.shape[1], dtype=bool)
    for group in groups:
        ok = np.ones(points.shape[1], dtype=bool)
        for axis, op, value in group:
            if isinstance(value, str):
                value = float(bounds[axis, 0 if _NAMES[value][1] == "min" else 1])
            c = points[axis]
            if op == "=":
                ok &= np.abs(c - value) <= tol
            elif op == "<=":
                ok &= c <= value + tol
            elif op == ">=":
                ok &= c >= value - tol
            elif op == "<":
                ok &= c < value - tol
            else:
                ok &= c > value + tol
        result |= ok
    return result


def select_facets(mesh: Mesh | MeshData, expr: str, name: str = "boundary") -> np.ndarray:
    """Boundary facets [indices, ascending, int64] whose end nodes all satisfy ``expr``;
    ParameterError naming the boundary ``name`` and the expression when none does."""
    if isinstance(mesh, MeshData):
        mesh = mesh.mesh
    groups = parse_predicate(conform(name, expr, str), name)
    p = mesh.p
    bounds = np.stack([p.min(axis=1), p.max(axis=1)], axis=1)
    facets = mesh.boundary_facets()
    ends = mesh.facets[:, facets]
    lengths = np.linalg.norm(p[:, mesh.facets[0]] - p[:, mesh.facets[1]], axis=0)
    tol = 1e-3 * float(lengths.min())
    ok = _holds(p, groups, bounds, tol)
    chosen = np.sort(facets[ok[ends[0]] & ok[ends[1]]]).astype(np.int64)
    if chosen.size == 0:
        raise ParameterError(name, f"selects no boundary facet: {expr!r} (the mesh spans x "
                                   f"{bounds[0, 0]:.6g} to {bounds[0, 1]:.6g}, y "
                                   f"{bounds[1, 0]:.6g} to {bounds[1, 1]:.6g} m)")
    return chosen


def select_elements(mesh: Mesh | MeshData, expr: str, name: str = "region") -> np.ndarray:
    """Elements [indices, ascending, int64] whose centroid (the mean of their corners)
    satisfies ``expr`` (the grammar of the module docstring; ``left``, ``top``, … the mesh's
    bounds); ParameterError naming the region ``name`` and the expression when none does."""
    if isinstance(mesh, MeshData):
        mesh = mesh.mesh
    groups = parse_predicate(conform(name, expr, str), name)
    p = mesh.p
    bounds = np.stack([p.min(axis=1), p.max(axis=1)], axis=1)
    centroids = p[:, mesh.t].mean(axis=1)
    lengths = np.linalg.norm(p[:, mesh.facets[0]] - p[:, mesh.facets[1]], axis=0)
    chosen = np.flatnonzero(_holds(centroids, groups, bounds, 1e-3 * float(lengths.min())))
    if chosen.size == 0:
        raise ParameterError(name, f"selects no element: {expr!r} holds at no element's "
                                   f"centroid (the mesh spans x {bounds[0, 0]:.6g} to "
                                   f"{bounds[0, 1]:.6g}, y {bounds[1, 0]:.6g} to "
                                   f"{bounds[1, 1]:.6g} m)")
    return chosen.astype(np.int64)


def select_boundaries(mesh_data: MeshData, expressions: Mapping[str, str]) -> MeshData:
    """``mesh_data`` with a boundary per ``name: expression`` (:func:`select_facets`) added
    (a name it already has is replaced)."""
    if not isinstance(expressions, Mapping):
        raise ParameterError("boundaries", f"must map names to expressions, got "
                                           f"{type(expressions).__name__}")
    for name in expressions:
        if not (isinstance(name, str) and name.strip()):
            raise ParameterError("boundaries", f"names must be non-empty strings, got "
                                               f"{name!r}")
    return mesh_data.with_boundaries({name: select_facets(mesh_data.mesh, expr, name)
                                      for name, expr in expressions.items()})
