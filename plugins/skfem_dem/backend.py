"""The DEM backend behind :class:`~granular_material_skfem.material.DEMMaterial`.

A backend owns the RVEs of a material (one per Gauss point, batch-first) and offers what
the material needs: evaluate ∇u from the committed state, commit, revert, checkpoint.
:class:`InProcessBackend` keeps the whole :class:`~granular_material.dem.DEMBatch` in this
process (CPU shards or one CUDA device); a backend that spreads shards over MPI ranks
would implement the same four calls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from granular_material.dem import DEMBatch, DEMInstabilityError, Homogenized, RVEData, save_rve
from granular_material.procedures import drive_grad_u, has_real_logarithm

__all__ = ["TANGENTS", "DEMBackend", "Evaluation", "InProcessBackend", "check_driving"]

TANGENTS = ("kruyt-rothenburg", "perturbation")
_COMPONENTS = ((0, 0), (0, 1), (1, 0), (1, 1))  # the (k, l) of ∂u_k/∂x_l


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


@dataclass(frozen=True)
class Evaluation:
    """What one evaluation of the RVEs gave.

    Attributes:
        homogenized: the homogenised RVEs (stress, tangent, void ratio, ... of
            :class:`~granular_material.dem.Homogenized`); with the "perturbation" tangent its
            ``tangent`` is the forward-difference one. NaN throughout when the batch failed.
        failed: RVEs whose state blew up or whose ∇u inverts the cell, shape (B,), bool.
        dem_steps: DEM steps run, all strain paths of the evaluation together.
    """

    homogenized: Homogenized
    failed: np.ndarray
    dem_steps: int


def _nan_like(h: Homogenized) -> Homogenized:
    return Homogenized(**{f.name: np.full_like(np.asarray(getattr(h, f.name), dtype=np.float64),
                                               np.nan) for f in fields(h)})


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

    Args:
        batch: the RVEs, in their committed state.
        max_strain_per_step: largest strain component per DEM step (Guo & Zhao: 1e-5).
        min_steps: fewest DEM steps per evaluation.
        tangent: "kruyt-rothenburg" (the contact-network estimate, one DEM run per
            evaluation) or "perturbation" (the derivative of the RVE's own response to ∇u by
            forward differences: four more runs from the committed state, with ∇u + h E_kl,
            h = max(perturbation · max|∇u|, min_perturbation) per RVE).
        perturbation: relative size of the perturbation [-].
        min_perturbation: smallest perturbation [-].
    """

    def __init__(self, batch: DEMBatch, max_strain_per_step: float = 1.0e-5,
                 min_steps: int = 2, tangent: str = "kruyt-rothenburg",
                 perturbation: float = 0.1, min_perturbation: float = 1.0e-4) -> None:
        check_driving(tangent, perturbation, min_perturbation, max_strain_per_step, min_steps)
        self.batch = batch
        self.max_strain_per_step = max_strain_per_step
        self.min_steps = min_steps
        self.tangent = tangent
        self.perturbation, self.min_perturbation = perturbation, min_perturbation
        self._committed = batch.snapshot()
        self._trial = False

    @property
    def n_rve(self) -> int:
        """Number of RVEs B."""
        return self.batch.n_rve

    def _drive(self, grad_u: np.ndarray, failed: np.ndarray) -> tuple[int, bool]:
        """From the committed state, drive ∇u (failed RVEs held still); marks RVEs that blow
        up, or whose ∇u has no constant velocity gradient, in ``failed``. Returns (DEM steps,
        whether the batch came through)."""
        failed |= ~has_real_logarithm(np.eye(2) + grad_u)
        self.batch.restore(self._committed)
        try:
            steps = drive_grad_u(self.batch, np.where(failed[:, None, None], 0.0, grad_u),
                                 max_strain_per_step=self.max_strain_per_step,
                                 min_steps=self.min_steps)
        except DEMInstabilityError as exc:
            failed[np.asarray(exc.rve, dtype=int)] = True
            self.batch.restore(self._committed)
            return 0, False
        return steps, True

    def evaluate(self, grad_u: np.ndarray) -> Evaluation:
        """Restore the committed state, apply ∇u [-] (B, 2, 2), homogenise."""
        self._trial = False
        finite = np.isfinite(grad_u).all(axis=(1, 2))
        grad_u = np.where(finite[:, None, None], grad_u, 0.0)
        failed = ~finite
        dem_steps, perturbed, ok = 0, [], True
        if self.tangent == "perturbation":
            size = np.maximum(self.perturbation * np.abs(grad_u).max(axis=(1, 2)),
                              self.min_perturbation)
            for row, col in _COMPONENTS:
                g = grad_u.copy()
                g[:, row, col] += size
                steps, ok = self._drive(g, failed)
                dem_steps += steps
                if not ok:  # the evaluation has failed: the remaining runs are wasted work
                    break
                perturbed.append(self.batch.homogenize().stress)
        if ok:
            steps, ok = self._drive(grad_u, failed)
            dem_steps += steps
        h = self.batch.homogenize()
        if not ok:
            return Evaluation(_nan_like(h), failed, dem_steps)
        if perturbed:
            stress = np.asarray(h.stress, dtype=np.float64)
            tangent = np.empty(h.tangent.shape)
            for (row, col), sigma in zip(_COMPONENTS, perturbed, strict=True):
                tangent[:, :, :, row, col] = (sigma - stress) / size[:, None, None]
            h = replace(h, tangent=tangent)
        self._trial = True
        return Evaluation(h, failed, dem_steps)

    def commit(self) -> None:
        """Snapshot the state of the last successful evaluate as the committed state."""
        if not self._trial:
            raise RuntimeError("commit() needs a successful evaluate() since the last commit")
        self._committed = self.batch.snapshot()
        self._trial = False

    def revert(self) -> None:
        """Restore the committed state on the device."""
        self.batch.restore(self._committed)
        self._trial = False

    def committed_rves(self) -> RVEData:
        """The committed RVE states (contact history included); the trial state is kept."""
        trial = self.batch.snapshot()
        self.batch.restore(self._committed)
        try:
            return self.batch.to_data()
        finally:
            self.batch.restore(trial)

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed state (contact history included) to the RVE file ``path``."""
        save_rve(path, self.committed_rves())
