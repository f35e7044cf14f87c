"""DEMMaterial: one periodic DEM RVE per Gauss point as a constitutive model.

The material is driven by the displacement gradient since its last commit (the
strain-driven protocol of Guo & Zhao 2014): every RVE is restored to its committed state,
deformed by ∇u over n = max(⌈max|∇u| / 1e-5⌉, 2) DEM steps, and homogenised into the Love
stress σ = (1/V) Σ_c f^c ⊗ d^c and the Kruyt–Rothenburg tangent
D = (1/V) Σ_c (k_n n⊗d⊗n⊗d + k_t t⊗d⊗t⊗d) (Wu, Fu & Zhou 2025, eqs. 5–6).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from granular_material_skfem.adapter import TANGENTS, InProcessBackend

from granular_material.dem import DEMBatch, RVEData, load_rve
from granular_material.fem.material import MaterialResponse, PointStatus
from granular_material.procedures import prepare_packing

__all__ = ["DEMMaterial", "DEMMaterialParameters"]


@dataclass(frozen=True)
class DEMMaterialParameters:
    """How the RVEs of a :class:`DEMMaterial` are made and driven.

    Attributes:
        rve: RVE file to load (B = 1, or B = number of Gauss points); None: prepare packings.
        particles: discs per prepared RVE (ignored with ``rve``), >= 4.
        seed: seed of the first prepared RVE; RVE p uses seed + p (independent packings).
        pressure: isotropic consolidation pressure of prepared RVEs [Pa], > 0.
        replicate: one RVE (the first of the file, or one prepared with ``seed``) copied to
            every Gauss point.
        device: "cpu", "cuda" or None (CUDA when present).
        max_strain_per_step: largest strain per DEM step while driving ∇u [-].
        min_steps: fewest DEM steps per evaluation.
        shards: CPU shards (threads) of the batch; None: the engine's default (one per
            core). With 1, independent RVEs are also prepared one at a time (RVE p from the
            random gas of seed + p, consolidated on its own).
        tangent: "kruyt-rothenburg" (Wu et al. eq. 6) or "perturbation" (forward
            differences of the RVE response, four extra DEM runs per evaluation; see
            :class:`~granular_material_skfem.adapter.InProcessBackend`).
        perturbation: relative perturbation of ∇u for the "perturbation" tangent [-].
    """

    rve: str | None = None
    particles: int = 400
    seed: int = 1
    pressure: float = 100.0e3
    replicate: bool = False
    device: str | None = None
    max_strain_per_step: float = 1.0e-5
    min_steps: int = 2
    shards: int | None = None
    tangent: str = "kruyt-rothenburg"
    perturbation: float = 0.1

    def __post_init__(self) -> None:
        if self.tangent not in TANGENTS:
            raise ValueError(f"tangent must be one of {', '.join(TANGENTS)}, got {self.tangent!r}")
        if not (math.isfinite(self.perturbation) and self.perturbation > 0):
            raise ValueError(f"perturbation must be > 0, got {self.perturbation!r}")
        if self.shards is not None and (int(self.shards) != self.shards or self.shards < 1):
            raise ValueError(f"shards must be an integer >= 1 or None, got {self.shards!r}")
        if int(self.particles) != self.particles or self.particles < 4:
            raise ValueError(f"particles must be an integer >= 4, got {self.particles!r}")
        if not (math.isfinite(self.pressure) and self.pressure > 0):
            raise ValueError(f"pressure must be a positive number of Pa, got {self.pressure!r}")
        if self.device not in (None, "cpu", "cuda") and not str(self.device).startswith("cuda:"):
            raise ValueError(f"device must be 'cpu', 'cuda' or None, got {self.device!r}")
        if not (math.isfinite(self.max_strain_per_step) and self.max_strain_per_step > 0):
            raise ValueError(
                f"max_strain_per_step must be positive, got {self.max_strain_per_step!r}"
            )
        if self.min_steps < 1:
            raise ValueError(f"min_steps must be >= 1, got {self.min_steps!r}")


class DEMMaterial:
    """The DEM material: owns one RVE batch, one RVE per Gauss point (batch-first)."""

    def __init__(self, rve: str | Path | None = None, particles: int = 400, seed: int = 1,
                 pressure: float = 100.0e3, replicate: bool = False,
                 device: str | None = None, max_strain_per_step: float = 1.0e-5,
                 min_steps: int = 2, shards: int | None = None,
                 progress: bool = False, tangent: str = "kruyt-rothenburg",
                 perturbation: float = 0.1) -> None:
        self.parameters = DEMMaterialParameters(
            None if rve is None else str(rve), particles, seed, pressure, replicate, device,
            max_strain_per_step, min_steps, shards, tangent, perturbation,
        )
        self.progress = progress
        self.backend: InProcessBackend | None = None

    @property
    def n_points(self) -> int:
        """Number of Gauss points (RVEs) allocated."""
        return 0 if self.backend is None else self.backend.n_rve

    @property
    def batch(self) -> DEMBatch:
        """The RVE batch (after :meth:`allocate`)."""
        if self.backend is None:
            raise RuntimeError("allocate() the DEM material first")
        return self.backend.batch

    def _backend(self, batch: DEMBatch) -> InProcessBackend:
        p = self.parameters
        return InProcessBackend(batch, p.max_strain_per_step, p.min_steps, tangent=p.tangent,
                                perturbation=p.perturbation)

    def allocate(self, n_points: int) -> None:
        """Load or prepare ``n_points`` RVEs in their consolidated state."""
        p = self.parameters
        if n_points < 1:
            raise ValueError(f"n_points must be >= 1, got {n_points}")
        if p.rve is not None:
            data = load_rve(p.rve)
            if p.replicate or data.n_rve == 1:
                data = data.replicate(n_points)
            elif data.n_rve != n_points:
                raise ValueError(
                    f"rve file {p.rve} holds {data.n_rve} RVEs; {n_points} Gauss points need "
                    f"1 (replicated) or {n_points}"
                )
        elif p.replicate:
            data = self._prepare(1, p.seed).replicate(n_points)
        elif p.shards == 1:
            data = _concatenate([self._prepare(1, p.seed + k) for k in range(n_points)])
        else:
            data = self._prepare(n_points, p.seed)
        self.backend = self._backend(DEMBatch(data, device=p.device, shards=p.shards))

    def _prepare(self, n_rve: int, seed: int) -> RVEData:
        p = self.parameters
        batch = prepare_packing(n_disc=p.particles, n_rve=n_rve, seed=seed, pressure=p.pressure,
                                device=p.device, progress=self.progress)
        return batch.to_data()

    def evaluate(self, grad_u: np.ndarray) -> MaterialResponse:
        """Love stress and Kruyt–Rothenburg tangent for ∇u (n, 2, 2) since the commit.

        ``work`` is the number of DEM steps run; ``fields`` holds ``void_ratio`` and
        ``coordination``. RVEs that blew up are reported with ``PointStatus.FAILED``.
        """
        if self.backend is None:
            raise RuntimeError("allocate() the DEM material before evaluate()")
        grad_u = np.asarray(grad_u, dtype=np.float64)
        if grad_u.shape != (self.n_points, 2, 2):
            raise ValueError(f"grad_u must have shape ({self.n_points}, 2, 2), got {grad_u.shape}")
        ev = self.backend.evaluate(grad_u)
        status = np.where(ev.failed, PointStatus.FAILED, PointStatus.OK).astype(np.int8)
        return MaterialResponse(
            stress=ev.stress, tangent=ev.tangent, status=status, work=ev.steps,
            fields={"void_ratio": ev.void_ratio, "coordination": ev.coordination},
        )

    def commit(self) -> None:
        """The RVE states of the last evaluation become the committed states."""
        self.batch  # noqa: B018 - raises before allocate
        self.backend.commit()

    def revert(self) -> None:
        """Every RVE back to its committed state."""
        if self.backend is not None:
            self.backend.revert()

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed RVE states (an RVE file, B = n_points) to ``path``."""
        self.batch  # noqa: B018 - raises before allocate
        self.backend.checkpoint(path)

    def restore(self, path: str | Path) -> None:
        """Load committed RVE states written by :meth:`checkpoint`."""
        p = self.parameters
        self.backend = self._backend(DEMBatch(load_rve(path), device=p.device, shards=p.shards))


def _concatenate(parts: list[RVEData]) -> RVEData:
    """One batch from several (same meta; extra arrays concatenated along the batch axis)."""
    first = parts[0]

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(d, name) for d in parts])

    return replace(
        first, radius=cat("radius"), position=cat("position"), cell=cat("cell"),
        velocity=cat("velocity"), angular_velocity=cat("angular_velocity"),
        extra={k: np.concatenate([d.extra[k] for d in parts]) for k in first.extra},
    )
