"""The scikit-fem (felupe, MGIS) way into a material: :meth:`ScikitFemInterface.response`
takes the *total* ∇u in any layout and answers in that layout; the protocol's ``evaluate``
(the increment, batch-first) stays the one code path of the physics. See
:mod:`granular_material.fem.materials.protocol` for the conventions.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from granular_material.fem.layout import grad_points
from granular_material.fem.materials.checks import check_grad
from granular_material.fem.materials.response import MaterialResponse, QuadratureResponse

__all__ = ["MEASURES", "ScikitFemInterface"]

#: what the ∇u given to :meth:`ScikitFemInterface.response` measures
MEASURES = ("total", "increment")


class ScikitFemInterface:
    """What a scikit-fem (felupe, MGIS) user calls on a material, beside the protocol.

    Mixed into :class:`~granular_material.fem.materials.linear_elastic.LinearElastic` and the DEM
    material. The class must call :meth:`_track_allocate` in ``allocate``,
    :meth:`_track_evaluate` in ``evaluate`` (with the increment it was given),
    :meth:`_track_commit` in ``commit`` and :meth:`_track_revert` in ``revert``; the DEM
    material's checkpoint keeps :attr:`committed_grad_u` too.

    Why a separate method rather than changing ``evaluate``: the protocol's ``evaluate``
    takes the increment, and the project's Newton driver (and every run built on it) relies
    on it bit for bit; ``response`` gives a user the convention of scikit-fem's examples,
    felupe and MGIS (the total ∇u, in scikit-fem's layout) without a second code path for
    the physics: a total is turned into the increment and evaluated by ``evaluate``.
    """

    _committed_grad: np.ndarray | None = None
    _trial_grad: np.ndarray | None = None

    @property
    def committed_grad_u(self) -> np.ndarray:
        """Total ∇u [-] of the committed state, batch-first (n, 2, 2) (a copy): zero after
        ``allocate``; each ``commit`` adds the increment of the last evaluation."""
        n = self.n_points  # type: ignore[attr-defined]
        if self._committed_grad is None or self._committed_grad.shape[0] != n:
            return np.zeros((n, 2, 2))
        return self._committed_grad.copy()

    def response(self, grad_u: Any, measure: str = "total"
                 ) -> MaterialResponse | QuadratureResponse:
        """Stress and tangent for ∇u, in the layout ∇u came in.

        Args:
            grad_u: ∂u_k/∂x_l [-]: batch-first ``(n, 2, 2)``, scikit-fem's quadrature-last
                ``(2, 2, nelems, nqp)`` (``basis.interpolate(u).grad``), or a scikit-fem
                ``DiscreteField`` of the displacement (``basis.interpolate(u)``).
            measure: ``"total"`` (default: ∇u since ``allocate``, as scikit-fem's examples,
                felupe and MGIS pass it; the material evaluates
                ``∇u − committed_grad_u``) or ``"increment"`` (∇u since the last commit:
                what :meth:`evaluate` takes and the project's Newton driver passes).

        Returns:
            a :class:`MaterialResponse` (batch-first input) or a
            :class:`QuadratureResponse` (quadrature-last input, or a DiscreteField):
            Cauchy stress σ [Pa], tension positive, and D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) [Pa]
            on the configuration of the last commit.

        Like :meth:`evaluate`, it starts from the committed state: calling it twice with the
        same ∇u gives the same answer; :meth:`commit` makes that state the committed one.
        """
        if measure not in MEASURES:
            raise ValueError(f"measure must be one of {', '.join(MEASURES)}, got {measure!r}")
        n = self.n_points  # type: ignore[attr-defined]
        if n == 0:
            raise RuntimeError("allocate() the material before response()")
        if grad_u is None:
            raise ValueError(f"grad_u must be ∇u of {n} points (batch-first (n, 2, 2), "
                             "quadrature-last or a DiscreteField), got None")
        given = np.asarray(getattr(grad_u, "grad", grad_u))  # a DiscreteField's ∇u
        if given.dtype.kind not in "biuf":
            check_grad(given, n)  # names complex values, text or objects
        grad, layout = grad_points(grad_u, n)
        if measure == "total":
            grad = grad - self.committed_grad_u
        result = self.evaluate(grad)  # type: ignore[attr-defined]
        return result.in_layout(layout)

    def _track_allocate(self, n_points: int) -> None:
        self._committed_grad = np.zeros((n_points, 2, 2))
        self._trial_grad = None

    def _track_evaluate(self, increment: np.ndarray) -> None:
        committed = self.committed_grad_u
        trial = committed + np.asarray(increment, dtype=np.float64)
        finite = np.isfinite(trial).all(axis=(1, 2))
        # a point whose ∇u is not finite fails and stays at its committed state
        self._trial_grad = np.where(finite[:, None, None], trial, committed)

    def _track_commit(self, failed: np.ndarray | None = None) -> None:
        """The last evaluation's total ∇u becomes the committed one, but at the ``failed``
        points (bool, (n,)), whose state stays the committed one."""
        if self._trial_grad is not None:
            if failed is not None and np.any(failed):
                keep = np.asarray(failed, dtype=bool)[:, None, None]
                self._trial_grad = np.where(keep, self.committed_grad_u, self._trial_grad)
            self._committed_grad, self._trial_grad = self._trial_grad, None

    def _track_revert(self) -> None:
        self._trial_grad = None
