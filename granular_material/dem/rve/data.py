"""The data model of an RVE batch: B periodic RVEs of N discs each as host (numpy) arrays,
with its meta and any further arrays (docs/design.md#rve-file)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from granular_material.dem.rve.format import _BATCH_ARRAYS, RVEMeta

__all__ = ["RVEData"]


@dataclass(frozen=True)
class RVEData:
    """A batch of B periodic RVEs of N discs each, as host (numpy) arrays.

    Attributes:
        radius: disc radii [m], shape (B, N), float64.
        position: disc centres [m], Cartesian inside the cell, shape (B, N, 2), float64.
        cell: cell matrices H [m] (columns = cell vectors), shape (B, 2, 2), float64.
        velocity: fluctuating velocities [m/s], shape (B, N, 2), float64.
        angular_velocity: [rad/s], shape (B, N), float64.
        meta: material and run parameters.
        extra: further arrays (contact history), passed through unchanged.
    """

    radius: np.ndarray
    position: np.ndarray
    cell: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    meta: RVEMeta = field(default_factory=RVEMeta)
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def n_rve(self) -> int:
        """Number of RVEs B in the batch."""
        return int(self.radius.shape[0])

    @property
    def n_disc(self) -> int:
        """Number of discs N per RVE."""
        return int(self.radius.shape[1])

    def select(self, index: int) -> RVEData:
        """The single RVE ``index`` as a batch of one (extra arrays are dropped)."""
        if not -self.n_rve <= index < self.n_rve:
            raise IndexError(f"rve index {index} out of range for a batch of {self.n_rve}")
        sl = slice(index, index + 1) if index != -1 else slice(-1, None)
        return RVEData(
            self.radius[sl], self.position[sl], self.cell[sl], self.velocity[sl],
            self.angular_velocity[sl], self.meta,
        )

    def _arrays(self) -> dict[str, np.ndarray]:
        """Every per-RVE array of the core format (batch axis first)."""
        return {name: getattr(self, name) for name in _BATCH_ARRAYS}

    def take(self, rves: slice | np.ndarray | list[int]) -> RVEData:
        """The RVEs ``rves`` (a slice or indices) as a batch, contact history included."""
        return replace(self, **{k: v[rves] for k, v in self._arrays().items()},
                       extra={k: v[rves] for k, v in self.extra.items()})

    def replicate(self, n_rve: int) -> RVEData:
        """A batch of ``n_rve`` copies of RVE 0 (contact history included)."""
        if n_rve < 1:
            raise ValueError(f"n_rve must be >= 1, got {n_rve}")
        return self.take(np.zeros(n_rve, dtype=np.int64))

    @staticmethod
    def concatenate(parts: list[RVEData]) -> RVEData:
        """One batch of the RVEs of ``parts`` in order; the meta (and the set of extra
        arrays) of the first part is kept."""
        if not parts:
            raise ValueError("concatenate needs at least one RVEData")
        first = parts[0]
        arrays = {k: np.concatenate([getattr(p, k) for p in parts]) for k in _BATCH_ARRAYS}
        extra = {k: np.concatenate([p.extra[k] for p in parts]) for k in first.extra}
        return replace(first, **arrays, extra=extra)

