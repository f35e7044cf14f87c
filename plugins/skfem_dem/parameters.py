"""How the RVEs of the DEM material are made and driven (:class:`DEMMaterialParameters`),
and one in-process batch built from them: what both the material and its MPI workers use."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from granular_material_skfem.backend import (
    MIN_PERTURBATION,
    InProcessBackend,
    check_driving,
    check_reuse,
)

from granular_material.dem import DEMBatch, RVEData, resolve_device
from granular_material.procedures.packing import (
    DEFAULT_DISCS,
    DEFAULT_PRESSURE,
    PackingParameters,
    min_discs,
)
from granular_material.procedures.strain_path import DEFAULT_MIN_STEPS, DEFAULT_STRAIN_PER_STEP

__all__ = ["BACKENDS", "DEMMaterialParameters", "in_process_backend"]

#: who holds the RVEs: this process (``inprocess``), or contiguous shards of them on the ranks
#: of an MPI job (``mpi``, :mod:`granular_material_skfem.mpi`)
BACKENDS = ("inprocess", "mpi")


@dataclass(frozen=True)
class DEMMaterialParameters:
    """How the RVEs of a :class:`DEMMaterial` are made and driven.

    Attributes:
        rve: RVE file to load (B = 1, or B = number of Gauss points); None: prepare packings.
        particles: discs per prepared RVE (ignored with ``rve``), >= ``min_discs()`` (12).
        seed: seed of the first prepared RVE; RVE p uses seed + p (independent packings).
        pressure: isotropic consolidation pressure of prepared RVEs [Pa], > 0: the
            material's ``confining`` (:attr:`DEMMaterial.confining`; this field keeps its
            name for the MPI workers and checkpoints that carry it).
        replicate: one RVE (the first of the file, or one prepared with ``seed``) copied to
            every Gauss point.
        device: "cpu", "cuda" or None (CUDA when present).
        max_strain_per_step: largest strain per DEM step while driving ∇u [-].
        min_steps: fewest DEM steps per evaluation.
        shards: CPU shards (threads) of the batch, per rank with the ``mpi`` backend; None:
            the engine's default (one per core; with ``mpi`` the cores of a node shared by
            its ranks). With 1, independent RVEs are also prepared one at a time (RVE p from
            the random gas of seed + p, consolidated on its own).
        tangent: "objective" (default: Kruyt–Rothenburg applied to the strain, sym ∇u,
            plus the stress's rotation by the spin, so that a rigid rotation costs
            nothing), "kruyt-rothenburg" (Wu et al. eq. 6 as published), "perturbation"
            (forward differences of the RVE response, four extra DEM runs per evaluation) or
            "condensed" (fluctuations condensed out of the contact network's stiffness, plus
            the stress's spin; contacts at their Coulomb cap slide freely) or
            "condensed-sticking" (the same with every touching contact sticking: an upper
            bound of the RVE's incremental stiffness); see
            :class:`~granular_material_skfem.backend.InProcessBackend`.
        perturbation: relative perturbation of ∇u for the "perturbation" tangent [-].
        reuse_tol: strain [-]: an RVE whose ∇u moved by at most this (every component) since
            it was last driven keeps its response instead of being stepped (see
            :class:`~granular_material_skfem.backend.InProcessBackend`); 0: every RVE is
            stepped at every evaluation.
        reuse_correction: "none" or "tangent" (a reused response corrected to first order).
        drive: "restart" (every trial from the committed state, Guo & Zhao) or "continue"
            (from the last trial state by the change of ∇u).
        max_dem_steps: cap on one RVE path's DEM steps per evaluation: a point whose path
            needs more is reported failed (Newton cuts back); None: no cap.
        backend: "inprocess" (every RVE in this process) or "mpi" (contiguous shards on the
            ranks of an MPI job, see :mod:`granular_material_skfem.mpi`; the same results
            bit for bit).
        packing: the material of prepared RVEs (contact law, friction, damping, density,
            thickness) and how they are packed (radii, target void ratio e0); ignored with
            ``rve`` (the file carries its own material). Default: Wu et al.'s Table 1.
    """

    rve: str | None = None
    particles: int = DEFAULT_DISCS
    seed: int = 1
    pressure: float = DEFAULT_PRESSURE
    replicate: bool = False
    device: str | None = None
    max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP
    min_steps: int = DEFAULT_MIN_STEPS
    shards: int | None = None
    tangent: str = "objective"
    perturbation: float = 0.1
    reuse_tol: float = 0.0
    reuse_correction: str = "none"
    drive: str = "restart"
    max_dem_steps: int | None = None
    backend: str = "inprocess"
    packing: PackingParameters = field(default_factory=PackingParameters)

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, "
                             f"got {self.backend!r}")
        check_driving(self.tangent, self.perturbation, MIN_PERTURBATION, self.max_strain_per_step,
                      self.min_steps)
        check_reuse(self.reuse_tol, self.reuse_correction, self.drive, self.tangent)
        if self.max_dem_steps is not None and (int(self.max_dem_steps) != self.max_dem_steps
                                               or self.max_dem_steps < 1):
            raise ValueError(f"max_dem_steps must be an integer >= 1 or None, "
                             f"got {self.max_dem_steps!r}")
        if self.shards is not None and (int(self.shards) != self.shards or self.shards < 1):
            raise ValueError(f"shards must be an integer >= 1 or None, got {self.shards!r}")
        if not isinstance(self.packing, PackingParameters):
            raise ValueError(f"packing must be PackingParameters, got {self.packing!r}")
        fewest = min_discs(self.packing.radius_range)
        if int(self.particles) != self.particles or self.particles < fewest:
            raise ValueError(f"particles must be an integer >= {fewest} (the periodic cell must "
                             f"stay wider than twice the contact cut-off), got "
                             f"{self.particles!r}")
        if not (math.isfinite(self.pressure) and self.pressure > 0):
            raise ValueError(f"pressure must be a positive number of Pa, got {self.pressure!r}")
        if self.device is not None:
            resolve_device(self.device)  # the engine's one device check


def in_process_backend(data: RVEData, parameters: DEMMaterialParameters,
                       device: str | None, shards: int | None) -> InProcessBackend:
    """The RVEs ``data`` in one :class:`DEMBatch` on ``device`` with ``shards`` CPU threads,
    driven as ``parameters`` say."""
    p = parameters
    return InProcessBackend(DEMBatch(data, device=device, shards=shards),
                            p.max_strain_per_step, p.min_steps, tangent=p.tangent,
                            perturbation=p.perturbation, reuse_tol=p.reuse_tol,
                            reuse_correction=p.reuse_correction, drive=p.drive,
                            max_steps=p.max_dem_steps)
