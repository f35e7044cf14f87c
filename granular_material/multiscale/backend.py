"""The RVEs of a DEM material held in this process (:class:`InProcessBackend`).

A backend owns the RVEs of a material (one per Gauss point, batch-first) and offers what the
material needs: evaluate ∇u from the committed state, commit, revert, checkpoint. Between
evaluations it carries two values and nothing else: the :class:`Committed` side (the batch's
snapshot, each RVE's lag, the committed response) and the :class:`Trial` of the increment
under way (the ∇u each RVE's state was driven to, their response, a held tangent). ``commit``
makes the trial the committed side; ``revert`` drops it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from granular_material.dem import DEMBatch, DEMInstabilityError, Homogenized, RVEData, save_rve
from granular_material.dem.batch import REBASE_MARGIN as BATCH_REBASE_MARGIN
from granular_material.dem.condensed.dispatch import condense
from granular_material.fem.materials.protocol import FailureReason
from granular_material.multiscale.evaluation import (
    Evaluation,
    instability_reason,
    nan_like,
    totals,
)
from granular_material.multiscale.parameters import MIN_PERTURBATION, DEMDriving
from granular_material.procedures.strain_path import DEFAULT_MIN_STEPS, drive_planned, plan_drive
from granular_material.timing import PhaseTimes

__all__ = ["Committed", "InProcessBackend", "Trial"]

_COMPONENTS = ((0, 0), (0, 1), (1, 0), (1, 1))  # the (k, l) of ∂u_k/∂x_l
#: the margin of the committed cells' rebasing (:meth:`DEMBatch.rebase_thin_cells`)
REBASE_MARGIN = BATCH_REBASE_MARGIN


@dataclass(frozen=True)
class Committed:
    """The committed side of a backend.

    Attributes:
        snapshot: the batch's committed state (:meth:`DEMBatch.snapshot`).
        lag: F_lag − I [-] per RVE, (B, 2, 2): how far the FEM's committed configuration is
            ahead of a reused RVE's (zero where no RVE was reused).
        response: the response of the committed states; None until known.
    """

    snapshot: Any
    lag: np.ndarray
    response: Homogenized | None = None


@dataclass(frozen=True)
class Trial:
    """The increment under way.

    Attributes:
        reached: ∇u [-] (from the committed state) each RVE's current state was driven to,
            (B, 2, 2).
        target: the ∇u [-] of the last complete evaluation, per RVE (what the FEM commits).
        response: the response of each RVE's current state; None until measured.
        hold: the tangent is held over the increment (:meth:`InProcessBackend.hold_tangent`).
        held: the held tangent [Pa] (before the stress's spin), once measured.
        complete: the last evaluation completed, so that it can be committed.
    """

    reached: np.ndarray
    target: np.ndarray
    response: Homogenized | None = None
    hold: bool = False
    held: np.ndarray | None = None
    complete: bool = False


@dataclass
class _Work:
    """One evaluation's bookkeeping: which RVEs failed and why, the seconds by phase."""

    failed: np.ndarray
    reasons: np.ndarray
    times: PhaseTimes = field(default_factory=PhaseTimes)

    def fail(self, where: np.ndarray, reason: FailureReason) -> None:
        """The RVEs ``where`` fail for ``reason`` (those that had not failed already)."""
        new = where & ~self.failed
        if new.any():
            self.reasons[new] = reason.value
        self.failed |= where


class InProcessBackend:
    """All RVEs in one :class:`DEMBatch` of this process, driven as ``driving`` says.

    Reuse of undisturbed RVEs: the backend remembers, per RVE, the ∇u its state was last
    driven to (measured from its committed state) and the response there. An RVE whose new
    ∇u differs from that one by at most ``reuse_tol`` in every component is not stepped: it
    keeps its state and returns that response (``reuse_correction="tangent"``: plus its
    tangent times the difference). When a step commits, a reused RVE's committed state is the
    one it reached; the small mismatch to the ∇u the FEM committed is carried as the RVE's
    *lag* F_lag = (I + ∇u_FEM)(I + ∇u_RVE)⁻¹ and the next step drives it by
    (I + ∇u)·F_lag − I, so that no error accumulates over the steps. ``reuse_tol = 0`` steps
    every RVE at every evaluation, exactly as without reuse.

    The tangent is :attr:`DEMDriving.method`: the perturbation tangent drives four more runs
    from the committed state with ∇u + h E_kl, h = max(perturbation · max|∇u|,
    :data:`~granular_material.multiscale.parameters.MIN_PERTURBATION`) per RVE; the condensed
    ones condense each moved RVE's contact network on the batch's device
    (:func:`~granular_material.dem.condensed.dispatch.condense`).

    Args:
        batch: the RVEs, in their committed state.
        driving: how they are driven and measured (a :class:`DEMDriving` or any of its
            subclasses, e.g. the material's parameters); default: its defaults.
    """

    def __init__(self, batch: DEMBatch, driving: DEMDriving | None = None) -> None:
        self.batch = batch
        self.driving = DEMDriving() if driving is None else driving
        self._committed = Committed(batch.snapshot(), np.zeros((batch.n_rve, 2, 2)))
        self._trial = self._fresh_trial()

    @classmethod
    def holding(cls, data: RVEData, driving: DEMDriving, device: str | None,
                shards: int | None, resume: bool = False) -> InProcessBackend:
        """The RVEs ``data`` in one batch on ``device`` with ``shards`` CPU threads; with
        ``resume``, ``data`` is a :meth:`checkpoint`'s and the backend continues from it."""
        states = cls.without_backend_arrays(data) if resume else data
        backend = cls(DEMBatch(states, device=device, shards=shards), driving)
        if resume:
            backend.resume_from(data)
        return backend

    @property
    def n_rve(self) -> int:
        """Number of RVEs B."""
        return self.batch.n_rve

    @property
    def committed(self) -> Committed:
        """The committed side (read-only)."""
        return self._committed

    @property
    def trial(self) -> Trial:
        """The increment under way (read-only)."""
        return self._trial

    @property
    def lag(self) -> np.ndarray:
        """F_lag − I [-] per RVE, (B, 2, 2): see the class docstring."""
        return self._committed.lag

    def _fresh_trial(self) -> Trial:
        zeros = np.zeros((self.n_rve, 2, 2))
        return Trial(zeros, zeros.copy(), self._committed.response)

    def _drive(self, grad_u: np.ndarray, moving: np.ndarray, work: _Work,
               restart: bool = True) -> tuple[int, int, int] | None:
        """Drive the ``moving`` RVEs that have not failed by ∇u (from the committed state when
        ``restart``, else from their current state), planned once (:func:`plan_drive`): an
        RVE whose ∇u has no constant velocity gradient, or whose path needs more than
        ``max_dem_steps`` steps, fails instead. Returns the cost (DEM steps, RVE paths,
        particle-steps), or None when the batch did not come through (every RVE is then back
        in its committed state)."""
        d = self.driving
        plan = plan_drive(grad_u, moving & ~work.failed, d.max_strain_per_step,
                          DEFAULT_MIN_STEPS, d.max_dem_steps)
        work.fail(plan.inverted, FailureReason.CELL_INVERTED)
        work.fail(plan.capped, FailureReason.MAX_DEM_STEPS)
        driven = plan.driven
        with work.times.phase("dem"):
            if restart:
                self.batch.restore(self._committed.snapshot, None if driven.all() else driven)
        if not driven.any():
            return 0, 0, 0
        try:
            with work.times.phase("dem"):
                dem_steps = drive_planned(self.batch, plan)
        except DEMInstabilityError as exc:
            blown = np.zeros_like(work.failed)
            blown[np.asarray(exc.rve, dtype=int)] = True
            work.fail(blown, instability_reason(exc.reasons))
            self._back_to_committed()
            return None
        return dem_steps, int(driven.sum()), plan.particle_steps(self.batch.n_disc)

    def _back_to_committed(self) -> None:
        """The batch back in its committed state, the trial's states with it."""
        self.batch.restore(self._committed.snapshot)
        if self._committed.response is None and self.driving.reuse_tol > 0:
            # the state itself, unstepped
            self._committed = replace(self._committed, response=self.batch.homogenize())
        self._trial = replace(self._trial, reached=np.zeros((self.n_rve, 2, 2)),
                              response=self._committed.response)

    def _moving(self, target: np.ndarray, failed: np.ndarray) -> np.ndarray:
        """The RVEs that must be stepped for ``target``: all with reuse off or before any
        response is known; else those that moved by more than ``reuse_tol``. Driven on
        (``continue``), an RVE already at exactly ``target`` is not stepped either, so that
        evaluating the same ∇u twice gives the same answer."""
        trial = self._trial
        if trial.response is None:
            return ~failed
        change = np.abs(target - trial.reached).max(axis=(1, 2))
        if self.driving.reuse_tol > 0:
            return (change > self.driving.reuse_tol) & ~failed
        if self.driving.drive == "continue":
            return (change > 0) & ~failed
        return ~failed

    def _measure(self, moved: np.ndarray, times: PhaseTimes) -> Homogenized:
        """The current response: measured afresh for the ``moved`` RVEs, kept for the
        others."""
        current = self._trial.response
        with times.phase("homogenization"):
            if current is None or moved.all():
                return self.batch.homogenize()
            if not moved.any():
                return current
            return current.with_rves(moved, self.batch.homogenize(moved))

    def hold_tangent(self, hold: bool) -> None:
        """``hold``: the next evaluation measures the tangent and the later ones, up to the
        next commit or revert, return that one instead of measuring it again: no
        condensation (``condensed``, ``condensed-sticking``) and no four perturbed drives
        (``perturbation``), for a Newton driver that keeps the first tangent of an increment
        anyway. The other tangents cost nothing extra and are measured as always."""
        self._trial = replace(self._trial, hold=bool(hold), held=None)

    def _perturbed(self, target: np.ndarray, moving: np.ndarray, work: _Work,
                   drives: list[tuple[int, int, int]]) -> tuple[list[np.ndarray], np.ndarray]:
        """The stresses [Pa] of the four perturbed drives from the committed state (∇u + h
        E_kl) and h per RVE; fewer than four when a drive failed (the batch is then back in
        its committed state)."""
        size = np.maximum(self.driving.perturbation * np.abs(target).max(axis=(1, 2)),
                          MIN_PERTURBATION)
        perturbed: list[np.ndarray] = []
        for row, col in _COMPONENTS:
            g = target.copy()
            g[:, row, col] += size
            cost = self._drive(g, moving, work)
            if cost is None:  # the evaluation has failed: the remaining runs are wasted
                return perturbed, size
            drives.append(cost)
            sigma = np.full((self.n_rve, 2, 2), np.nan)
            with work.times.phase("homogenization"):
                sigma[moving] = self.batch.homogenize(moving).stress
            perturbed.append(sigma)
        return perturbed, size

    def evaluate(self, grad_u: np.ndarray) -> Evaluation:
        """Respond to ∇u [-] (B, 2, 2) since the commit: the RVEs that moved are driven to
        it, the others reused (see the class docstring); homogenised results."""
        method = self.driving.method
        self._trial = replace(self._trial, complete=False)
        trial = self._trial
        finite = np.isfinite(grad_u).all(axis=(1, 2))
        work = _Work(np.zeros(self.n_rve, dtype=bool), np.full(self.n_rve, "", dtype=object))
        work.fail(~finite, FailureReason.NON_FINITE_INPUT)
        grad_u = np.where(finite[:, None, None], grad_u, 0.0)
        # with no lag this is grad_u exactly (the lag is exactly zero where no RVE was reused)
        lag = self._committed.lag
        target = grad_u + lag + grad_u @ lag
        moving = self._moving(target, work.failed)
        drives: list[tuple[int, int, int]] = []  # DEM steps, RVE paths, particle-steps
        perturbed: list[np.ndarray] = []
        complete = True
        if method.perturbed and moving.any() and trial.held is None:
            perturbed, size = self._perturbed(target, moving, work, drives)
            complete = len(perturbed) == len(_COMPONENTS)
        cost: tuple[int, int, int] | None = None
        if complete:
            if self.driving.drive == "restart" or perturbed:
                cost = self._drive(target, moving, work)
            else:  # from the current trial state, by the change since it
                eye = np.eye(2)
                change = (eye + target) @ np.linalg.inv(eye + trial.reached) - eye
                cost = self._drive(change, moving, work, restart=False)
        if cost is None:
            current = self._trial.response
            h = current if current is not None else self.batch.homogenize()
            return Evaluation(nan_like(h), work.failed, *totals(drives), drives=tuple(drives),
                              complete=False, reasons=work.reasons.copy(),
                              timings=work.times.as_dict())
        drives.append(cost)
        moved = moving & ~work.failed
        new = self._measure(moved, work.times)
        if perturbed:
            stress = np.asarray(new.stress, dtype=np.float64)
            tangent = np.array(new.tangent, dtype=np.float64, copy=True)
            for (row, col), sigma in zip(_COMPONENTS, perturbed, strict=True):
                tangent[moved, :, :, row, col] = ((sigma[moved] - stress[moved])
                                                  / size[moved, None, None])
            new = replace(new, tangent=tangent)
        held = trial.held
        if method.condensed and moved.any() and held is None:
            with work.times.phase("tangent"):
                tangent = np.array(new.tangent, dtype=np.float64, copy=True)
                tangent[moved] = condense(self.batch, np.flatnonzero(moved), method.sliding)
                new = replace(new, tangent=tangent)
        if held is not None:
            new = replace(new, tangent=held)
        elif trial.hold and method.holdable:
            held = np.array(new.tangent, dtype=np.float64, copy=True)
        reached = trial.reached.copy()
        reached[moved] = target[moved]
        self._trial = Trial(reached, target, new, trial.hold, held, complete=True)
        with work.times.phase("tangent"):
            response = self._response(new, target, reached)
        return Evaluation(response, work.failed, *totals(drives), drives=tuple(drives),
                          reasons=work.reasons.copy(), timings=work.times.as_dict())

    def _response(self, current: Homogenized, target: np.ndarray,
                  reached: np.ndarray) -> Homogenized:
        """What the RVEs answer for ``target``: their current response with the tangent
        finished by its method (the stress's spin), reused RVEs' corrected to first order
        when asked (σ + D : Δ∇u, Δ∇u = target − reached)."""
        method = self.driving.method
        if method.spin != "none":
            current = replace(current, tangent=method.finish(current.tangent, current.stress))
        if self.driving.reuse_correction == "tangent":
            change = target - reached
            if change.any():
                stress = current.stress + np.einsum("bijkl,bkl->bij", current.tangent, change)
                current = replace(current, stress=stress)
        return current

    def commit(self) -> None:
        """The trial becomes the committed side: the batch's current state, its response, and
        the mismatch of reused RVEs as their lag."""
        trial = self._trial
        if not trial.complete:
            raise RuntimeError("commit() needs a successful evaluate() since the last commit")
        reused = (trial.target != trial.reached).any(axis=(1, 2))
        lag = np.zeros((self.n_rve, 2, 2))
        if reused.any():
            eye = np.eye(2)
            lag[reused] = ((eye + trial.target[reused])
                           @ np.linalg.inv(eye + trial.reached[reused]) - eye)
        # a cell sheared near the engine's limit takes its least skewed basis (the same
        # packing), so that the soil shears on (beside a footing's edge, in a band)
        self.batch.rebase_thin_cells(REBASE_MARGIN)
        self._committed = Committed(self.batch.snapshot(), lag, trial.response)
        self._trial = self._fresh_trial()

    def revert(self) -> None:
        """Drop the trial: every RVE back in its committed state."""
        self._back_to_committed()
        self._trial = self._fresh_trial()

    def committed_rves(self, rves: np.ndarray | None = None) -> RVEData:
        """The committed RVE states (contact history included), of all RVEs or of the
        indices ``rves``; the trial state is kept."""
        trial = self.batch.snapshot()
        self.batch.restore(self._committed.snapshot)
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
        extra["backend_lag"] = self._committed.lag.copy()
        response = self._committed.response
        if response is not None:
            for f in fields(response):
                extra[f"backend_response_{f.name}"] = np.asarray(getattr(response, f.name))
        return replace(data, extra=extra)

    def checkpoint(self, path: str | Path) -> None:
        """Write :meth:`checkpoint_data` to the RVE file ``path``, so that
        :meth:`resume_from` continues exactly."""
        save_rve(path, self.checkpoint_data())

    def resume_from(self, data: RVEData) -> None:
        """Take the lag and committed response of a :meth:`checkpoint` file's ``data`` (its
        RVE states are the batch's already)."""
        committed = self._committed
        if "backend_lag" in data.extra:
            committed = replace(committed, lag=np.array(data.extra["backend_lag"],
                                                        dtype=np.float64))
        names = [f.name for f in fields(Homogenized)]
        if all(f"backend_response_{n}" in data.extra for n in names):
            committed = replace(committed, response=Homogenized(
                **{n: np.array(data.extra[f"backend_response_{n}"]) for n in names}))
        self._committed = committed
        self._trial = replace(self._trial, response=committed.response)

    @staticmethod
    def without_backend_arrays(data: RVEData) -> RVEData:
        """``data`` less the ``backend_*`` arrays of a checkpoint (the RVE states alone)."""
        return replace(data, extra={k: v for k, v in data.extra.items()
                                    if not k.startswith("backend_")})
