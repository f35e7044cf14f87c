"""The one place where scikit-fem's quadrature layout meets the materials' batch layout.

scikit-fem stores a field at quadrature points with the tensor axes first and
``(nelems, nqp)`` last, e.g. ∇u as ``(2, 2, nelems, nqp)``. Materials take the batch axis
first, ``(n, 2, 2)``, with Gauss point ``p = element * nqp + q``. Every conversion in the
package goes through :func:`to_points` and :func:`to_quadrature`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["to_points", "to_quadrature"]


def to_points(field: np.ndarray) -> np.ndarray:
    """scikit-fem ``(*tensor, nelems, nqp)`` → batch-first ``(nelems * nqp, *tensor)``.

    Point ``p = element * nqp + q``; the result is a contiguous copy.
    """
    field = np.asarray(field)
    if field.ndim < 2:
        raise ValueError(f"a quadrature field needs axes (..., nelems, nqp), got {field.shape}")
    *tensor, nelems, nqp = field.shape
    moved = np.moveaxis(field.reshape(*tensor, nelems * nqp), -1, 0)
    return np.ascontiguousarray(moved)


def to_quadrature(points: np.ndarray, nqp: int) -> np.ndarray:
    """Batch-first ``(nelems * nqp, *tensor)`` → scikit-fem ``(*tensor, nelems, nqp)``."""
    points = np.asarray(points)
    if nqp < 1 or points.ndim < 1 or points.shape[0] % nqp:
        raise ValueError(
            f"{points.shape[0] if points.ndim else 0} points do not split into "
            f"elements of nqp={nqp} quadrature points"
        )
    nelems = points.shape[0] // nqp
    moved = np.moveaxis(points, 0, -1)
    return np.ascontiguousarray(moved.reshape(*points.shape[1:], nelems, nqp))
