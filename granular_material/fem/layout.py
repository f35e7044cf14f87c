"""The one place where scikit-fem's quadrature layout meets the materials' batch layout.

scikit-fem stores a field at quadrature points with the tensor axes first and
``(nelems, nqp)`` last, e.g. ∇u as ``(2, 2, nelems, nqp)``. Materials take the batch axis
first, ``(n, 2, 2)``, with Gauss point ``p = element * nqp + q``. Every conversion in the
package goes through :func:`to_points` and :func:`to_quadrature`.

A material's user-facing
:meth:`~granular_material.fem.materials.protocol.ScikitFemInterface.response`
accepts three layouts of ∇u and answers in the one it was given (:func:`grad_points`):

- batch-first ``(n, 2, 2)`` (the driver's, and the materials' own);
- quadrature-last ``(2, 2, nelems, nqp)`` (scikit-fem's, ``basis.interpolate(u).grad``);
- a scikit-fem ``DiscreteField`` of the displacement (``basis.interpolate(u)``): its
  ``.grad``, quadrature-last.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LAYOUTS", "Layout", "grad_points", "to_points", "to_quadrature"]

#: the layouts of ∇u a material's ``response`` accepts
LAYOUTS = ("points", "quadrature")


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


@dataclass(frozen=True)
class Layout:
    """How a caller laid out its ∇u, so that the answer comes back the same way.

    Attributes:
        kind: ``"points"`` (batch-first ``(n, 2, 2)``) or ``"quadrature"``
            (scikit-fem's ``(2, 2, nelems, nqp)``).
        nqp: quadrature points per element (``"quadrature"``; 0 for ``"points"``).
    """

    kind: str = "points"
    nqp: int = 0


def _is_discrete_field(value: object) -> bool:
    """A scikit-fem ``DiscreteField`` (an ndarray subclass carrying ``.grad``)."""
    if type(value) is np.ndarray or getattr(value, "grad", None) is None:
        return False
    return type(value).__name__ == "DiscreteField"


def _layout_error(n_points: int, shape: tuple[int, ...] | str) -> ValueError:
    return ValueError(
        f"grad_u must be laid out batch-first (n, 2, 2) with n = {n_points} Gauss points, "
        f"quadrature-last (2, 2, nelems, nqp) with nelems * nqp = {n_points} (scikit-fem's "
        "layout, e.g. basis.interpolate(u).grad), or be a scikit-fem DiscreteField of the "
        f"displacement (basis.interpolate(u)); got {shape}. Convert other layouts with "
        "granular_material.fem.to_points / to_quadrature"
    )


def grad_points(grad_u: object, n_points: int) -> tuple[np.ndarray, Layout]:
    """∇u [-] batch-first ``(n_points, 2, 2)`` float64, and the layout it came in.

    ``grad_u``: a batch-first array ``(n, 2, 2)``, a quadrature-last array
    ``(2, 2, nelems, nqp)`` (``∂u_k/∂x_l`` at ``[k, l, e, q]``, point ``p = e * nqp + q``),
    or a scikit-fem ``DiscreteField`` of a vector displacement (its ``.grad`` is used).
    ``ValueError`` naming the accepted layouts and :func:`to_points`/:func:`to_quadrature`
    for anything else, or for a point count other than ``n_points``.
    """
    if _is_discrete_field(grad_u):
        grad = np.asarray(grad_u.grad, dtype=np.float64)  # type: ignore[attr-defined]
        if grad.ndim != 4 or grad.shape[:2] != (2, 2):
            raise _layout_error(n_points, f"a DiscreteField whose .grad has shape {grad.shape} "
                                          "(a scalar field? interpolate the vector "
                                          "displacement)")
        return _quadrature(grad, n_points)
    grad = np.asarray(grad_u, dtype=np.float64)
    if grad.ndim == 3 and grad.shape == (n_points, 2, 2):
        return grad, Layout("points")
    if grad.ndim == 4 and grad.shape[:2] == (2, 2):
        return _quadrature(grad, n_points)
    raise _layout_error(n_points, f"shape {grad.shape}")


def _quadrature(grad: np.ndarray, n_points: int) -> tuple[np.ndarray, Layout]:
    nelems, nqp = grad.shape[2:]
    if nelems * nqp != n_points:
        raise _layout_error(n_points, f"shape {grad.shape} ({nelems * nqp} points)")
    return to_points(grad), Layout("quadrature", int(nqp))
