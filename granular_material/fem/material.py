"""The material protocol that the Newton driver and scikit-fem scripts talk to.

A material holds one constitutive state per Gauss point. The driver evaluates it with the
displacement gradient accumulated since the last commit and, once the load step has
converged, commits it. Arrays are batch-first: point ``p`` of a mesh is ``element * nqp + q``
(see :mod:`granular_material.fem.layout`).

Two ways in, one state:

- ``evaluate(grad_u)`` is the protocol's: batch-first ``(n, 2, 2)`` and the *increment*
  ∇u since the last commit. The project's :class:`~granular_material.fem.newton.NewtonSolver`
  calls it, and nothing about it changes.
- ``response(grad_u, measure="total")`` (:class:`ScikitFemInterface`, offered by both
  shipped materials) is what a scikit-fem, felupe or MGIS user expects: the *total* ∇u by
  default (``measure="increment"`` for the protocol's), in any layout of
  :func:`~granular_material.fem.layout.grad_points` (batch-first, scikit-fem's quadrature-last
  ``(2, 2, nelems, nqp)``, or a ``DiscreteField``), answered in that same layout
  (:class:`QuadratureResponse` for quadrature-last input).

How the material knows the committed state: it keeps the total ∇u of its committed state,
:attr:`ScikitFemInterface.committed_grad_u` (zero at ``allocate``; every ``commit`` makes
the last evaluation's total the committed one, whichever way it was evaluated). A total is
turned into the increment ``∇u − committed_grad_u`` and evaluated as such. This is the
small-strain composition of the project's default formulation (the mesh does not move, so
the reference configuration is also the configuration of the last commit); a finite-strain
(updated-Lagrangian) user passes increments measured on the committed configuration,
``∇_X Δu · F_n⁻¹``, with ``measure="increment"``.

Kinematics and measures, for every material here: ∇u is ∂u_k/∂x_l on the configuration of
the last commit; the stress is the Cauchy stress σ [Pa], tension positive; the tangent is
D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) [Pa], a full fourth-order array. D has the major and the first
minor symmetry of σ (D_ijkl = D_jikl) but in general *not* the second minor symmetry
(D_ijkl ≠ D_ijlk): its spin part, the rotation of the stress by W = skw ∇u, makes it respond
to the skew part of ∇u. A Voigt/Mandel user (3 × 3 matrices on sym ∇u) must therefore either
keep the full (2, 2, 2, 2) tangent (recommended: scikit-fem's forms contract it with ∇v and
∇u directly) or, knowing that the spin term is then dropped, use the part that acts on the
strain, ½ (D_ijkl + D_ijlk), which is exact for the linear-elastic material and loses the
stress's rotation for the DEM one.

A failed point carries a reason (:class:`FailureReason`, the response's ``reasons``) and the
stress of its committed state, never NaN, in every shipped material: a ∇u that is NaN or
infinite at a point is that point's failure (``non_finite_input``); ∇u that is None, text,
complex or of another shape is a ``ValueError`` before any work. What ``commit()`` does after
an evaluation in which points failed is each material's (said in its class): the
linear-elastic and DEM materials commit the failed points' committed state unchanged (their
``committed_grad_u`` too), the Mohr–Coulomb material refuses the commit (RuntimeError);
none commits a non-finite state. ``allocate(n)`` refuses (ParameterError naming
``n_points``, with the estimate) a count that is not an integer >= 1 or whose state would
not fit in the memory available, before it takes any; ``restore(path)`` refuses another
material's checkpoint by that material's name (ValueError).

Semantics every implementation keeps:

- ``evaluate(grad_u)`` starts from the *committed* state, so calling it twice with the same
  ``grad_u`` gives the same answer (idempotent) and a failed Newton iteration costs no state
  (a DEM material with ``drive="continue"`` drives its RVEs on from their last trial state
  instead: still idempotent, but its answer depends on the iterates that came before);
- ``commit()`` makes the state of the last ``evaluate`` the committed one;
- ``revert()`` drops the trial state (the next ``evaluate`` starts from the committed one
  anyway, but a material that keeps its trial state in place restores it here);
- ``checkpoint(path)`` / ``restore(path)`` write and read the committed state;
- optionally, ``hold_tangent(hold)``: the Newton driver's ``tangent_update="hold"`` calls
  ``hold_tangent(True)`` before an increment's first evaluation and then uses that
  evaluation's tangent alone, so a material whose tangent is costly (the DEM material's
  condensed or perturbation tangent) may return it unchanged from the later evaluations,
  until the next ``commit`` or ``revert``. A material without it is evaluated as always.

Materials are found by name through the ``granular_material.materials`` entry-point group.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from granular_material.entry_points import entry_point_names, load_entry_point
from granular_material.fem.layout import Layout, grad_points, to_quadrature
from granular_material.fem.material_checks import check_grad

__all__ = [
    "ENTRY_POINT_GROUP",
    "MEASURES",
    "FailureReason",
    "Material",
    "MaterialResponse",
    "PointStatus",
    "QuadratureResponse",
    "ScikitFemInterface",
    "available_materials",
    "create_material",
    "load_material",
]

#: what the ∇u given to :meth:`ScikitFemInterface.response` measures
MEASURES = ("total", "increment")

ENTRY_POINT_GROUP = "granular_material.materials"


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
            evaluations of a load step (:attr:`~granular_material.fem.newton.StepRecord.costs`)
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
    :meth:`ScikitFemInterface.response` answers to a ``(2, 2, nelems, nqp)`` ∇u or a
    ``DiscreteField``, ready for a form (``w.sigma``, ``w.D``).

    Attributes:
        stress: Cauchy stress σ [Pa], tension positive, shape (2, 2, nelems, nqp).
        tangent: D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) [Pa], shape (2, 2, 2, 2, nelems, nqp); no
            minor symmetry in (k, l) in general (see :mod:`granular_material.fem.material`).
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


@runtime_checkable
class Material(Protocol):
    """What the Newton driver needs from a constitutive model (batch of Gauss points)."""

    @property
    def n_points(self) -> int:
        """Number of Gauss points allocated (0 before :meth:`allocate`)."""
        ...

    def allocate(self, n_points: int) -> None:
        """Create the initial committed state for ``n_points`` Gauss points."""
        ...

    def evaluate(self, grad_u: np.ndarray) -> MaterialResponse:
        """Response to ∇u [-], shape (n, 2, 2), measured from the committed state."""
        ...

    def commit(self) -> None:
        """Accept the state of the last :meth:`evaluate` as the committed state."""
        ...

    def revert(self) -> None:
        """Discard any trial state; the committed state is unchanged."""
        ...

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed state to ``path``."""
        ...

    def restore(self, path: str | Path) -> None:
        """Read a committed state written by :meth:`checkpoint` (allocates as needed)."""
        ...


class ScikitFemInterface:
    """What a scikit-fem (felupe, MGIS) user calls on a material, beside the protocol.

    Mixed into :class:`~granular_material.fem.linear_elastic.LinearElastic` and the DEM
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


def available_materials() -> list[str]:
    """Names registered in the ``granular_material.materials`` entry-point group."""
    return entry_point_names(ENTRY_POINT_GROUP)


def load_material(name: str) -> type:
    """The material class registered under ``name``; ``ValueError`` naming the choices."""
    return load_entry_point(ENTRY_POINT_GROUP, name, "material")


def create_material(name: str, **parameters: Any) -> Material:
    """Instantiate the material ``name`` with keyword ``parameters`` (not yet allocated)."""
    material = load_material(name)(**parameters)
    if not isinstance(material, Material):
        raise TypeError(f"material {name!r} does not implement the Material protocol")
    return material
