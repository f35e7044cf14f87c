"""Plane-strain Mohr–Coulomb elastoplasticity with friction softening and its exact tangent.

The return mapping in principal stresses is in
:mod:`granular_material.fem.materials.mohr_coulomb_return`; this module holds the state, the
kinematics (spin of the committed stress, elastic trial), the spectral decomposition of the
in-plane stress and the assembly of the consistent tangent.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from granular_material.errors import ParameterError
from granular_material.fem.materials.checks import check_grad, check_points, checkpoint_archive
from granular_material.fem.materials.linear_elastic import isotropic_tangent
from granular_material.fem.materials.mohr_coulomb_parameters import (
    MohrCoulombParameters,
    MohrCoulombRunParameters,
    number,
)
from granular_material.fem.materials.mohr_coulomb_return import (
    APEX,
    ELASTIC,
    SYM4,
    in_plane_principal,
    principal_return,
    spectral_derivative,
    yield_function,
)
from granular_material.fem.materials.protocol import (
    FailureReason,
    MaterialResponse,
    PointStatus,
    ScikitFemInterface,
)
from granular_material.filesafe import write_whole
from granular_material.vocabulary import renamed

__all__ = ["APEX_TANGENT", "MohrCoulomb", "MohrCoulombParameters", "MohrCoulombRunParameters"]

_I2 = np.eye(2)
#: the fraction of the elastic tangent that a point at the apex iterates with (a matrix for
#: Newton, never its stress): with c = 0 the apex is stress-free and its exact tangent is 0,
#: so an element whose points all reach it leaves Newton a singular matrix (the softening
#: footing's corner: "matrix is exactly singular" at 9 mm). The DEM material floors an
#: unconfined RVE's tangent by the same fraction of its initial one.
APEX_TANGENT = 0.05
_NAME = "mohr-coulomb"
#: memory of one point: its state and trial copies, and an evaluation's principal
#: return, spectral derivative, spin and tangent work arrays, with a margin [bytes]
_POINT_BYTES = 8192


class MohrCoulomb(ScikitFemInterface):
    """Plane-strain Mohr–Coulomb material: linear isotropic elasticity, the full hexagon on
    the principal stresses (the in-plane pair and the out-of-plane σzz, tracked), a
    non-associated potential (ψ), friction softening with the plastic shear strain γp.

    Kinematics (as the DEM material under finite strain): ``evaluate(G)`` takes G = ∇u, the
    increment since the last commit on the committed configuration. The committed stress is
    spun by W = skw G to first order, σrot = σn + W σn − σn W (σzz unchanged), then the
    elastic trial σtr = σrot + C : sym G, σzz,tr = σzz,n + λ tr sym G, then the implicit
    return in principal stresses
    (:func:`~granular_material.fem.materials.mohr_coulomb_return.principal_return`).
    The tangent D_ijkl = ∂σ_ij/∂G_kl [Pa] is the exact derivative of that whole map: the
    return's algorithmic Jacobian, the rotation of the in-plane principal directions (with
    its limit at equal eigenvalues) and the spin term.

    Signs: tension positive. The plastic shear strain γp ≥ 0 grows by 2 Σ Δγ^i over the
    active planes (the principal plastic shear Δε1p − Δε3p on the face; see
    :mod:`~granular_material.fem.materials.mohr_coulomb_return`); on the face the plastic volumetric
    strain (tension positive: dilation > 0) grows as dεvp/dγp = sin ψ (−sin ψ with
    compression positive).

    A response carries ``costs`` ``{"return_iterations": n}`` (local Newton iterations,
    0 without softening) and ``fields``: ``stress_zz`` [Pa], ``plastic_shear_strain`` [-],
    ``friction_angle`` [°] (after softening) and ``return_region`` (0 elastic, 1 face,
    2 edge σ1 = σ2, 3 edge σ2 = σ3, 4 apex).

    With c = 0 the apex is the origin: a point returned there (e.g. pulled into tension) is
    stress-free with status OK; it has no strength there and its exact tangent is zero. The
    tangent it answers is ``apex_tangent`` × C (default :data:`APEX_TANGENT`), so that a
    Newton matrix stays regular where a region of points reaches the apex; the stress, and so
    the converged answer, is the same. ``apex_tangent=0`` gives the exact tangent everywhere.

    Strength reduction: :meth:`reduce_strength` (F) makes the later evaluations use
    ``parameters.reduced(F)`` from the committed state; :attr:`strength_factor` is F (1.0
    by default), kept by :meth:`checkpoint` and :meth:`restore`.

    Failures: a non-finite ∇u fails its point (``non_finite_input``), a local Newton that
    does not converge fails it (``failed``); a failed point answers its committed stress and
    the elastic tangent, never NaN. :meth:`commit` refuses an evaluation with failed points
    (RuntimeError) and keeps the committed state.

    The constants ``young``, ``poisson``, ``friction_angle``, ``dilation_angle``,
    ``cohesion``, ``critical_friction_angle`` and ``softening_strain`` are those of
    :class:`MohrCoulombParameters` (degrees, Pa), and a run specification's
    (:class:`MohrCoulombRunParameters`); ``E`` and ``nu``, their old names, are deprecated
    (a :class:`~granular_material.vocabulary.RenamedWarning`).

    Args:
        initial_stress: the stress at allocation [Pa], tension positive: a number
            (isotropic), a (2, 2) array (every point) or an (n, 2, 2) array (per Gauss
            point, checked at :meth:`allocate`).
        initial_stress_zz: σzz at allocation [Pa]: a number or an (n,) array; default the
            initial σxx (a geostatic K0 state has both horizontal stresses K0·σv).
        apex_tangent: the fraction [-] (≥ 0) of the elastic tangent C a point at the apex
            answers as its tangent; 0: the exact (zero) tangent.
    """

    #: the parameters of the material in a run specification
    Parameters = MohrCoulombRunParameters

    def __init__(
        self, young: float = 60.0e6, poisson: float = 0.3, friction_angle: float = 30.0,
        dilation_angle: float = 0.0, cohesion: float = 0.0,
        critical_friction_angle: float | None = None, softening_strain: float = 0.0,
        initial_stress: float | np.ndarray = 0.0,
        initial_stress_zz: float | np.ndarray | None = None,
        *, E: float | None = None, nu: float | None = None,
        apex_tangent: float = APEX_TANGENT,
    ) -> None:
        old = renamed({k: v for k, v in (("E", E), ("nu", nu)) if v is not None},
                      "mohr-coulomb")
        self.parameters = MohrCoulombParameters(
            old.get("young", young), old.get("poisson", poisson), friction_angle,
            dilation_angle, cohesion, critical_friction_angle, softening_strain)
        self._strength = self.parameters.strength()
        self._factor = 1.0
        self.apex_tangent = number("apex_tangent", apex_tangent)
        if not self.apex_tangent >= 0:
            raise ParameterError("apex_tangent", "must be a fraction >= 0 of the elastic "
                                                 f"tangent, got {apex_tangent!r}")
        lam, mu = self.parameters.lame
        self._lam = lam
        self._c = isotropic_tangent(lam, mu)
        self._initial = _initial_array("initial_stress", initial_stress, (2, 2))
        if self._initial.ndim >= 2 and not np.allclose(
                self._initial, np.swapaxes(self._initial, -1, -2), rtol=0, atol=1e-9 * (
                    1 + np.abs(self._initial).max())):
            raise ParameterError("initial_stress", "must be symmetric")
        self._initial_zz = (None if initial_stress_zz is None
                            else _initial_array("initial_stress_zz", initial_stress_zz, ()))
        self._stress = np.zeros((0, 2, 2))
        self._zz = np.zeros(0)
        self._gamma = np.zeros(0)
        self._yielding = np.zeros(0, dtype=bool)
        self._trial: tuple[np.ndarray, ...] | None = None
        self._trial_failed = np.zeros(0, dtype=bool)

    @staticmethod
    def for_run(parameters: MohrCoulombRunParameters, context: Any) -> MohrCoulomb:
        """The material of a run: isotropic at the run's confining pressure (a
        :class:`~granular_material.fem.materials.run_context.RunContext`), not yet allocated."""
        return MohrCoulomb(young=parameters.young, poisson=parameters.poisson,
                           friction_angle=parameters.friction_angle,
                           dilation_angle=parameters.dilation_angle,
                           cohesion=parameters.cohesion,
                           critical_friction_angle=parameters.critical_friction_angle,
                           softening_strain=parameters.softening_strain,
                           initial_stress=-context.confining)

    @staticmethod
    def continuum_twin(parameters: MohrCoulombRunParameters, pressure: float,
                       device: str | None = None) -> dict[str, Any]:
        """What a boundary-value problem's continuum start takes of the material: its own
        ``young`` [Pa] and ``poisson`` [-], and its ``friction_angle`` [°] where it is
        cohesionless (the start's friction cap is a cone through the origin; with cohesion,
        None: the material refuses a start outside its strength itself)."""
        return {"young": float(parameters.young), "poisson": float(parameters.poisson),
                "friction_angle": (float(parameters.friction_angle)
                                   if parameters.cohesion == 0 else None)}

    @staticmethod
    def for_problem(parameters: MohrCoulombRunParameters, context: Any,
                    initial_stress: np.ndarray) -> MohrCoulomb:
        """The material of a boundary-value problem: its Gauss points at ``initial_stress``
        [Pa] (n, 2, 2), tension positive (σzz = σxx: both horizontal stresses alike, as in a
        geostatic K0 state); not yet allocated."""
        return MohrCoulomb(young=parameters.young, poisson=parameters.poisson,
                           friction_angle=parameters.friction_angle,
                           dilation_angle=parameters.dilation_angle,
                           cohesion=parameters.cohesion,
                           critical_friction_angle=parameters.critical_friction_angle,
                           softening_strain=parameters.softening_strain,
                           initial_stress=initial_stress)

    # -- read-only state -------------------------------------------------------------
    @property
    def n_points(self) -> int:
        """Number of Gauss points allocated."""
        return int(self._stress.shape[0])

    @property
    def stress(self) -> np.ndarray:
        """Committed in-plane Cauchy stress [Pa], (n, 2, 2) (a copy)."""
        return self._stress.copy()

    @property
    def stress_zz(self) -> np.ndarray:
        """Committed out-of-plane stress σzz [Pa], (n,) (a copy)."""
        return self._zz.copy()

    @property
    def plastic_shear_strain(self) -> np.ndarray:
        """Committed plastic shear strain γp [-], (n,) (a copy)."""
        return self._gamma.copy()

    @property
    def yielding(self) -> np.ndarray:
        """Whether each point yielded in the last committed increment, (n,) bool."""
        return self._yielding.copy()

    @property
    def friction_angle_now(self) -> np.ndarray:
        """Friction angle after softening at the committed γp [°], (n,)."""
        return np.degrees(self._strength.angles(self._gamma)[0])

    # -- strength reduction ------------------------------------------------------------
    @property
    def strength_factor(self) -> float:
        """The factor F [-] the strength is divided by (:meth:`reduce_strength`; 1.0: the
        parameters' own strength)."""
        return self._factor

    def reduce_strength(self, factor: float) -> None:
        """Make every later :meth:`evaluate` use the strength of
        ``parameters.reduced(factor)`` (c/F, tan φ/F, tan φcs/F, tan ψ/F; F > 0, finite,
        relative to :attr:`parameters`, not to the factor before). The committed stress and
        plastic strain are kept, so the next :meth:`evaluate` starts from the committed
        state and returns its trial onto the reduced surface; an evaluation not yet
        committed is kept as it was made (a driver that sets the factor it converged at
        commits it). :attr:`parameters` stay the unreduced ones; ``friction_angle_now`` and
        the ``friction_angle`` field are the reduced angle. ParameterError naming ``factor``
        for a factor that is not > 0 and finite."""
        reduced = self.parameters.reduced(factor)
        self._strength = reduced.strength()
        self._factor = float(factor)

    # -- protocol --------------------------------------------------------------------
    def allocate(self, n_points: int) -> None:
        """Start ``n_points`` points at the initial stress, γp = 0; ParameterError when an
        initial stress has the wrong shape or lies outside the yield surface."""
        n_points = check_points(n_points, _POINT_BYTES, _NAME)
        stress = _per_point("initial_stress", self._initial, n_points, (2, 2))
        zz = (stress[:, 0, 0].copy() if self._initial_zz is None
              else _per_point("initial_stress_zz", self._initial_zz, n_points, ()))
        principal, _, _ = in_plane_principal(stress, zz)
        principal = -np.sort(-principal, axis=1)
        f = yield_function(principal, self._strength.phi, self._strength.cohesion)
        tol = 1e-9 * (np.abs(principal).max(axis=1) + self._strength.cohesion + 1.0)
        outside = np.flatnonzero(f > tol)
        if outside.size:
            worst = outside[np.argmax(f[outside])]
            raise ParameterError("initial_stress", (
                f"lies outside the Mohr-Coulomb surface at {outside.size} of {n_points} "
                f"points; the worst, point {worst}, has f = {f[worst]:.6g} Pa (principal "
                f"stresses {principal[worst].tolist()} Pa)"))
        self._stress, self._zz = stress, zz
        self._gamma = np.zeros(n_points)
        self._yielding = np.zeros(n_points, dtype=bool)
        self._trial = None
        self._track_allocate(n_points)

    def evaluate(self, grad_u: np.ndarray) -> MaterialResponse:
        """σ [Pa] (n, 2, 2) and D = ∂σ/∂∇u [Pa] (n, 2, 2, 2, 2) for ∇u [-] (n, 2, 2), the
        increment since the last commit on the committed configuration."""
        n = self.n_points
        grad = check_grad(grad_u, n)
        self._track_evaluate(grad)
        finite = np.isfinite(grad).all(axis=(1, 2))
        grad = np.where(finite[:, None, None], grad, 0.0)
        eps = 0.5 * (grad + np.swapaxes(grad, 1, 2))
        spin = 0.5 * (grad - np.swapaxes(grad, 1, 2))
        tr = eps[:, 0, 0] + eps[:, 1, 1]
        s_n = self._stress
        trial = (s_n + spin @ s_n - s_n @ spin
                 + (eps.reshape(n, 4) @ self._c.reshape(4, 4).T).reshape(n, 2, 2))
        trial_zz = self._zz + self._lam * tr
        principal, m_a, m_b = in_plane_principal(trial, trial_zz)
        order = np.argsort(-principal, axis=1, kind="stable")
        ret = principal_return(np.take_along_axis(principal, order, axis=1), self._gamma,
                               self._strength)
        out = np.empty_like(principal)
        np.put_along_axis(out, order, ret.stress, axis=1)
        perm = np.zeros((n, 3, 3))
        np.put_along_axis(perm, order[:, :, None], 1.0, axis=2)  # sorted = perm @ principal
        jac = np.swapaxes(perm, 1, 2) @ ret.jacobian @ perm
        stress = out[:, 0, None, None] * m_a + out[:, 1, None, None] * m_b
        tangent = self._tangent(*spectral_derivative(jac, principal, out, m_a, m_b), s_n)
        if self.apex_tangent > 0:
            tangent[ret.region == APEX] += self.apex_tangent * self._c
        ok = finite & ret.converged
        ok &= np.isfinite(stress).all(axis=(1, 2)) & np.isfinite(out[:, 2])
        ok &= np.isfinite(tangent).all(axis=(1, 2, 3, 4))
        reasons = np.full(n, FailureReason.NONE.value, dtype=object)
        reasons[~ret.converged] = FailureReason.FAILED.value
        reasons[~ok & (reasons == "")] = FailureReason.NON_FINITE.value
        reasons[~finite] = FailureReason.NON_FINITE_INPUT.value
        gamma, region = ret.gamma, ret.region.copy()
        if not ok.all():  # failed points answer their committed state and C (+ spin)
            bad = ~ok
            stress[bad], out[bad, 2], gamma[bad], region[bad] = (
                s_n[bad], self._zz[bad], self._gamma[bad], ELASTIC)
            tangent[bad] = self._tangent(np.broadcast_to(SYM4, (n, 4, 4)), np.zeros((n, 4)),
                                         s_n)[bad]
        self._trial = (stress.copy(), out[:, 2].copy(), gamma.copy(), region != ELASTIC)
        self._trial_failed = ~ok
        status = np.where(ok, PointStatus.OK, PointStatus.FAILED).astype(np.int8)
        fields = {"stress_zz": out[:, 2].copy(), "plastic_shear_strain": gamma.copy(),
                  "friction_angle": np.degrees(self._strength.angles(gamma)[0]),
                  "return_region": region.astype(np.float64)}
        return MaterialResponse(stress=stress, tangent=tangent, status=status,
                                costs={"return_iterations": ret.iterations}, fields=fields,
                                reasons=None if ok.all() else reasons)

    def _tangent(self, spectral: np.ndarray, to_zz: np.ndarray, s_n: np.ndarray
                 ) -> np.ndarray:
        """D = ∂σ/∂G [Pa] (n, 2, 2, 2, 2) from ∂σ/∂σtr (n, 4, 4) and ∂σ/∂σzz,tr (n, 4) of
        :func:`~granular_material.fem.materials.mohr_coulomb_return.spectral_derivative` and the
        committed stress ``s_n`` (the spin term)."""
        n = s_n.shape[0]
        # ∂σtr_pq/∂G_kl: elasticity plus the spin of the committed stress,
        # ½ (δ_pk σ_lq − δ_pl σ_kq − σ_pk δ_ql + σ_pl δ_qk)
        s_t = np.swapaxes(s_n, 1, 2)  # axes below: (n, p, q, k, l)
        spin = 0.5 * (_I2[None, :, None, :, None] * s_t[:, None, :, None, :]
                      - _I2[None, :, None, None, :] * s_t[:, None, :, :, None]
                      - s_n[:, :, None, :, None] * _I2[None, None, :, None, :]
                      + s_n[:, :, None, None, :] * _I2[None, None, :, :, None])
        d_trial = self._c.reshape(1, 4, 4) + spin.reshape(n, 4, 4)
        tangent = spectral @ d_trial + self._lam * to_zz[:, :, None] * _I2.reshape(1, 1, 4)
        return tangent.reshape(n, 2, 2, 2, 2)

    def commit(self) -> None:
        """Make the state of the last evaluation the committed state; RuntimeError (and the
        committed state kept) when that evaluation failed at some point."""
        if self._trial is None:
            raise RuntimeError("commit() needs an evaluate() since the last commit/revert")
        if self._trial_failed.any():
            bad = np.flatnonzero(self._trial_failed)
            raise RuntimeError(f"commit() refuses an evaluation that failed at {bad.size} "
                               f"points (first {bad[:8].tolist()}); revert() it")
        self._stress, self._zz, self._gamma, self._yielding = self._trial
        self._trial = None
        self._track_commit()

    def revert(self) -> None:
        """Drop the trial state."""
        self._trial = None
        self._track_revert()

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed state (stress, σzz, γp, yielding, total ∇u), the
        parameters and the :attr:`strength_factor` to ``path`` (.npz), whole or not at all
        (a temporary file renamed)."""
        p = asdict(self.parameters)
        p["critical_friction_angle"] = (np.nan if p["critical_friction_angle"] is None
                                        else p["critical_friction_angle"])
        arrays = {"material": np.array(_NAME), "stress": self._stress, "stress_zz": self._zz,
                  "gamma": self._gamma, "yielding": self._yielding,
                  "grad_u": self.committed_grad_u, "strength_factor": np.array(self._factor),
                  **{f"p_{k}": v for k, v in p.items()}}

        def write(tmp: Path) -> None:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)
        write_whole(path, write)

    def restore(self, path: str | Path) -> None:
        """Read a :meth:`checkpoint`, its strength factor included (1 for a checkpoint
        written before strength reduction existed); ValueError for another material's
        checkpoint or other parameters (the initial stress is not compared: the state holds
        the stress)."""
        with checkpoint_archive(path, _NAME, ("material", "stress", "stress_zz", "gamma",
                                              "yielding", "grad_u")) as data:
            kw = {k[2:]: float(data[k]) for k in data.files if k.startswith("p_")}
            if math.isnan(kw.get("critical_friction_angle", math.nan)):
                kw["critical_friction_angle"] = None
            try:
                saved = MohrCoulombParameters(**kw)
            except TypeError as exc:
                raise ValueError(f"{path}: unreadable parameters ({exc})") from None
            if saved != self.parameters:
                raise ValueError(f"{path}: checkpoint parameters {saved} differ from "
                                 f"{self.parameters}")
            stress = np.array(data["stress"], dtype=np.float64)
            n = stress.shape[0]
            state = (stress, np.array(data["stress_zz"], dtype=np.float64),
                     np.array(data["gamma"], dtype=np.float64),
                     np.array(data["yielding"], dtype=bool))
            grad = np.array(data["grad_u"], dtype=np.float64)
            factor = (float(data["strength_factor"]) if "strength_factor" in data.files
                      else 1.0)
        shapes = [(n, 2, 2), (n,), (n,), (n,)]
        if [a.shape for a in state] != shapes or grad.shape != (n, 2, 2) or not all(
                np.isfinite(a).all() for a in (*state[:3], grad)):
            raise ValueError(f"{path}: the state's arrays are inconsistent or not finite")
        if self.n_points and self.n_points != n:
            raise ValueError(f"{path} holds {n} points; this material is allocated for "
                             f"{self.n_points}")
        try:
            reduced = self.parameters.reduced(factor)
        except ParameterError as exc:
            raise ValueError(f"{path}: unreadable strength factor ({exc})") from None
        self._stress, self._zz, self._gamma, self._yielding = state
        self._strength, self._factor = reduced.strength(), factor
        self._track_allocate(n)
        self._committed_grad = grad
        self._trial = None


def _initial_array(field: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """A number or an array of ``shape`` or (n, *shape), finite; ParameterError otherwise."""
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(field, f"must be a number or an array, got {value!r}") from None
    if array.shape not in ((), shape, (array.shape[0] if array.ndim else 0, *shape)):
        raise ParameterError(field, f"must be a number, shape {shape} or (n, *{shape}), got "
                                    f"shape {array.shape}")
    if not np.isfinite(array).all():
        raise ParameterError(field, "must be finite")
    return array


def _per_point(field: str, array: np.ndarray, n: int, shape: tuple[int, ...]) -> np.ndarray:
    """``array`` (number, ``shape`` or (n, *shape)) for ``n`` points, shape (n, *shape)."""
    if array.ndim == 0:
        base = array * (_I2 if shape == (2, 2) else 1.0)
        return np.broadcast_to(base, (n, *shape)).copy()
    if array.shape == shape and shape:
        return np.broadcast_to(array, (n, *shape)).copy()
    if array.shape != (n, *shape):
        raise ParameterError(field, f"has shape {array.shape}, the material has {n} points: "
                                    f"give a number, {shape} or {(n, *shape)}")
    return array.copy()
