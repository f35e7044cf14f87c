"""The DEM backend behind :class:`~granular_material_skfem.material.DEMMaterial`.

A backend owns the RVEs of a material (one per Gauss point, batch-first) and offers what
the material needs: evaluate ∇u from the committed state, commit, revert, checkpoint.
:class:`InProcessBackend` keeps the whole :class:`~granular_material.dem.DEMBatch` in this
process (CPU shards or one CUDA device); a backend that spreads shards over MPI ranks
would implement the same four calls.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from granular_material.dem import DEMBatch, DEMInstabilityError, load_rve, save_rve
from granular_material.procedures import drive_grad_u, has_real_logarithm

__all__ = ["TANGENTS", "DEMBackend", "DEMEvaluation", "InProcessBackend"]

TANGENTS = ("kruyt-rothenburg", "perturbation")
_COMPONENTS = ((0, 0), (0, 1), (1, 0), (1, 1))  # the (k, l) of ∂u_k/∂x_l


@dataclass(frozen=True)
class DEMEvaluation:
    """Homogenised response of the RVEs after one strain path.

    Attributes:
        stress: Love stress [Pa], tension positive, shape (B, 2, 2).
        tangent: Kruyt–Rothenburg tangent dσ_ij/d(∂u_k/∂x_l) [Pa], shape (B, 2, 2, 2, 2).
        failed: RVEs whose state blew up or whose ∇u inverts the cell, shape (B,), bool.
        steps: DEM steps run (the longest strain path of the batch).
        void_ratio: 2D void ratio [-], shape (B,).
        coordination: coordination number [-], shape (B,).
    """

    stress: np.ndarray
    tangent: np.ndarray
    failed: np.ndarray
    steps: int
    void_ratio: np.ndarray
    coordination: np.ndarray


class DEMBackend(Protocol):
    """What the DEM material asks of whoever holds its RVEs."""

    n_rve: int

    def evaluate(self, grad_u: np.ndarray) -> DEMEvaluation:
        """Deform every RVE from its committed state by ∇u (B, 2, 2) and homogenise."""
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
        if tangent not in TANGENTS:
            raise ValueError(f"tangent must be one of {', '.join(TANGENTS)}, got {tangent!r}")
        if not (perturbation > 0 and min_perturbation > 0):
            raise ValueError("perturbation and min_perturbation must be > 0, got "
                             f"{perturbation!r}, {min_perturbation!r}")
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

    @classmethod
    def from_file(cls, path: str | Path, device: str | None = None,
                  **kwargs: float) -> InProcessBackend:
        """A backend holding the RVE batch of ``path`` (written by :meth:`checkpoint`)."""
        return cls(DEMBatch(load_rve(path), device=device), **kwargs)

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

    def evaluate(self, grad_u: np.ndarray) -> DEMEvaluation:
        """Restore the committed state, apply ∇u [-] (B, 2, 2), homogenise."""
        b = self.n_rve
        self._trial = False
        finite = np.isfinite(grad_u).all(axis=(1, 2))
        grad_u = np.where(finite[:, None, None], grad_u, 0.0)
        failed = ~finite
        work, perturbed, ok = 0, [], True
        if self.tangent == "perturbation":
            size = np.maximum(self.perturbation * np.abs(grad_u).max(axis=(1, 2)),
                              self.min_perturbation)
            for row, col in _COMPONENTS:
                g = grad_u.copy()
                g[:, row, col] += size
                steps, ok = self._drive(g, failed)
                work += steps
                if not ok:  # the evaluation has failed: the remaining runs are wasted work
                    break
                perturbed.append(self.batch.homogenize().stress)
        if ok:
            steps, ok = self._drive(grad_u, failed)
            work += steps
        if not ok:
            nan = np.full(b, np.nan)
            return DEMEvaluation(np.full((b, 2, 2), np.nan), np.full((b, 2, 2, 2, 2), np.nan),
                                 failed, work, nan, nan.copy())
        h = self.batch.homogenize()
        stress = np.asarray(h.stress, dtype=np.float64)
        tangent = np.asarray(h.tangent, dtype=np.float64)
        if perturbed:
            tangent = np.empty_like(tangent)
            for (row, col), sigma in zip(_COMPONENTS, perturbed, strict=True):
                tangent[:, :, :, row, col] = (sigma - stress) / size[:, None, None]
        self._trial = True
        return DEMEvaluation(stress, tangent, failed, work,
                             np.asarray(h.void_ratio, dtype=np.float64),
                             np.asarray(h.coordination, dtype=np.float64))

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

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed state (contact history included) to the RVE file ``path``."""
        trial = self.batch.snapshot()
        self.batch.restore(self._committed)
        try:
            save_rve(path, self.batch.to_data())
        finally:
            self.batch.restore(trial)
