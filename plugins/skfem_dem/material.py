"""DEMMaterial: one periodic DEM RVE per Gauss point as a constitutive model.

The material is driven by the displacement gradient since its last commit (the
strain-driven protocol of Guo & Zhao 2014): every RVE is restored to its committed state,
deformed by ∇u over n = max(⌈max|∇u| / 1e-5⌉, 2) DEM steps, and homogenised into the Love
stress σ = (1/V) Σ_c f^c ⊗ d^c, symmetrised (its antisymmetric part, the RVE's imbalance of
moments, is reported as the field ``stress_skew``), and a tangent: by default the objective
one, the Kruyt–Rothenburg D = (1/V) Σ_c (k_n n⊗d⊗n⊗d + k_t t⊗d⊗t⊗d) (Wu, Fu & Zhou 2025,
eqs. 5–6) applied to sym ∇u plus the stress's rotation by the spin.

∇u is the displacement gradient since the last commit, measured on the configuration the
RVE was committed in (the FEM's updated-Lagrangian formulation hands over exactly that; see
:mod:`granular_material.fem.kinematics`); the stress is the Cauchy stress of the deformed
RVE, the tangent D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) on that configuration.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from granular_material_skfem.backend import InProcessBackend
from granular_material_skfem.parameters import (
    BACKENDS,
    DEMMaterialParameters,
    in_process_backend,
)
from granular_material_skfem.run_parameters import (
    DEMParameters,
    check_run,
    material_for_run,
    run_summary,
)

from granular_material.dem import RVEData, load_rve
from granular_material.fem.material import MaterialResponse, PointStatus
from granular_material.procedures.packing import (
    VOID_RATIO_TOLERANCE,
    PackingParameters,
    prepare_packing,
)

if TYPE_CHECKING:
    import pandas as pd
    from granular_material_skfem.mpi import MPIBackend

__all__ = ["BACKENDS", "DEMMaterial", "DEMMaterialParameters", "in_process_backend"]

class DEMMaterial:
    """The DEM material: owns one RVE batch, one RVE per Gauss point (batch-first), held in
    this process or, with ``backend="mpi"``, in shards on the ranks of an MPI job.

    In a run specification its parameters are :class:`DEMParameters` (``Parameters``), and
    ``check_run``, ``for_run`` and ``run_summary`` are its run hooks (see
    :mod:`granular_material.runs.context`); its stress carries noise (``noisy``).
    """

    #: the parameters of the material in a run specification
    Parameters = DEMParameters
    #: DEM stress carries noise: the Newton defaults of noisy materials apply
    noisy = True
    check_run = staticmethod(check_run)
    for_run = staticmethod(material_for_run)
    run_summary = staticmethod(run_summary)

    def __init__(self, rve: str | Path | None = None, particles: int = 400, seed: int = 1,
                 pressure: float = 100.0e3, replicate: bool = False,
                 device: str | None = None, max_strain_per_step: float = 1.0e-5,
                 min_steps: int = 2, shards: int | None = None,
                 progress: bool = False, tangent: str = "objective",
                 perturbation: float = 0.1, reuse_tol: float = 0.0,
                 reuse_correction: str = "none", drive: str = "restart",
                 max_dem_steps: int | None = None, backend: str = "inprocess",
                 packing: PackingParameters | None = None) -> None:
        self.parameters = DEMMaterialParameters(
            None if rve is None else str(rve), particles, seed, pressure, replicate, device,
            max_strain_per_step, min_steps, shards, tangent, perturbation, reuse_tol,
            reuse_correction, drive, max_dem_steps, backend,
            PackingParameters() if packing is None else packing,
        )
        self.progress = progress
        self.backend: InProcessBackend | MPIBackend | None = None

    @staticmethod
    def launch(backend: str, main: Callable[[], int]) -> int:
        """Run a program whose DEM materials use ``backend``; returns this process's exit
        code. In process that is ``main()``; with ``"mpi"`` rank 0 runs ``main`` and every
        other rank serves its RVE shard to rank 0 until ``main`` has ended, however it ends
        (see :func:`granular_material_skfem.mpi.launch`)."""
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
        if backend == "inprocess":
            return main()
        from granular_material_skfem.mpi import launch

        return launch(main)

    @property
    def n_points(self) -> int:
        """Number of Gauss points (RVEs) allocated."""
        return 0 if self.backend is None else self.backend.n_rve

    def _allocated(self) -> InProcessBackend | MPIBackend:
        if self.backend is None:
            raise RuntimeError("allocate() the DEM material first")
        return self.backend

    def reference_curve(self, axial_strain: float, confining: float, device: str | None,
                        progress: bool = False) -> pd.DataFrame:
        """The drained biaxial test of RVE 0 in pure DEM, from its committed state, to
        ``axial_strain`` [-] (compression positive) at ``confining`` [Pa]: the curve a
        single element is compared with (one row per recorded DEM step)."""
        from granular_material.dem import DEMBatch
        from granular_material.procedures import biaxial_test

        batch = DEMBatch(self.committed_rves().take([0]), device=device, shards=1)
        curve = biaxial_test(batch, axial_strain=axial_strain, confining=confining,
                             progress=progress)
        return curve[curve["rve"] == 0].reset_index(drop=True)

    def committed_rves(self, points: np.ndarray | None = None) -> RVEData:
        """The committed RVE states, one per Gauss point or of the point indices ``points``
        (contact history included)."""
        return self._allocated().committed_rves(points)

    def _backend(self, data: RVEData, resume: bool = False) -> InProcessBackend | MPIBackend:
        """The backend of the chosen kind holding ``data`` (a checkpoint's, with its
        ``backend_*`` arrays, when ``resume``)."""
        p = self.parameters
        if p.backend == "mpi":
            from granular_material_skfem.mpi import MPIBackend

            return MPIBackend(data, p, resume=resume)
        states = InProcessBackend.without_backend_arrays(data) if resume else data
        backend = in_process_backend(states, p, p.device, p.shards)
        if resume:
            backend.resume_from(data)
        return backend

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
            data = RVEData.concatenate([self._prepare(1, p.seed + k) for k in range(n_points)])
        else:
            data = self._prepare(n_points, p.seed)
        self.backend = self._backend(data)

    def _prepare(self, n_rve: int, seed: int) -> RVEData:
        """``n_rve`` packings of the parameters' material (seeds seed, seed + 1, …);
        ``RuntimeError`` naming the RVEs whose void ratio ends more than
        ``VOID_RATIO_TOLERANCE`` above the packing's ``target_void_ratio``."""
        p = self.parameters
        packing = p.packing
        batch = prepare_packing(n_disc=p.particles, n_rve=n_rve, seed=seed, pressure=p.pressure,
                                meta=packing.meta, target_void_ratio=packing.target_void_ratio,
                                radius_range=packing.radius_range, device=p.device,
                                progress=self.progress)
        target = packing.target_void_ratio
        if target is not None:
            void_ratio = batch.homogenize().void_ratio
            missed = np.flatnonzero(void_ratio > target + VOID_RATIO_TOLERANCE)
            if missed.size:
                shown = ", ".join(f"seed {seed + i}: {void_ratio[i]:.4g}" for i in missed[:5])
                if missed.size > 5:
                    shown += f" and {missed.size - 5} more"
                raise RuntimeError(
                    f"target void ratio {target:g} not reached under the pressure "
                    f"{p.pressure:g} Pa: void ratio of the RVEs of {shown} (frictionless "
                    "compaction reached the pressure first; a denser packing needs a higher "
                    "pressure)")
        return batch.to_data()

    def evaluate(self, grad_u: np.ndarray) -> MaterialResponse:
        """Symmetrised Love stress and the tangent for ∇u (n, 2, 2) since the commit.

        ``costs`` holds ``dem_steps`` (DEM steps run: the longest RVE path of each drive,
        summed over the drives), ``rve_evaluations`` (RVE paths run; points not stepped,
        e.g. reused, do not count) and ``particle_steps`` (disc-steps run, Σ steps × discs
        over the paths); ``fields`` holds ``void_ratio``,
        ``coordination`` and ``stress_skew`` (σxy − σyx of the Love sum over 2 [Pa], what
        the symmetrisation removed). RVEs that blew up are reported with
        ``PointStatus.FAILED``.
        """
        if self.backend is None:
            raise RuntimeError("allocate() the DEM material before evaluate()")
        grad_u = np.asarray(grad_u, dtype=np.float64)
        if grad_u.shape != (self.n_points, 2, 2):
            raise ValueError(f"grad_u must have shape ({self.n_points}, 2, 2), got {grad_u.shape}")
        ev = self.backend.evaluate(grad_u)
        h = ev.homogenized
        status = np.where(ev.failed, PointStatus.FAILED, PointStatus.OK).astype(np.int8)

        def f64(values: np.ndarray) -> np.ndarray:
            return np.asarray(values, dtype=np.float64)

        love = f64(h.stress)
        return MaterialResponse(
            stress=0.5 * (love + np.swapaxes(love, 1, 2)), tangent=f64(h.tangent),
            status=status,
            costs={"dem_steps": ev.dem_steps, "rve_evaluations": ev.rve_evaluations,
                   "particle_steps": ev.particle_steps},
            fields={"void_ratio": f64(h.void_ratio), "coordination": f64(h.coordination),
                    "stress_skew": 0.5 * (love[:, 0, 1] - love[:, 1, 0])},
        )

    def commit(self) -> None:
        """The RVE states of the last evaluation become the committed states."""
        self._allocated().commit()

    def revert(self) -> None:
        """Every RVE back to its committed state."""
        if self.backend is not None:
            self.backend.revert()

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed RVE states (an RVE file, B = n_points) to ``path``; with the
        ``mpi`` backend rank 0 gathers the shards and writes the one file, which either
        backend, on any number of ranks, restores."""
        self._allocated().checkpoint(path)

    def restore(self, path: str | Path) -> None:
        """Load the committed state written by :meth:`checkpoint` (RVE states with contact
        history, and what reuse and ``continue`` carry between steps)."""
        self.backend = self._backend(load_rve(path), resume=True)

