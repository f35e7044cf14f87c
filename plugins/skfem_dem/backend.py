"""The DEM backend behind :class:`~granular_material_skfem.material.DEMMaterial`.

A backend owns the RVEs of a material (one per Gauss point, batch-first) and offers what
the material needs: evaluate ∇u from the committed state, commit, revert, checkpoint.
:class:`InProcessBackend` keeps the whole :class:`~granular_material.dem.DEMBatch` in this
process (CPU shards or one CUDA device); :class:`~granular_material_skfem.mpi.MPIBackend`
spreads contiguous shards of the RVEs over MPI ranks, each shard an :class:`InProcessBackend`
of its own, behind the same calls.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from granular_material.dem import DEMBatch, DEMInstabilityError, Homogenized, RVEData, save_rve
from granular_material.dem.condensed import condensed_tangent
from granular_material.dem.condensed_cg import CGFallbackWarning, condensed_tangent_cg
from granular_material.dem.condensed_device import condensed_tangent_of_batch
from granular_material.dem.homogenization import objective_tangent, spin_tangent
from granular_material.fem.material import FailureReason
from granular_material.procedures import (
    drive_grad_u,
    has_real_logarithm,
    over_step_cap,
    path_steps,
)
from granular_material.procedures.strain_path import DEFAULT_MIN_STEPS, DEFAULT_STRAIN_PER_STEP
from granular_material.timing import PhaseTimes

__all__ = [
    "DRIVES",
    "REUSE_CORRECTIONS",
    "TANGENTS",
    "DEMBackend",
    "Evaluation",
    "InProcessBackend",
    "check_driving",
    "check_reuse",
    "instability_reason",
]

#: the RVEs' tangents: the objective one (symmetric Kruyt–Rothenburg plus the stress's spin,
#: see granular_material.dem.homogenization.objective_tangent), Kruyt–Rothenburg as Wu et al.
#: publish it, forward differences of the RVE's own response, or the condensed stiffness of
#: its contact network (granular_material.dem.condensed, plus the stress's spin), with the
#: contacts at their Coulomb cap free to slide or (condensed-sticking) keeping kt
TANGENTS = ("objective", "kruyt-rothenburg", "perturbation", "condensed", "condensed-sticking")
#: the condensed tangents and how each treats a contact at its Coulomb cap
#: (granular_material.dem.condensed.SLIDING_MODES)
CONDENSED_SLIDING = {"condensed": "free", "condensed-sticking": "stick"}
#: how an RVE that must move is driven to a new trial ∇u: from the committed state along the
#: whole path of the step (``restart``, Guo & Zhao), or from its last trial state by the change
DRIVES = ("restart", "continue")
#: what a reused RVE returns: its last response as it is, or corrected to first order by
#: its tangent for the change of ∇u
REUSE_CORRECTIONS = ("none", "tangent")
_COMPONENTS = ((0, 0), (0, 1), (1, 0), (1, 1))  # the (k, l) of ∂u_k/∂x_l


#: the smallest perturbation of ∇u the perturbation tangent takes [-]
MIN_PERTURBATION = 1.0e-4


def check_driving(tangent: str, perturbation: float, min_perturbation: float,
                  max_strain_per_step: float, min_steps: int) -> None:
    """The one check of how RVEs are driven; ``ValueError`` naming the field and value."""
    if tangent not in TANGENTS:
        raise ValueError(f"tangent must be one of {', '.join(TANGENTS)}, got {tangent!r}")
    for name, value in (("perturbation", perturbation), ("min_perturbation", min_perturbation),
                        ("max_strain_per_step", max_strain_per_step)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    if int(min_steps) != min_steps or min_steps < 1:
        raise ValueError(f"min_steps must be an integer >= 1, got {min_steps!r}")


def check_reuse(reuse_tol: float, reuse_correction: str, drive: str, tangent: str) -> None:
    """The one check of the reuse settings; ``ValueError`` naming the field and value."""
    if not (math.isfinite(reuse_tol) and reuse_tol >= 0):
        raise ValueError(f"reuse_tol must be a finite strain >= 0 (0: off), got {reuse_tol!r}")
    if reuse_correction not in REUSE_CORRECTIONS:
        raise ValueError(f"reuse_correction must be one of {', '.join(REUSE_CORRECTIONS)}, "
                         f"got {reuse_correction!r}")
    if drive not in DRIVES:
        raise ValueError(f"drive must be one of {', '.join(DRIVES)}, got {drive!r}")
    if drive == "continue" and tangent == "perturbation":
        raise ValueError("drive 'continue' does not combine with the 'perturbation' tangent "
                         "(its perturbed runs start from the committed state)")


@dataclass(frozen=True)
class Evaluation:
    """What one evaluation of the RVEs gave.

    Attributes:
        homogenized: the homogenised RVEs (stress, tangent, void ratio, ... of
            :class:`~granular_material.dem.Homogenized`); with the "perturbation" tangent its
            ``tangent`` is the forward-difference one. NaN throughout when the batch failed.
        failed: RVEs whose state blew up or whose ∇u inverts the cell, shape (B,), bool.
        dem_steps: DEM steps run: the longest path of each drive, the drives of the
            evaluation together.
        rve_evaluations: RVE paths run (an RVE stepped in a drive counts once per drive).
        particle_steps: disc-steps run, Σ over the stepped RVEs of their steps × discs.
        drives: the cost (DEM steps, RVE paths, particle-steps) of each drive the evaluation
            completed, in order (the totals above are their sums, DEM steps included).
        complete: False when a drive blew up: the batch is then back in its committed state
            and the response is NaN throughout.
        reasons: why each failed RVE failed, shape (B,), str (:class:`FailureReason`
            values, "" where it did not); None: "failed" where ``failed``.
        timings: wall-clock seconds [s] by phase: ``dem`` (stepping the RVEs, restoring
            them included), ``homogenization`` (Love stress, tangent, fabric) and ``tangent``
            (the objective or condensed tangent on top); empty where not timed.
    """

    homogenized: Homogenized
    failed: np.ndarray
    dem_steps: int
    rve_evaluations: int = 0
    particle_steps: int = 0
    drives: tuple[tuple[int, int, int], ...] = ()
    complete: bool = True
    reasons: np.ndarray | None = None
    timings: dict[str, float] = field(default_factory=dict)

    def failure_reasons(self) -> np.ndarray:
        """:attr:`reasons`, or "failed" where ``failed`` when the backend gave none."""
        if self.reasons is not None:
            return np.asarray(self.reasons, dtype=object)
        reasons = np.full(len(self.failed), "", dtype=object)
        reasons[np.asarray(self.failed, dtype=bool)] = FailureReason.FAILED.value
        return reasons


#: the DEM's messages (:class:`~granular_material.dem.DEMInstabilityError`) by the words that
#: tell them apart, most telling first, and the reason each gives a point
_INSTABILITIES = (("non-finite", FailureReason.BLOW_UP),
                  ("cell became too small", FailureReason.CELL_TOO_THIN),
                  ("overflowed", FailureReason.OVERCOMPRESSED),
                  ("coincide", FailureReason.COINCIDENT))


def instability_reason(messages: list[str]) -> FailureReason:
    """The reason of the RVEs of a :class:`~granular_material.dem.DEMInstabilityError`: the
    first of its messages, in the order blow-up, cell too thin, overcompressed, coincident
    discs (the DEM reports the messages of the batch together, not one per RVE)."""
    text = " ".join(messages)
    for words, reason in _INSTABILITIES:
        if words in text:
            return reason
    return FailureReason.BLOW_UP


def _nan_like(h: Homogenized) -> Homogenized:
    return Homogenized(**{f.name: np.full_like(np.asarray(getattr(h, f.name), dtype=np.float64),
                                               np.nan) for f in fields(h)})


def _with_condensed(batch: DEMBatch, h: Homogenized, moved: np.ndarray,
                    sliding: str = "free") -> Homogenized:
    """``h`` with the condensed tangent [Pa] of the ``moved`` RVEs' current states, contacts
    at their cap treated as ``sliding`` says ("free" or "stick"): on a CUDA batch by the
    warp CG on its device, its systems assembled there too (float64) or on the host
    (float32); on the CPU by scipy's LU. An RVE whose CG does not converge (a nearly
    singular network: the paper's specimen on an H200 met one in 600 at 3.6 %) takes the
    LU's tangent, with a :class:`CGFallbackWarning`."""
    tangent = np.array(h.tangent, dtype=np.float64, copy=True)
    rves = np.flatnonzero(moved)
    if not str(batch.device).startswith("cuda"):
        tangent[moved] = condensed_tangent(batch.to_data(), rves=rves, sliding=sliding).tangent
        return replace(h, tangent=tangent)
    data = None  # a host copy of the batch, made once where it is needed
    if batch.dtype == "float64":
        result = condensed_tangent_of_batch(batch, rves=rves, sliding=sliding,
                                            raise_unconverged=False)
    else:
        data = batch.to_data()
        result = condensed_tangent_cg(data, rves=rves, device=batch.device,
                                      sliding=sliding, raise_unconverged=False)
    tangent[moved] = result.tangent
    unconverged = rves[~result.converged]
    if len(unconverged):
        data = batch.to_data() if data is None else data
        redo = condensed_tangent(data, rves=unconverged, sliding=sliding)
        tangent[unconverged] = redo.tangent
        warnings.warn(
            f"condensed tangent: the CG on {batch.device} did not converge for "
            f"{len(unconverged)} of {len(rves)} RVEs ({unconverged.tolist()[:10]}, relative "
            f"residual up to {result.residual[~result.converged].max():.2g}); their tangents "
            "are scipy's LU's, on the host", CGFallbackWarning, stacklevel=2)
    return replace(h, tangent=tangent)


def _totals(drives: list[tuple[int, int, int]]) -> tuple[int, int, int]:
    """DEM steps, RVE paths and particle-steps of ``drives`` together."""
    steps, paths, particles = (int(sum(d[k] for d in drives)) for k in range(3))
    return steps, paths, particles


class DEMBackend(Protocol):
    """What the DEM material asks of whoever holds its RVEs."""

    n_rve: int

    def evaluate(self, grad_u: np.ndarray) -> Evaluation:
        """Deform every RVE from its committed state by ∇u (B, 2, 2) and homogenise."""
        ...

    def committed_rves(self) -> RVEData:
        """The committed RVE states (contact history included)."""
        ...

    def commit(self) -> None:
        """The state reached by the last evaluate becomes the committed state."""
        ...

    def revert(self) -> None:
        """Return every RVE to its committed state."""
        ...

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed state as an RVE file."""
        ...


class InProcessBackend:
    """All RVEs in one :class:`DEMBatch` of this process.

    Reuse of undisturbed RVEs: the backend remembers, per RVE, the ∇u its state was last
    driven to (measured from its committed state) and the response there. An RVE whose new
    ∇u differs from that one by at most ``reuse_tol`` in every component is not stepped: it
    keeps its state and returns that response (``reuse_correction="tangent"``: plus its
    tangent times the difference). When a step commits, a reused RVE's committed state is the
    one it reached; the small mismatch to the ∇u the FEM committed is carried as the RVE's
    *lag* F_lag = (I + ∇u_FEM)(I + ∇u_RVE)⁻¹ and the next step drives it by
    (I + ∇u)·F_lag − I, so that no error accumulates over the steps. ``reuse_tol = 0`` steps
    every RVE at every evaluation, exactly as without reuse.

    Args:
        batch: the RVEs, in their committed state.
        max_strain_per_step: largest strain component per DEM step (Guo & Zhao: 1e-5).
        min_steps: fewest DEM steps per evaluation.
        tangent: "objective" (the symmetric Kruyt–Rothenburg estimate plus the stress's
            spin, one DEM run per evaluation: see
            :func:`~granular_material.dem.homogenization.objective_tangent`),
            "kruyt-rothenburg" (the contact-network estimate as Wu et al. publish it) or
            "perturbation" (the derivative of the RVE's own response to ∇u by
            forward differences: four more runs from the committed state, with ∇u + h E_kl,
            h = max(perturbation · max|∇u|, min_perturbation) per RVE) or "condensed" (the
            contact network's stiffness with the discs' fluctuations condensed out,
            :mod:`granular_material.dem.condensed`: no DEM run, a sparse LU per RVE; a
            contact at its Coulomb cap slides freely) or "condensed-sticking" (the same,
            every touching contact keeping kt: an upper bound of the RVE's incremental
            stiffness at its contacts, so that a Newton correction does not overshoot where
            a contact at its cap sticks again).
        perturbation: relative size of the perturbation [-].
        min_perturbation: smallest perturbation [-].
        reuse_tol: largest change of ∇u [-] (max over the components) for which an RVE keeps
            its last response instead of being stepped; 0: off.
        reuse_correction: "none" or "tangent" (first-order correction of a reused response).
        drive: "restart" (an RVE that moves is restored to the committed state and driven
            along the whole path of the step) or "continue" (driven from its last trial state
            by the change, (I + ∇u_new)(I + ∇u_last)⁻¹ − I: fewer steps, but the response then
            depends on the Newton iterates' path).
        max_steps: cap on one RVE path's DEM steps: an RVE whose path needs more is reported
            failed (the Newton driver then cuts the increment back); None: no cap.
    """

    def __init__(self, batch: DEMBatch, max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
                 min_steps: int = DEFAULT_MIN_STEPS, tangent: str = "objective",
                 perturbation: float = 0.1, min_perturbation: float = MIN_PERTURBATION,
                 reuse_tol: float = 0.0, reuse_correction: str = "none",
                 drive: str = "restart", max_steps: int | None = None) -> None:
        check_driving(tangent, perturbation, min_perturbation, max_strain_per_step, min_steps)
        check_reuse(reuse_tol, reuse_correction, drive, tangent)
        self.batch = batch
        self.max_strain_per_step = max_strain_per_step
        self.min_steps = min_steps
        self.tangent = tangent
        self.perturbation, self.min_perturbation = perturbation, min_perturbation
        self.reuse_tol, self.reuse_correction, self.drive = reuse_tol, reuse_correction, drive
        self.max_steps = max_steps
        self._committed = batch.snapshot()
        self._trial = False
        b = batch.n_rve
        #: F_lag − I per RVE: what the FEM's committed configuration is ahead of the RVE's
        self.lag = np.zeros((b, 2, 2))
        #: ∇u (from the committed state) that each RVE's current state was driven to
        self._reached = np.zeros((b, 2, 2))
        #: the ∇u of the last evaluation, per RVE (what the FEM commits)
        self._target = np.zeros((b, 2, 2))
        #: response of each RVE's current state (None until measured), and the committed one
        self._current: Homogenized | None = None
        self._committed_response: Homogenized | None = None
        #: why each RVE failed in the current evaluation ("" where it did not)
        self._reasons = np.full(b, "", dtype=object)
        #: the current evaluation's seconds by phase
        self._times = PhaseTimes()
        #: hold_tangent: whether it is on, and the tangent held (before the stress's spin)
        self._hold = False
        self._held: np.ndarray | None = None

    @property
    def n_rve(self) -> int:
        """Number of RVEs B."""
        return self.batch.n_rve

    def _drive(self, grad_u: np.ndarray, failed: np.ndarray, moving: np.ndarray,
               restart: bool = True) -> tuple[int, int, int] | None:
        """Drive the ``moving`` RVEs by ∇u (from the committed state when ``restart``, else
        from their current state); the others are left as they are. Marks RVEs that blow up,
        whose ∇u has no constant velocity gradient, or whose path would need more than
        ``max_steps`` DEM steps, in ``failed``. Returns the cost (DEM
        steps, RVE paths, particle-steps), or None when the batch did not come through (all
        RVEs are then back in their committed state)."""
        inverted = moving & ~has_real_logarithm(np.eye(2) + grad_u)
        self._mark(inverted & ~failed, FailureReason.CELL_INVERTED)
        failed |= inverted
        capped = moving & over_step_cap(grad_u, self.max_strain_per_step, self.min_steps,
                                        self.max_steps)
        self._mark(capped & ~failed, FailureReason.MAX_DEM_STEPS)
        failed |= capped
        moving = moving & ~failed
        with self._times.phase("dem"):
            if restart:
                self.batch.restore(self._committed, None if moving.all() else moving)
        if not moving.any():
            return 0, 0, 0
        grad_u = np.where(moving[:, None, None], grad_u, 0.0)
        steps = path_steps(grad_u, self.max_strain_per_step, self.min_steps, self.max_steps)
        try:
            with self._times.phase("dem"):
                dem_steps = drive_grad_u(self.batch, grad_u,
                                         max_strain_per_step=self.max_strain_per_step,
                                         min_steps=self.min_steps,
                                         active=None if moving.all() else moving,
                                         max_steps=self.max_steps)
        except DEMInstabilityError as exc:
            blown = np.zeros_like(failed)
            blown[np.asarray(exc.rve, dtype=int)] = True
            self._mark(blown & ~failed, instability_reason(exc.reasons))
            failed |= blown
            self._back_to_committed()
            return None
        return dem_steps, int(moving.sum()), int(steps[moving].sum()) * self.batch.n_disc

    def _mark(self, where: np.ndarray, reason: FailureReason) -> None:
        """Record ``reason`` for the RVEs ``where`` (those of this evaluation's failures)."""
        if where.any():
            self._reasons[where] = reason.value

    def _back_to_committed(self) -> None:
        self.batch.restore(self._committed)
        self._reached[:] = 0.0
        if self._committed_response is None and self.reuse_tol > 0:
            self._committed_response = self.batch.homogenize()  # the state itself, unstepped
        self._current = self._committed_response

    def _moving(self, target: np.ndarray, failed: np.ndarray) -> np.ndarray:
        """The RVEs that must be stepped for ``target``: all with reuse off or before any
        response is known; else those that moved by more than ``reuse_tol``. Driven on
        (``continue``), an RVE already at exactly ``target`` is not stepped either, so that
        evaluating the same ∇u twice gives the same answer."""
        if self._current is None:
            return ~failed
        change = np.abs(target - self._reached).max(axis=(1, 2))
        if self.reuse_tol > 0:
            return (change > self.reuse_tol) & ~failed
        if self.drive == "continue":
            return (change > 0) & ~failed
        return ~failed

    def _measure(self, moved: np.ndarray) -> Homogenized:
        """The current response: measured afresh for the ``moved`` RVEs, kept for the
        others."""
        with self._times.phase("homogenization"):
            if self._current is None or moved.all():
                return self.batch.homogenize()
            if not moved.any():
                return self._current
            return self._current.with_rves(moved, self.batch.homogenize(moved))

    def hold_tangent(self, hold: bool) -> None:
        """``hold``: the next evaluation measures the tangent and the later ones, up to the
        next commit or revert, return that one instead of measuring it again: no
        condensation (``condensed``, ``condensed-sticking``) and no four perturbed drives
        (``perturbation``), for a Newton driver that keeps the first tangent of an increment
        anyway. The other tangents cost nothing extra and are measured as always."""
        self._hold = bool(hold)
        self._held = None

    def evaluate(self, grad_u: np.ndarray) -> Evaluation:
        """Respond to ∇u [-] (B, 2, 2) since the commit: the RVEs that moved are driven to
        it, the others reused (see the class docstring); homogenised results."""
        self._trial = False
        self._times = PhaseTimes()
        finite = np.isfinite(grad_u).all(axis=(1, 2))
        self._reasons = np.full(self.n_rve, "", dtype=object)
        self._mark(~finite, FailureReason.NON_FINITE_INPUT)
        grad_u = np.where(finite[:, None, None], grad_u, 0.0)
        # with no lag this is grad_u exactly (the lag is exactly zero where no RVE was reused)
        target = grad_u + self.lag + grad_u @ self.lag
        failed = ~finite
        moving = self._moving(target, failed)
        drives: list[tuple[int, int, int]] = []  # DEM steps, RVE paths, particle-steps
        perturbed: list[np.ndarray] = []
        cost: tuple[int, int, int] | None = (0, 0, 0)
        held = self._held  # None unless a hold is on and its first tangent is measured
        if self.tangent == "perturbation" and moving.any() and held is None:
            size = np.maximum(self.perturbation * np.abs(target).max(axis=(1, 2)),
                              self.min_perturbation)
            for row, col in _COMPONENTS:
                g = target.copy()
                g[:, row, col] += size
                cost = self._drive(g, failed, moving)
                if cost is None:  # the evaluation has failed: the remaining runs are wasted
                    break
                drives.append(cost)
                sigma = np.full((self.n_rve, 2, 2), np.nan)
                with self._times.phase("homogenization"):
                    sigma[moving] = self.batch.homogenize(moving).stress
                perturbed.append(sigma)
        if cost is not None:
            if self.drive == "restart" or perturbed:
                cost = self._drive(target, failed, moving)
            else:  # from the current trial state, by the change since it
                eye = np.eye(2)
                change = (eye + target) @ np.linalg.inv(eye + self._reached) - eye
                cost = self._drive(change, failed, moving, restart=False)
        if cost is None:
            h = self._current if self._current is not None else self.batch.homogenize()
            return Evaluation(_nan_like(h), failed, *_totals(drives), drives=tuple(drives),
                              complete=False, reasons=self._reasons.copy(),
                              timings=self._times.as_dict())
        drives.append(cost)
        moved = moving & ~failed
        new = self._measure(moved)
        if perturbed:
            stress = np.asarray(new.stress, dtype=np.float64)
            tangent = np.array(new.tangent, dtype=np.float64, copy=True)
            for (row, col), sigma in zip(_COMPONENTS, perturbed, strict=True):
                tangent[moved, :, :, row, col] = ((sigma[moved] - stress[moved])
                                                  / size[moved, None, None])
            new = replace(new, tangent=tangent)
        if self.tangent in CONDENSED_SLIDING and moved.any() and held is None:
            with self._times.phase("tangent"):
                new = _with_condensed(self.batch, new, moved, CONDENSED_SLIDING[self.tangent])
        if held is not None:
            new = replace(new, tangent=held)
        elif self._hold and (self.tangent in CONDENSED_SLIDING
                             or self.tangent == "perturbation"):
            self._held = np.array(new.tangent, dtype=np.float64, copy=True)
        self._reached[moved] = target[moved]
        self._current = new
        self._target = target
        self._trial = True
        with self._times.phase("tangent"):
            response = self._response(new, target)
        return Evaluation(response, failed, *_totals(drives), drives=tuple(drives),
                          reasons=self._reasons.copy(), timings=self._times.as_dict())

    def _response(self, current: Homogenized, target: np.ndarray) -> Homogenized:
        """What the RVEs answer for ``target``: their current response, reused RVEs'
        corrected to first order when asked (σ + D : Δ∇u), with the objective tangent
        where it is chosen (the condensed one gets the stress's spin added: it is
        objective already, C:W = 0)."""
        if self.tangent == "objective" or self.tangent in CONDENSED_SLIDING:
            stress = np.asarray(current.stress, dtype=np.float64)
            symmetric = 0.5 * (stress + np.swapaxes(stress, 1, 2))
            tangent = (objective_tangent(current.tangent, symmetric)
                       if self.tangent == "objective"
                       else current.tangent + spin_tangent(symmetric))
            current = replace(current, tangent=tangent)
        if self.reuse_correction == "tangent":
            change = target - self._reached
            if change.any():
                stress = current.stress + np.einsum("bijkl,bkl->bij", current.tangent, change)
                current = replace(current, stress=stress)
        return current

    def commit(self) -> None:
        """Snapshot the state of the last successful evaluate as the committed state; the
        mismatch of reused RVEs becomes their lag."""
        if not self._trial:
            raise RuntimeError("commit() needs a successful evaluate() since the last commit")
        self._committed = self.batch.snapshot()
        reused = (self._target != self._reached).any(axis=(1, 2))
        self.lag[:] = 0.0
        if reused.any():
            eye = np.eye(2)
            self.lag[reused] = ((eye + self._target[reused])
                                @ np.linalg.inv(eye + self._reached[reused]) - eye)
        self._reached[:] = 0.0
        self._target[:] = 0.0
        self._committed_response = self._current
        self._trial = False
        self.hold_tangent(False)

    def revert(self) -> None:
        """Restore the committed state on the device."""
        self._back_to_committed()
        self._trial = False
        self.hold_tangent(False)

    def committed_rves(self, rves: np.ndarray | None = None) -> RVEData:
        """The committed RVE states (contact history included), of all RVEs or of the
        indices ``rves``; the trial state is kept."""
        trial = self.batch.snapshot()
        self.batch.restore(self._committed)
        try:
            data = self.batch.to_data()
        finally:
            self.batch.restore(trial)
        return data if rves is None else data.take(np.asarray(rves, dtype=int))

    def checkpoint_data(self) -> RVEData:
        """The committed state (contact history included) with what reuse and ``continue``
        carry between steps (each RVE's lag and committed response) as further arrays
        ``backend_*``: what :meth:`checkpoint` writes."""
        data = self.committed_rves()
        extra = dict(data.extra)
        extra["backend_lag"] = self.lag.copy()
        if self._committed_response is not None:
            for f in fields(self._committed_response):
                extra[f"backend_response_{f.name}"] = np.asarray(
                    getattr(self._committed_response, f.name))
        return replace(data, extra=extra)

    def checkpoint(self, path: str | Path) -> None:
        """Write :meth:`checkpoint_data` to the RVE file ``path``, so that
        :meth:`resume_from` continues exactly."""
        save_rve(path, self.checkpoint_data())

    def resume_from(self, data: RVEData) -> None:
        """Take the lag and committed response of a :meth:`checkpoint` file's ``data`` (its
        RVE states are the batch's already)."""
        if "backend_lag" in data.extra:
            self.lag[:] = data.extra["backend_lag"]
        names = [f.name for f in fields(Homogenized)]
        if all(f"backend_response_{n}" in data.extra for n in names):
            self._committed_response = Homogenized(
                **{n: np.array(data.extra[f"backend_response_{n}"]) for n in names})
        self._current = self._committed_response

    @staticmethod
    def without_backend_arrays(data: RVEData) -> RVEData:
        """``data`` less the ``backend_*`` arrays of a checkpoint (the RVE states alone)."""
        return replace(data, extra={k: v for k, v in data.extra.items()
                                    if not k.startswith("backend_")})
