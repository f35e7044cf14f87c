"""Isotropic linear elasticity in plane strain: the baseline material a user swaps out."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from granular_material.errors import ParameterError
from granular_material.fem.materials.checks import (
    CHECKPOINT_NAME_KEY,
    check_grad,
    check_points,
    checkpoint_archive,
)
from granular_material.fem.materials.protocol import (
    FailureReason,
    MaterialResponse,
    PointStatus,
    ScikitFemInterface,
)
from granular_material.filesafe import write_whole
from granular_material.typed_fields import conform_fields
from granular_material.vocabulary import accept_old_keywords, renamed

__all__ = ["LinearElastic", "LinearElasticParameters", "LinearElasticRunParameters",
           "isotropic_tangent"]

_I2 = np.eye(2)
#: the material's name (its entry point), kept in its checkpoints
_NAME = "linear-elastic"
#: memory of one point: its strain, ∇u and their trial copies, and an evaluation's stress,
#: tangent and work arrays, with a margin [bytes]
_POINT_BYTES = 1024


@dataclass(frozen=True, eq=False)
class LinearElasticParameters:
    """Parameters of :class:`LinearElastic`.

    Attributes:
        young: Young's modulus E [Pa], > 0.
        poisson: Poisson's ratio ν [-], in (-1, 0.5).
        initial_stress: stress at zero strain [Pa], tension positive: a number (the
            isotropic σ0 I, e.g. ``-100e3`` for a specimen consolidated to 100 kPa), a
            (2, 2) tensor for every point, or one (n, 2, 2) tensor per Gauss point (a
            geostatic state,
            :func:`granular_material.fem.boundary_value.initial_stress.geostatic_stress`);
            tensors must be finite and symmetric and are kept as a read-only float64 copy.
            Two parameter sets are equal when their moduli and initial stresses are.
    """

    young: float = 60.0e6
    poisson: float = 0.3
    initial_stress: float | np.ndarray = 0.0

    def __post_init__(self) -> None:
        conform_fields(self, skip=("initial_stress",))  # numbers, not text or None
        _check_stress_value(self.initial_stress)
        if not (math.isfinite(self.young) and self.young > 0):
            raise ParameterError("young", f"must be a positive number of Pa, got {self.young!r}")
        if not (math.isfinite(self.poisson) and -1.0 < self.poisson < 0.5):
            raise ParameterError("poisson", f"must lie in (-1, 0.5), got {self.poisson!r}")
        if np.ndim(self.initial_stress) == 0:
            if not math.isfinite(self.initial_stress):
                raise ParameterError("initial_stress", f"must be finite, got "
                                                       f"{self.initial_stress!r}")
            return
        sigma = np.array(self.initial_stress, dtype=np.float64)
        if sigma.shape != (2, 2) and (sigma.ndim != 3 or sigma.shape[1:] != (2, 2)):
            raise ParameterError("initial_stress", "must be a number, a (2, 2) tensor or an "
                                                   f"(n, 2, 2) array [Pa], got shape {sigma.shape}")
        if not np.isfinite(sigma).all():
            raise ParameterError("initial_stress", "must be finite everywhere")
        skew = np.abs(sigma[..., 0, 1] - sigma[..., 1, 0])
        if np.any(skew > 1e-9 * max(float(np.abs(sigma).max()), 1.0)):
            raise ParameterError("initial_stress", "must be symmetric (a Cauchy stress): "
                                                   f"σ_xy − σ_yx up to {skew.max():.3g} Pa")
        sigma.setflags(write=False)
        object.__setattr__(self, "initial_stress", sigma)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, LinearElasticParameters):
            return NotImplemented
        a, b = self.initial_stress, other.initial_stress
        same = (np.ndim(a) == np.ndim(b) == 0 and a == b) or (
            np.ndim(a) > 0 and np.ndim(b) > 0 and np.array_equal(a, b))
        return bool(self.young == other.young and self.poisson == other.poisson and same)

    __hash__ = None  # type: ignore[assignment]  # equal by value, holding an array

    @property
    def per_point(self) -> int | None:
        """The number of points an (n, 2, 2) initial stress is given for, else None."""
        sigma = self.initial_stress
        return int(sigma.shape[0]) if np.ndim(sigma) == 3 else None

    @property
    def lame(self) -> tuple[float, float]:
        """Lamé constants (λ, μ) [Pa]: λ = Eν/((1+ν)(1−2ν)), μ = E/(2(1+ν))."""
        e, nu = self.young, self.poisson
        return e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))


def _check_stress_value(value: Any) -> None:
    """An initial stress is a real number or an array of them (ParameterError otherwise)."""
    if isinstance(value, str | bytes | bool) or value is None:
        raise ParameterError("initial_stress", "must be a number, a (2, 2) tensor or an "
                                               f"(n, 2, 2) array [Pa], got {value!r}")
    try:
        array = np.asarray(value)
    except ValueError:
        array = None
    if array is None or array.dtype.kind not in "biuf":
        raise ParameterError("initial_stress", "must be a number, a (2, 2) tensor or an "
                                               f"(n, 2, 2) array of real numbers [Pa], got "
                                               f"{value!r}"[:200])


@accept_old_keywords("linear-elastic")
@dataclass(frozen=True, kw_only=True)
class LinearElasticRunParameters:
    """The material of a run specification (its initial stress is the run's confining
    pressure): ``young`` Young's modulus [Pa], ``poisson`` Poisson's ratio [-] (the old names
    ``E`` and ``nu`` are still read, with a
    :class:`~granular_material.vocabulary.RenamedWarning`)."""

    young: float = LinearElasticParameters.young
    poisson: float = LinearElasticParameters.poisson

    def __post_init__(self) -> None:
        LinearElasticParameters(self.young, self.poisson)  # the material's own checks


def isotropic_tangent(lam: float, mu: float) -> np.ndarray:
    """C_ijkl = λ δ_ij δ_kl + μ (δ_ik δ_jl + δ_il δ_jk) [Pa], shape (2, 2, 2, 2).

    Contracted with the full ∇u it gives σ = λ tr(ε) I + 2μ ε, ε = sym ∇u (plane strain:
    ε_zz = 0, σ_zz = λ tr ε is not part of the 2D stress).
    """
    d = _I2
    return (
        lam * np.einsum("ij,kl->ijkl", d, d)
        + mu * (np.einsum("ik,jl->ijkl", d, d) + np.einsum("il,jk->ijkl", d, d))
    )


class LinearElastic(ScikitFemInterface):
    """Isotropic, plane-strain linear elastic material (small strain).

    State per point: the committed total strain ε (n, 2, 2). ``evaluate(∇u)`` (the protocol:
    ∇u since the last commit) returns σ = σ0 I + C : (ε + sym ∇u) with the constant tangent C
    of :func:`isotropic_tangent`; ``response(∇u)`` takes the *total* ∇u (or
    ``measure="increment"``) in batch-first or scikit-fem's quadrature-last layout, or a
    ``DiscreteField``, and answers in that layout (see
    :class:`~granular_material.fem.materials.protocol.ScikitFemInterface`).

    Kinematics: ∇u = ∂u_k/∂x_l on the configuration of the last commit (small strain: the
    reference one); σ is the Cauchy stress [Pa], tension positive; the tangent
    D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) = C_ijkl [Pa] has every symmetry (major and both minor), so
    its Voigt/Mandel 3 × 3 form is exact (a rotation costs nothing: small strain).

    Names: ``young`` and ``poisson`` here, in the run specification
    (:class:`LinearElasticRunParameters`) and on the command line (``--young``,
    ``--poisson``); ``E=`` and ``nu=``, their old names, are deprecated (a
    :class:`~granular_material.vocabulary.RenamedWarning`). The spec's confining pressure P
    becomes ``initial_stress=-P`` (tension positive) in :meth:`for_run`.

    Args:
        young: Young's modulus E [Pa], > 0 (default 60 MPa).
        poisson: Poisson's ratio ν [-], in (−1, 0.5) (default 0.3).
        initial_stress: stress at zero strain [Pa], tension positive: a number σ0 (the
            isotropic σ0 I, e.g. ``-100e3`` for a specimen consolidated to 100 kPa; default
            0), a (2, 2) tensor, or an (n, 2, 2) array, one per Gauss point (checked
            against n at :meth:`allocate`).

    A point whose ∇u is not finite fails (``PointStatus.FAILED``,
    ``FailureReason.NON_FINITE_INPUT``): it keeps its committed strain, so its stress is the
    committed one (never NaN), and a ``commit`` keeps it there.
    """

    #: the parameters of the material in a run specification
    Parameters = LinearElasticRunParameters

    def __init__(
        self, young: float = 60.0e6, poisson: float = 0.3,
        initial_stress: float | np.ndarray = 0.0,
        *, E: float | None = None, nu: float | None = None,
    ) -> None:
        old = renamed({k: v for k, v in (("E", E), ("nu", nu)) if v is not None},
                      "linear-elastic")
        young, poisson = old.get("young", young), old.get("poisson", poisson)
        self.parameters = LinearElasticParameters(young, poisson, initial_stress)
        self._tangent = isotropic_tangent(*self.parameters.lame)
        self._strain = np.zeros((0, 2, 2))
        self._trial: np.ndarray | None = None

    @staticmethod
    def for_run(parameters: LinearElasticRunParameters, context: Any) -> LinearElastic:
        """The material of a run: isotropic at the run's confining pressure (a
        :class:`~granular_material.fem.materials.run_context.RunContext`), not yet allocated."""
        return LinearElastic(young=parameters.young, poisson=parameters.poisson,
                             initial_stress=-context.confining)

    @staticmethod
    def continuum_twin(parameters: LinearElasticRunParameters, pressure: float,
                       device: str | None = None) -> dict[str, Any]:
        """What a boundary-value problem's continuum start takes of the material: its own
        ``young`` [Pa] and ``poisson`` [-], and no strength (``friction_angle`` None)."""
        return {"young": float(parameters.young), "poisson": float(parameters.poisson),
                "friction_angle": None}

    @staticmethod
    def for_problem(parameters: LinearElasticRunParameters, context: Any,
                    initial_stress: np.ndarray) -> LinearElastic:
        """The material of a boundary-value problem: its Gauss points at ``initial_stress``
        [Pa] (n, 2, 2), tension positive; not yet allocated."""
        return LinearElastic(young=parameters.young, poisson=parameters.poisson,
                             initial_stress=initial_stress)

    @property
    def n_points(self) -> int:
        """Number of Gauss points allocated."""
        return int(self._strain.shape[0])

    @property
    def strain(self) -> np.ndarray:
        """Committed total strain [-], shape (n, 2, 2), float64 (a copy)."""
        return self._strain.copy()

    @property
    def initial_stress(self) -> float | np.ndarray:
        """The stress at zero strain [Pa], as given (a number, (2, 2) or (n, 2, 2))."""
        return self.parameters.initial_stress

    def _check_points(self, n_points: int) -> None:
        given = self.parameters.per_point
        if given is not None and given != n_points:
            raise ParameterError("initial_stress", f"holds {given} points' stresses, the "
                                                   f"material has {n_points} Gauss points")

    def allocate(self, n_points: int) -> None:
        """Start ``n_points`` points at zero strain (at the initial stress); ParameterError
        naming ``n_points`` (with the memory estimate) for a count that is not an integer
        >= 1 or would not fit in memory, before anything is allocated."""
        n_points = check_points(n_points, _POINT_BYTES, _NAME)
        self._check_points(n_points)
        self._strain = np.zeros((n_points, 2, 2))
        self._trial = None
        self._track_allocate(n_points)

    def evaluate(self, grad_u: np.ndarray) -> MaterialResponse:
        """σ [Pa] (n, 2, 2) and C [Pa] (n, 2, 2, 2, 2) for ∇u [-] (n, 2, 2) since the
        commit (the increment; ``response`` takes totals)."""
        grad_u = check_grad(grad_u, self.n_points)
        n = self.n_points
        finite = np.isfinite(grad_u).all(axis=(1, 2))
        status = np.full(n, PointStatus.OK, dtype=np.int8)
        reasons = None
        if not finite.all():  # those points stay where they were committed
            grad_u = np.where(finite[:, None, None], grad_u, 0.0)
            status[~finite] = PointStatus.FAILED
            reasons = np.where(finite, FailureReason.NONE.value,
                               FailureReason.NON_FINITE_INPUT.value)
        self._track_evaluate(grad_u)
        strain = self._strain + 0.5 * (grad_u + np.swapaxes(grad_u, 1, 2))
        stress = np.einsum("ijkl,nkl->nij", self._tangent, strain)
        sigma0 = self.parameters.initial_stress
        if np.ndim(sigma0) == 0:
            stress += sigma0 * _I2
        else:
            stress += sigma0
        self._trial = strain
        return MaterialResponse(
            stress=stress,
            tangent=np.broadcast_to(self._tangent, (n, 2, 2, 2, 2)).copy(),
            status=status, reasons=reasons,
        )

    def commit(self) -> None:
        """Make the strain of the last evaluation the committed strain."""
        if self._trial is None:
            raise RuntimeError("commit() needs an evaluate() since the last commit/revert")
        self._strain, self._trial = self._trial, None
        self._track_commit()

    def revert(self) -> None:
        """Drop the trial strain."""
        self._trial = None
        self._track_revert()

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed strain, total ∇u and the parameters (the initial stress as
        given: a number or its array) to ``path`` (.npz), whole or not at all (a temporary
        file renamed into place: a failed write keeps the previous file)."""
        p = self.parameters
        arrays = {CHECKPOINT_NAME_KEY: np.array(_NAME),
                  "strain": self._strain, "young": p.young, "poisson": p.poisson,
                  "initial_stress": np.asarray(p.initial_stress),
                  "grad_u": self.committed_grad_u}

        def write(tmp: Path) -> None:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)

        write_whole(path, write)

    def restore(self, path: str | Path) -> None:
        """Read a checkpoint; its parameters must match this material's. ValueError naming
        the material for another material's checkpoint, or a file that is none."""
        with checkpoint_archive(path, _NAME, ("strain", "young", "poisson",
                                              "initial_stress")) as data:
            sigma0 = data["initial_stress"]
            saved = LinearElasticParameters(
                float(data["young"]), float(data["poisson"]),
                float(sigma0) if sigma0.ndim == 0 else np.array(sigma0, dtype=np.float64),
            )
            if saved != self.parameters:
                raise ValueError(f"{path}: checkpoint parameters {saved} differ from "
                                 f"{self.parameters}")
            strain = np.array(data["strain"], dtype=np.float64)
            if strain.ndim != 3 or strain.shape[1:] != (2, 2) or not np.isfinite(strain).all():
                raise ValueError(f"{path}: the committed strain must be finite, shape "
                                 f"(n, 2, 2), got shape {strain.shape}")
            self._check_points(strain.shape[0])
            self._strain = strain
            self._track_allocate(self._strain.shape[0])
            if "grad_u" in data:  # checkpoints before the total form hold none
                self._committed_grad = np.array(data["grad_u"], dtype=np.float64)
        self._trial = None

