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
RVE, the tangent D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) on that configuration. D has the first minor
symmetry (D_ijkl = D_jikl: σ is symmetrised) but not the second (D_ijkl ≠ D_ijlk): the spin
term responds to skw ∇u. Keep the full (2, 2, 2, 2) tangent; a Voigt/Mandel 3 × 3 user
takes ½ (D_ijkl + D_ijlk) and loses the stress's rotation (see
:mod:`granular_material.fem.material`).

A scikit-fem user calls :meth:`DEMMaterial.response` with the *total* ∇u, in scikit-fem's
quadrature-last layout if they like (see
:class:`~granular_material.fem.material.ScikitFemInterface`); :meth:`DEMMaterial.evaluate`
keeps the protocol's increment.
"""

from __future__ import annotations

import os
import sys
import warnings
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from granular_material_skfem.backend import Evaluation, InProcessBackend
from granular_material_skfem.parameters import (
    BACKENDS,
    DEMMaterialParameters,
    in_process_backend,
)
from granular_material_skfem.run_parameters import (
    DEMParameters,
    check_run,
    material_keywords,
    run_summary,
)

from granular_material.dem import RVEData, load_rve, save_rve
from granular_material.fem.material import (
    FailureReason,
    MaterialResponse,
    PointStatus,
    ScikitFemInterface,
)
from granular_material.procedures.packing import (
    DEFAULT_DISCS,
    DEFAULT_PRESSURE,
    VOID_RATIO_TOLERANCE,
    PackingParameters,
    prepare_packing,
)
from granular_material.procedures.strain_path import DEFAULT_MIN_STEPS, DEFAULT_STRAIN_PER_STEP

if TYPE_CHECKING:
    import pandas as pd
    from granular_material_skfem.mpi import MPIBackend

    from granular_material.runs.context import RunContext

__all__ = ["BACKENDS", "UNCONFINED_FRACTION", "DEMMaterial", "DEMMaterialParameters",
           "UnconfinedWarning", "in_process_backend"]

#: a point whose mean pressure −tr σ / 2 falls below this fraction of the material's
#: confining pressure has lost its confinement (:class:`UnconfinedWarning`)
UNCONFINED_FRACTION = 0.01
#: the checkpoint's array of the committed total ∇u (a ``backend_*`` array: the RVE states
#: of a checkpoint are read without it)
_GRAD_KEY = "backend_material_grad_u"


class UnconfinedWarning(UserWarning):
    """A DEM RVE has (nearly) no confining stress: with none, a granular RVE relaxes into a
    stress-free gas of discs (zero stress, zero stiffness) and a Newton loop "converges" to
    nothing. Confine the specimen (a pressure on its boundary, as
    ``examples/skfem_material_swap.py`` does) or load RVEs prepared at a pressure."""


def _user_stacklevel() -> int:
    """The ``stacklevel`` of a warning issued by the caller of this function that points at
    the first frame outside granular_material and this plugin (the user's line)."""
    import granular_material

    roots = (os.path.dirname(granular_material.__file__) + os.sep,
             os.path.dirname(__file__) + os.sep)
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_code.co_filename.startswith(roots):
        frame, level = frame.f_back, level + 1
    return level


def _sym(stress: np.ndarray) -> np.ndarray:
    return 0.5 * (stress + np.swapaxes(stress, 1, 2))


class DEMMaterial(ScikitFemInterface):
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
    run_summary = staticmethod(run_summary)

    def __init__(self, rve: str | Path | None = None, particles: int = DEFAULT_DISCS,
                 seed: int = 1,
                 pressure: float | None = None, replicate: bool = False,
                 device: str | None = None,
                 max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
                 min_steps: int = DEFAULT_MIN_STEPS, shards: int | None = None,
                 progress: bool = False, tangent: str = "objective",
                 perturbation: float = 0.1, reuse_tol: float = 0.0,
                 reuse_correction: str = "none", drive: str = "restart",
                 max_dem_steps: int | None = None, backend: str = "inprocess",
                 packing: PackingParameters | None = None, *,
                 confining: float | None = None, isotropic: bool = False) -> None:
        """A DEM material (not yet allocated: :meth:`allocate` prepares or loads the RVEs).

        SI units throughout (m, N, Pa, kg, s; angles in rad); strains are dimensionless.

        Args:
            rve: RVE file (``.npz``, see ``granular-material prepare``) holding one RVE
                (copied to every Gauss point) or one per Gauss point; None (default):
                prepare packings at ``confining``.
            particles: discs per prepared RVE (ignored with ``rve``); default 400, at least
                12 for the default 3–7 mm radii. The spec's ``particles``.
            seed: seed of the first prepared RVE; RVE p uses ``seed + p``. The spec's
                ``seed``.
            pressure: deprecated name of ``confining`` (a DeprecationWarning).
            replicate: True: one RVE (prepared with ``seed``, or the file's first) copied to
                every Gauss point; False (default): one independent RVE per point. The
                command line's ``single-element`` replicates one RVE unless
                ``--independent``; ``biaxial`` never does.
            device: "cpu", "cuda", "cuda:N" or None (CUDA when present).
            max_strain_per_step: largest strain [-] of one DEM step along ∇u (default 1e-5,
                Guo & Zhao); the spec's ``max_strain_per_step``.
            min_steps: fewest DEM steps of one evaluation (default 2).
            shards: CPU threads of the batch (None: one per core).
            progress: show a progress bar while packings are prepared.
            tangent: "objective" (default), "kruyt-rothenburg", "perturbation",
                "condensed" or "condensed-sticking" (see :class:`DEMMaterialParameters`);
                the spec's ``tangent``.
            perturbation: relative perturbation of ∇u [-] of the "perturbation" tangent.
            reuse_tol: strain [-] under which a point keeps its last response (0: never).
            reuse_correction: "none" or "tangent".
            drive: "restart" (default: every evaluation from the committed state) or
                "continue".
            max_dem_steps: cap on one RVE path's DEM steps in one evaluation; a point over it
                fails with reason ``max_dem_steps`` (None: no cap; the run specification's
                default is 10⁶).
            backend: "inprocess" (default) or "mpi".
            packing: the material and packing of prepared RVEs (contact law, friction,
                damping, density, thickness, radii, target void ratio):
                :class:`~granular_material.procedures.packing.PackingParameters`, whose
                ``meta`` is an :class:`~granular_material.dem.RVEMeta`; default Wu et al.
                2025, Table 1. The run specification spells the same fields flat
                (``kn``, ``kt``, ``friction_angle``, ...: :class:`DEMParameters`).
            confining: isotropic pressure [Pa], > 0, compression positive, at which
                prepared RVEs are consolidated (default 100 kPa); the run specification's
                and the command line's ``confining``. It is also the scale of the
                :class:`UnconfinedWarning`. An RVE file carries its own stress.
            isotropic: after :meth:`allocate`, relax every RVE to the isotropic stress
                −confining I (:meth:`make_isotropic`): a packing consolidated by a normal
                stress servo keeps a shear stress (σxy ≈ −14 kPa for 64 discs, −7.7 kPa for
                400, seed 1, at 100 kPa); relaxed, |σxy| < 1 % of confining. Default False
                (the prepared state as it is, what the command line runs).

        The keywords follow the run specification (:class:`DEMParameters`, the command
        line's ``--option`` of the same name) where both have the setting; ``pressure`` was
        this class's name for ``confining`` and still works, with a DeprecationWarning.
        """
        if pressure is not None:
            if confining is not None:
                raise ValueError("give confining (pressure is its deprecated name), not both")
            warnings.warn("DEMMaterial(pressure=...) is deprecated: call it confining= (the "
                          "run specification's and the command line's name)",
                          DeprecationWarning, stacklevel=_user_stacklevel())
            confining = pressure
        if confining is None:
            confining = DEFAULT_PRESSURE
        self.parameters = DEMMaterialParameters(
            None if rve is None else str(rve), particles, seed, confining, replicate, device,
            max_strain_per_step, min_steps, shards, tangent, perturbation, reuse_tol,
            reuse_correction, drive, max_dem_steps, backend,
            PackingParameters() if packing is None else packing,
        )
        self.progress = progress
        self.isotropic = bool(isotropic)
        self.backend: InProcessBackend | MPIBackend | None = None
        #: the response of the committed state (None until known: a commit, or a failure)
        self._committed_response: MaterialResponse | None = None
        self._last_response: MaterialResponse | None = None
        self._warned_unconfined = False

    @property
    def confining(self) -> float:
        """Consolidation pressure of prepared RVEs [Pa], compression positive."""
        return self.parameters.pressure

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

    @classmethod
    def for_run(cls, parameters: DEMParameters, context: RunContext) -> DEMMaterial:
        """The material of a run specification (not yet allocated): the run hook of
        :mod:`granular_material.runs.context`."""
        return cls(**material_keywords(parameters, context))

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
        self._reset_state(n_points)
        if self.isotropic:
            self.make_isotropic()

    def make_isotropic(self, tol: float = 0.01, max_iterations: int = 30) -> int:
        """Relax every committed RVE to the isotropic stress −``confining`` I and commit it.

        A packing consolidated by a servo on its normal stresses keeps a shear stress (e.g.
        σxy ≈ −14 kPa at ∇u = 0 for 64 discs, seed 1, at 100 kPa): each RVE is driven by the
        symmetric ∇u that cancels σ + p I (Newton on the symmetric part of the tangent,
        every iteration from the committed state) until every component is within
        ``tol`` · p, and that state is committed as the new reference: ``committed_grad_u``
        is zero again (the strain of the relaxation is not the specimen's). Returns the
        iterations used; ``RuntimeError`` when ``max_iterations`` do not reach ``tol`` or a
        point fails. Cost: a few evaluations of ~10⁻³ strain (a few hundred DEM steps).
        """
        n = self._allocated().n_rve
        p = self.confining
        target = -p * np.eye(2)
        grad = np.zeros((n, 2, 2))
        index = ((0, 0), (1, 1), (0, 1))  # xx, yy, xy of σ and of sym ∇u
        for iteration in range(1, max_iterations + 1):
            r = self.evaluate(grad)
            if not r.ok:
                self.revert()
                raise RuntimeError(f"make_isotropic: points failed {r.failure_counts()}")
            error = r.stress - target
            if np.abs(error).max() <= tol * p:
                self.commit()
                self._committed_grad = np.zeros((n, 2, 2))
                return iteration
            d = r.tangent
            a = np.empty((n, 3, 3))
            for row, (i, j) in enumerate(index):
                for col, (k, m) in enumerate(index):
                    a[:, row, col] = d[:, i, j, k, m] + (d[:, i, j, m, k] if k != m else 0.0)
            rhs = -np.stack([error[:, i, j] for i, j in index], axis=1)
            step = np.linalg.solve(a, rhs[..., None])[..., 0]
            grad[:, 0, 0] += step[:, 0]
            grad[:, 1, 1] += step[:, 1]
            grad[:, 0, 1] += step[:, 2]
            grad[:, 1, 0] += step[:, 2]
        self.revert()
        raise RuntimeError(f"make_isotropic: the stress is {np.abs(error).max():.3g} Pa from "
                           f"isotropic after {max_iterations} iterations (tol {tol * p:.3g} Pa)")

    def _reset_state(self, n_points: int) -> None:
        self._track_allocate(n_points)
        self._committed_response = self._last_response = None

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

        The protocol's evaluation: ∇u [-] is the *increment* ∂Δu_k/∂x_l since the last
        commit, batch-first, on the configuration of the last commit (``response`` takes the
        total, and scikit-fem's layout). Stress: Cauchy σ [Pa], tension positive;
        tangent: D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) [Pa], no second minor symmetry.

        ``costs`` holds ``dem_steps`` (DEM steps run: the longest RVE path of each drive,
        summed over the drives), ``rve_evaluations`` (RVE paths run; points not stepped,
        e.g. reused, do not count) and ``particle_steps`` (disc-steps run, Σ steps × discs
        over the paths); ``fields`` holds ``void_ratio``,
        ``coordination`` and ``stress_skew`` (σxy − σyx of the Love sum over 2 [Pa], what
        the symmetrisation removed). A point that fails has ``PointStatus.FAILED``, a reason
        in ``reasons`` (:class:`~granular_material.fem.material.FailureReason`:
        ``max_dem_steps``, ``cell_inverted``, ``cell_too_thin``, ``blow_up``,
        ``overcompressed``, ``coincident_discs``, ``non_finite_input``; ``aborted`` for
        the other points when an RVE of the batch blew up, which sends the whole batch back
        to its committed state), and the stress, tangent and fields of its committed state
        (never NaN). A :class:`UnconfinedWarning` is issued (once) when a point's mean
        pressure falls below 1 % of ``confining``.
        """
        if self.backend is None:
            raise RuntimeError("allocate() the DEM material before evaluate()")
        grad_u = np.asarray(grad_u, dtype=np.float64)
        if grad_u.shape != (self.n_points, 2, 2):
            raise ValueError(
                f"evaluate() takes grad_u batch-first, shape ({self.n_points}, 2, 2) (the "
                f"increment since the commit), got {grad_u.shape}; response() also takes "
                "scikit-fem's quadrature-last (2, 2, nelems, nqp) or a DiscreteField (or "
                "convert with granular_material.fem.to_points / to_quadrature)")
        self._track_evaluate(grad_u)
        ev = self.backend.evaluate(grad_u)
        response = self._response_of(ev)
        self._last_response = response
        self._check_confinement(response)
        return response

    def _response_of(self, ev: Evaluation) -> MaterialResponse:
        """The material response of a backend's evaluation; failed points (all points of an
        incomplete one) get their committed state's response and a reason."""
        h = ev.homogenized
        reasons = ev.failure_reasons()
        failed = np.asarray(ev.failed, dtype=bool).copy()
        if not ev.complete:
            reasons[~failed] = FailureReason.ABORTED.value
            failed[:] = True
        status = np.where(failed, PointStatus.FAILED, PointStatus.OK).astype(np.int8)

        def f64(values: np.ndarray) -> np.ndarray:
            return np.asarray(values, dtype=np.float64)

        love = f64(h.stress)
        stress, tangent = _sym(love), f64(h.tangent).copy()
        fields = {"void_ratio": f64(h.void_ratio).copy(),
                  "coordination": f64(h.coordination).copy(),
                  "stress_skew": 0.5 * (love[:, 0, 1] - love[:, 1, 0])}
        if failed.any():
            committed = self._committed()
            stress[failed] = committed.stress[failed]
            tangent[failed] = committed.tangent[failed]
            for name, values in fields.items():
                values[failed] = np.asarray(committed.fields[name])[failed]
        return MaterialResponse(
            stress=stress, tangent=tangent, status=status,
            costs={"dem_steps": ev.dem_steps, "rve_evaluations": ev.rve_evaluations,
                   "particle_steps": ev.particle_steps},
            fields=fields, reasons=reasons, timings=ev.timings,
        )

    def _committed(self) -> MaterialResponse:
        """The response of the committed state: the last committed evaluation's, else
        measured on the committed RVEs (homogenised, not stepped; objective tangent)."""
        if self._committed_response is None:
            from granular_material.dem import DEMBatch
            from granular_material.dem.homogenization import objective_tangent

            p = self.parameters
            batch = DEMBatch(self.committed_rves(), device=p.device, shards=p.shards)
            h = batch.homogenize()
            love = np.asarray(h.stress, dtype=np.float64)
            stress = _sym(love)
            n = len(stress)
            self._committed_response = MaterialResponse(
                stress=stress,
                tangent=np.asarray(objective_tangent(np.asarray(h.tangent, dtype=np.float64),
                                                     stress), dtype=np.float64),
                status=np.zeros(n, dtype=np.int8),
                fields={"void_ratio": np.asarray(h.void_ratio, dtype=np.float64),
                        "coordination": np.asarray(h.coordination, dtype=np.float64),
                        "stress_skew": 0.5 * (love[:, 0, 1] - love[:, 1, 0])})
        return self._committed_response

    def _check_confinement(self, response: MaterialResponse) -> None:
        if self._warned_unconfined:
            return
        ok = response.status == PointStatus.OK
        pressure = -0.5 * np.trace(response.stress, axis1=1, axis2=2)
        loose = np.flatnonzero(ok & (pressure < UNCONFINED_FRACTION * self.confining))
        if loose.size:
            self._warned_unconfined = True
            warnings.warn(
                f"{loose.size} of {len(pressure)} DEM points have lost their confinement "
                f"(mean pressure below {UNCONFINED_FRACTION:.0%} of {self.confining:g} Pa, "
                f"e.g. {pressure[loose[0]]:.3g} Pa at point {loose[0]}): an unconfined RVE "
                "relaxes into a stress-free gas of discs. Apply a confining pressure on the "
                "boundary of the specimen (see docs/guide/scikit-fem.md)",
                UnconfinedWarning, stacklevel=_user_stacklevel())

    def hold_tangent(self, hold: bool) -> None:
        """``hold``: the next evaluation's tangent is returned by the later ones too, up to
        the next commit or revert, without measuring it again (the condensed and
        perturbation tangents cost a condensation or four DEM drives each time). Asked by
        the Newton driver's ``tangent_update="hold"``, which uses that tangent alone. The
        MPI backend measures it every time."""
        hold_tangent = getattr(self._allocated(), "hold_tangent", None)
        if hold_tangent is not None:
            hold_tangent(hold)

    def commit(self) -> None:
        """The RVE states of the last evaluation become the committed states (and its total
        ∇u :attr:`committed_grad_u`)."""
        self._allocated().commit()
        self._track_commit()
        self._committed_response = self._last_response

    def revert(self) -> None:
        """Every RVE back to its committed state."""
        if self.backend is not None:
            self.backend.revert()
        self._track_revert()

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed RVE states (an RVE file, B = n_points) to ``path``, with the
        committed total ∇u; with the ``mpi`` backend rank 0 gathers the shards and writes
        the one file, which either backend, on any number of ranks, restores."""
        data = self._allocated().checkpoint_data()
        extra = {**data.extra, _GRAD_KEY: self.committed_grad_u}
        # a run's own state, checked whole when a resume reads it: written fast
        save_rve(path, replace(data, extra=extra), compress=False, validate=False)

    def restore(self, path: str | Path) -> None:
        """Load the committed state written by :meth:`checkpoint` (RVE states with contact
        history, what reuse and ``continue`` carry between steps, the committed total ∇u)."""
        data = load_rve(path)
        self.backend = self._backend(data, resume=True)
        self._reset_state(self.backend.n_rve)
        if _GRAD_KEY in data.extra:
            self._committed_grad = np.array(data.extra[_GRAD_KEY], dtype=np.float64)
