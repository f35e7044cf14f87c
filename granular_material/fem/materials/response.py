"""What a material answers: stress, tangent and status per Gauss point
(:class:`MaterialResponse`, batch-first; :class:`QuadratureResponse`, scikit-fem's
quadrature-last layout), why a point failed (:class:`FailureReason`) and the costs it
reports. The conventions (measures, signs, symmetries) are
:mod:`granular_material.fem.materials.protocol`'s.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from granular_material.fem.layout import Layout, to_quadrature

__all__ = ["FailureReason", "MaterialResponse", "PointStatus", "QuadratureResponse"]


class PointStatus(enum.IntEnum):
    """Outcome of a material evaluation at one Gauss point."""

    OK = 0
    FAILED = 1  # no admissible state for this increment (instability, non-finite values)


class FailureReason(str, enum.Enum):
    """Why a point failed: the values of a response's ``reasons`` ("" where it did not).

    Members are strings, so ``response.reasons == FailureReason.MAX_DEM_STEPS`` works and a
    table or summary shows the short value.
    """

    NONE = ""  #: the point did not fail
    FAILED = "failed"  #: failed, reason not given by the material
    NON_FINITE = "non_finite"  #: the material returned a non-finite stress or tangent
    NON_FINITE_INPUT = "non_finite_input"  #: ∇u itself was not finite
    MAX_DEM_STEPS = "max_dem_steps"  #: the RVE's path needs more DEM steps than the cap
    CELL_INVERTED = "cell_inverted"  #: I + ∇u folds the cell (no real logarithm, det ≤ 0)
    CELL_TOO_THIN = "cell_too_thin"  #: the cell got too small or sheared for its discs
    BLOW_UP = "blow_up"  #: a velocity became non-finite or a disc jumped (DEM blow-up)
    OVERCOMPRESSED = "overcompressed"  #: a neighbour list overflowed (discs far too close)
    COINCIDENT = "coincident_discs"  #: two disc centres coincide
    ABORTED = "aborted"  #: not evaluated: another RVE of the same batch blew up

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class MaterialResponse:
    """Stress, tangent and status at every Gauss point after one evaluation.

    Attributes:
        stress: Cauchy stress σ [Pa], tension positive, shape (n, 2, 2), float64.
        tangent: D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) [Pa], shape (n, 2, 2, 2, 2), float64; ∇u on
            the configuration of the last commit; D_ijkl = D_jikl, but in general
            D_ijkl ≠ D_ijlk (no second minor symmetry: see the module docstring for
            Voigt/Mandel users).
        status: :class:`PointStatus` per point, shape (n,), int8.
        costs: what the evaluation cost, by name: numbers (int or float) whose names and
            units are the material's (e.g. the DEM material reports ``dem_steps``,
            ``rve_evaluations`` and ``particle_steps``); empty for a material that counts
            nothing (e.g. a closed-form law). The Newton driver sums each name over the
            evaluations of a load step
            (:attr:`~granular_material.fem.solver.newton.StepRecord.costs`)
            and knows none of them; NumPy scalars are stored as Python numbers.
        fields: further per-point scalars for output (e.g. ``void_ratio``), each shape (n,).
        reasons: why each point failed, shape (n,), str (values of :class:`FailureReason`,
            "" where the point is OK); None (default) derives it: "failed" where the status
            is not OK, "non_finite" where stress or tangent is not finite, else "".
        timings: wall-clock seconds [s] the evaluation spent by phase, for the run's timing
            table (:data:`granular_material.timing.RUN_PHASES`: the DEM material reports
            ``dem``, ``homogenization`` and ``tangent``); empty when the material does not
            time itself.
    """

    stress: np.ndarray
    tangent: np.ndarray
    status: np.ndarray
    costs: Mapping[str, int | float] = field(default_factory=dict)
    fields: Mapping[str, np.ndarray] = field(default_factory=dict)
    reasons: np.ndarray | None = None
    timings: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "costs", _costs(self.costs))
        n = self.stress.shape[0]
        if self.stress.shape != (n, 2, 2):
            raise ValueError(f"stress must have shape (n, 2, 2), got {self.stress.shape}")
        if self.tangent.shape != (n, 2, 2, 2, 2):
            raise ValueError(
                f"tangent must have shape ({n}, 2, 2, 2, 2), got {self.tangent.shape}"
            )
        if self.status.shape != (n,):
            raise ValueError(f"status must have shape ({n},), got {self.status.shape}")
        object.__setattr__(self, "reasons", self._reasons(n))

    @property
    def ok(self) -> bool:
        """True when every point succeeded and stress and tangent are finite."""
        return bool(
            np.all(self.status == PointStatus.OK)
            and np.isfinite(self.stress).all()
            and np.isfinite(self.tangent).all()
        )

    def failed_points(self) -> np.ndarray:
        """Indices of the points that failed or returned non-finite values, shape (k,)."""
        bad = (self.status != PointStatus.OK)
        bad |= ~np.isfinite(self.stress).all(axis=(1, 2))
        bad |= ~np.isfinite(self.tangent).all(axis=(1, 2, 3, 4))
        return np.flatnonzero(bad)

    def failure_causes(self) -> np.ndarray:
        """Indices of the points that failed of themselves, shape (k,): the failed points
        but those aborted because another RVE of their batch failed."""
        bad = self.failed_points()
        return bad[np.asarray(self.reasons)[bad] != FailureReason.ABORTED.value]

    def _reasons(self, n: int) -> np.ndarray:
        finite = (np.isfinite(self.stress).all(axis=(1, 2))
                  & np.isfinite(self.tangent).all(axis=(1, 2, 3, 4)))
        if self.reasons is None:
            reasons = np.full(n, "", dtype=object)
            reasons[np.asarray(self.status) != PointStatus.OK] = FailureReason.FAILED.value
        else:
            reasons = np.array([str(r) for r in np.asarray(self.reasons).reshape(-1)],
                               dtype=object)
            if reasons.shape != (n,):
                raise ValueError(f"reasons must have shape ({n},), got {reasons.shape}")
        reasons[~finite & (reasons == "")] = FailureReason.NON_FINITE.value
        return reasons

    def failure_counts(self) -> dict[str, int]:
        """How many points failed, by reason (:class:`FailureReason` values); empty when
        none did."""
        bad = self.failed_points()
        if not bad.size:
            return {}
        names, counts = np.unique(np.asarray(self.reasons)[bad].astype(str), return_counts=True)
        return {str(name or FailureReason.FAILED.value): int(k)
                for name, k in zip(names, counts, strict=True)}

    def to_quadrature(self, nqp: int) -> QuadratureResponse:
        """This response in scikit-fem's quadrature-last layout (``nqp`` points an
        element): see :class:`QuadratureResponse`."""
        return QuadratureResponse(
            stress=to_quadrature(self.stress, nqp), tangent=to_quadrature(self.tangent, nqp),
            status=to_quadrature(self.status, nqp),
            reasons=to_quadrature(np.asarray(self.reasons), nqp),
            costs=dict(self.costs),
            fields={k: to_quadrature(np.asarray(v), nqp) for k, v in self.fields.items()},
            points=self)

    def in_layout(self, layout: Layout) -> MaterialResponse | QuadratureResponse:
        """This response as the caller laid out its ∇u: itself for ``"points"``, a
        :class:`QuadratureResponse` for ``"quadrature"``."""
        return self if layout.kind == "points" else self.to_quadrature(layout.nqp)


@dataclass(frozen=True)
class QuadratureResponse:
    """A :class:`MaterialResponse` in scikit-fem's quadrature-last layout: what
    :meth:`~granular_material.fem.materials.scikit_fem_interface.ScikitFemInterface.response`
    answers to a ``(2, 2, nelems, nqp)`` ∇u or a ``DiscreteField``, ready for a form
    (``w.sigma``, ``w.D``).

    Attributes:
        stress: Cauchy stress σ [Pa], tension positive, shape (2, 2, nelems, nqp).
        tangent: D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) [Pa], shape (2, 2, 2, 2, nelems, nqp); no
            minor symmetry in (k, l) in general (see
            :mod:`granular_material.fem.materials.protocol`).
        status: :class:`PointStatus`, shape (nelems, nqp).
        reasons: :class:`FailureReason` values ("" where OK), shape (nelems, nqp).
        costs: the material's costs of the evaluation (as :class:`MaterialResponse`).
        fields: the material's per-point scalars, each shape (nelems, nqp).
        points: the same response batch-first (point ``p = element * nqp + q``).
    """

    stress: np.ndarray
    tangent: np.ndarray
    status: np.ndarray
    reasons: np.ndarray
    costs: Mapping[str, int | float]
    fields: Mapping[str, np.ndarray]
    points: MaterialResponse

    @property
    def ok(self) -> bool:
        """True when every point succeeded and stress and tangent are finite."""
        return self.points.ok

    @property
    def failed(self) -> np.ndarray:
        """Where a point failed or returned non-finite values, shape (nelems, nqp), bool."""
        mask = np.zeros(self.points.status.shape[0], dtype=bool)
        mask[self.points.failed_points()] = True
        return mask.reshape(self.status.shape)

    def failure_counts(self) -> dict[str, int]:
        """How many points failed, by reason."""
        return self.points.failure_counts()


def _costs(costs: Mapping[str, Any]) -> dict[str, int | float]:
    """``costs`` as a dict of names to Python ints and floats; ValueError for a name that is
    not a string or a value that is not a real number (booleans included)."""
    out: dict[str, int | float] = {}
    for name, value in costs.items():
        if not isinstance(name, str):
            raise ValueError(f"a cost's name must be a string, got {name!r}")
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"cost {name!r} must be an int or a float, got {value!r}")
        out[name] = value
    return out
