"""The degrees of freedom of a set of facets, and the force and displacement they carry.

A boundary's nodes are every node of the element on its facets: corner, midside (and, for
a facet, no centre node). Its force is the sum of a nodal vector over its (u_x, u_y) dofs:
of the reaction ``f_int − f_ext`` it is the force [N/m] the supports exert on the body
there; of the internal force ``f_int`` alone it is the force the body's stress exerts on
those nodes (equal to the reaction where no external load acts on them).
"""

from __future__ import annotations

import numpy as np
from skfem import Basis

__all__ = ["BoundaryDofs", "boundary_dofs"]


class BoundaryDofs:
    """The (u_x, u_y) dofs of the nodes of a set of facets.

    Attributes:
        x: u_x dofs, ascending, int64, shape (k,).
        y: u_y dofs of the same nodes, shape (k,).
        locations: the nodes' reference coordinates [m], shape (2, k).
    """

    def __init__(self, x: np.ndarray, y: np.ndarray, locations: np.ndarray) -> None:
        self.x = np.asarray(x, dtype=np.int64)
        self.y = np.asarray(y, dtype=np.int64)
        self.locations = np.asarray(locations, dtype=np.float64)

    def component(self, component: int) -> np.ndarray:
        """The dofs of displacement component 0 (u_x) or 1 (u_y)."""
        return self.x if component == 0 else self.y

    def force(self, nodal: np.ndarray) -> tuple[float, float]:
        """(F_x, F_y) [N/m]: ``nodal`` (ndofs,) summed over these dofs."""
        nodal = np.asarray(nodal)
        return float(nodal[self.x].sum()), float(nodal[self.y].sum())

    def displacement(self, u: np.ndarray) -> tuple[float, float]:
        """Mean (u_x, u_y) [m] of these nodes of the displacement ``u`` (ndofs,)."""
        u = np.asarray(u)
        return float(u[self.x].mean()), float(u[self.y].mean())


def boundary_dofs(basis: Basis, facets: np.ndarray) -> BoundaryDofs:
    """The dofs of every node of the vector ``basis`` on ``facets`` (indices of its mesh)."""
    dofs = basis.get_dofs(facets=np.asarray(facets, dtype=np.int64))
    x, y = (np.asarray(dofs.all(name), dtype=np.int64) for name in ("u^1", "u^2"))
    order = np.argsort(x)
    x, y = x[order], y[order]
    if x.shape != y.shape or not np.allclose(basis.doflocs[:, x], basis.doflocs[:, y]):
        raise RuntimeError("the basis's u_x and u_y dofs of the facets do not pair by node")
    return BoundaryDofs(x, y, basis.doflocs[:, x])
