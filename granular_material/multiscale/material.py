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
:mod:`granular_material.fem.materials.protocol`).

A scikit-fem user calls :meth:`DEMMaterial.response` with the *total* ∇u, in scikit-fem's
quadrature-last layout if they like (see
:class:`~granular_material.fem.materials.protocol.ScikitFemInterface`); :meth:`DEMMaterial.evaluate`
keeps the protocol's increment.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from granular_material.dem import RVEData, load_rve, save_rve
from granular_material.errors import ParameterError
from granular_material.fem.materials.checks import check_grad, check_points, checkpoint_archive
from granular_material.fem.materials.protocol import (
    MaterialResponse,
    PointStatus,
    ScikitFemInterface,
)
from granular_material.multiscale.backend import InProcessBackend
from granular_material.multiscale.confinement import (
    UNCONFINED_FRACTION,
    UnconfinedWarning,
    floored_tangent,
    unconfined,
)
from granular_material.multiscale.evaluation import Evaluation
from granular_material.multiscale.isotropic import relax_to_isotropic
from granular_material.multiscale.material_arguments import material_parameters, user_stacklevel
from granular_material.multiscale.parameters import BACKENDS, DEMMaterialParameters
from granular_material.multiscale.preparation import (
    StressPreparation,
    initial_rves,
    rves_at_stress,
)
from granular_material.multiscale.responses import measured_response, response_of
from granular_material.multiscale.run_hooks import (
    DEMParameters,
    check_run,
    continuum_twin,
    lowest_pressure,
    material_keywords,
    problem_keywords,
    run_summary,
    unit_weight,
)

if TYPE_CHECKING:
    import pandas as pd

    from granular_material.fem.materials.run_context import RunContext
    from granular_material.multiscale.mpi import MPIBackend

__all__ = ["UNCONFINED_FRACTION", "DEMMaterial", "UnconfinedWarning"]

#: the checkpoint's array of the committed total ∇u (a ``backend_*`` array: the RVE states
#: of a checkpoint are read without it)
_GRAD_KEY = "backend_material_grad_u"
#: the checkpoint's arrays of what the material answers its unconfined and failed points by
#: (``backend_*`` arrays too): the tangent of its first evaluation (the initial state's, the
#: floor of unconfined points; empty before any evaluation), each point's initial mean
#: pressure (with an initial stress), and the committed response (``..._stress``,
#: ``..._tangent``, ``..._field_NAME``: what a failed point answers)
_FLOOR_KEY = "backend_material_initial_tangent"
_PRESSURE_KEY = "backend_material_initial_pressure"
_COMMITTED_PREFIX = "backend_material_committed_"


class DEMMaterial(ScikitFemInterface):
    """The DEM material: owns one RVE batch, one RVE per Gauss point (batch-first), held in
    this process or, with ``backend="mpi"``, in shards on the ranks of an MPI job.

    Build it with its settings as keywords (the fields of :class:`DEMMaterialParameters`,
    each documented there: ``rve``, ``particles``, ``seed``, ``confining``, ``tangent``,
    ``drive``, ``reuse_tol``, ``device``, ...) or with a :class:`DEMMaterialParameters`;
    ``progress`` shows a bar while packings are prepared; ``pressure`` is the deprecated name
    of ``confining``. SI units (m, N, Pa, kg, s; angles in rad); strains dimensionless. It is
    not allocated yet: :meth:`allocate` prepares or loads the RVEs.

    In a run specification its parameters are :class:`DEMParameters` (``Parameters``), and
    ``check_run``, ``for_run`` and ``run_summary`` are its run hooks (see
    :mod:`granular_material.fem.materials.run_context`); its stress carries noise (``noisy``).
    """

    #: the parameters of the material in a run specification
    Parameters = DEMParameters
    #: DEM stress carries noise: the Newton defaults of noisy materials apply
    noisy = True
    check_run = staticmethod(check_run)
    run_summary = staticmethod(run_summary)
    unit_weight = staticmethod(unit_weight)
    lowest_pressure = staticmethod(lowest_pressure)
    continuum_twin = staticmethod(continuum_twin)

    def __init__(self, parameters: DEMMaterialParameters | str | Path | None = None, *,
                 progress: bool = False, pressure: float | None = None,
                 **settings: Any) -> None:
        self.parameters = material_parameters(parameters, pressure, settings)
        self.progress = progress
        self.backend: InProcessBackend | MPIBackend | None = None
        #: the response of the committed state (None until known: a commit, or a failure)
        self._committed_response: MaterialResponse | None = None
        self._last_response: MaterialResponse | None = None
        self._warned_unconfined = False
        self._initial_tangent: np.ndarray | None = None  # of the first evaluation
        #: each point's initial mean pressure [Pa] as a checkpoint restored it (its
        #: :attr:`preparation` is not restored)
        self._restored_pressure: np.ndarray | None = None
        #: how the RVEs were brought to ``initial_stress`` (None without it, or before
        #: :meth:`allocate`): the targets, clamped points, groups and errors
        self.preparation: StressPreparation | None = None

    @property
    def confining(self) -> float:
        """Consolidation pressure of prepared RVEs [Pa], compression positive."""
        return self.parameters.confining

    @property
    def isotropic(self) -> bool:
        """Whether :meth:`allocate` relaxes the RVEs to the isotropic stress."""
        return self.parameters.isotropic

    @staticmethod
    def launch(backend: str, main: Callable[[], int]) -> int:
        """Run a program whose DEM materials use ``backend``; returns this process's exit
        code. In process that is ``main()``; with ``"mpi"`` rank 0 runs ``main`` and every
        other rank serves its RVE shard to rank 0 until ``main`` has ended, however it ends
        (see :func:`granular_material.multiscale.mpi.launch`)."""
        if backend not in BACKENDS:
            raise ParameterError("backend", f"must be one of {', '.join(BACKENDS)}, got "
                                            f"{backend!r}")
        if backend == "inprocess":
            return main()
        from granular_material.multiscale.mpi import launch

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
        :mod:`granular_material.fem.materials.run_context`."""
        keywords = material_keywords(parameters, context)
        return cls(progress=keywords.pop("progress"), **keywords)

    @classmethod
    def for_problem(cls, parameters: DEMParameters, context: RunContext,
                    initial_stress: np.ndarray) -> DEMMaterial:
        """The material of a boundary-value problem whose points start at ``initial_stress``
        [Pa] (n, 2, 2), tension positive (not yet allocated): see
        :func:`~granular_material.multiscale.run_hooks.problem_keywords`."""
        keywords = problem_keywords(parameters, context, initial_stress)
        return cls(progress=keywords.pop("progress"), **keywords)

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
            from granular_material.multiscale.mpi import MPIBackend

            return MPIBackend(data, p, resume=resume)
        return InProcessBackend.holding(data, p, p.device, p.shards, resume)

    def allocate(self, n_points: int) -> None:
        """Load or prepare ``n_points`` RVEs in their consolidated state (and relax them to
        the isotropic stress where ``isotropic``), or, with ``initial_stress``, each at its
        point's stress (:attr:`preparation` says how; a :class:`UserWarning` names the points
        whose target was clamped to the lowest prepared pressure). ParameterError naming
        ``initial_stress`` unless it holds ``n_points`` tensors, and naming ``n_points``
        (with the estimate) for a count that is not an integer >= 1 or whose RVEs would not
        fit in memory, before any is prepared."""
        n_points = self._check_points(n_points)
        if self.parameters.initial_stress is not None:
            self.preparation = rves_at_stress(self.parameters, n_points, self.progress)
            data = self.preparation.data
            clamped = self.preparation.clamped
            if clamped.size:
                least = -np.linalg.eigvalsh(self.preparation.prepared[clamped[0]])[1]
                warnings.warn(
                    f"{clamped.size} of {n_points} points have an initial stress below the "
                    f"lowest an RVE is prepared to ({least:.3g} Pa, least principal "
                    f"compression): their targets were scaled up to it, ratios kept (points "
                    f"{clamped[:10].tolist()}{' …' if clamped.size > 10 else ''}; "
                    "material.preparation.clamped lists them all)",
                    UserWarning, stacklevel=user_stacklevel())
        else:
            data = initial_rves(self.parameters, n_points, self.progress)
        self.backend = self._backend(data)
        self._reset_state(n_points)
        if self.parameters.isotropic:
            self.make_isotropic()

    @classmethod
    def holding(cls, data: RVEData, parameters: DEMMaterialParameters,
                initial_pressure: np.ndarray | None = None) -> DEMMaterial:
        """A material allocated with the RVE states ``data`` as they are, one per Gauss point
        (no preparation, no relaxation): RVEs brought to their points' stresses elsewhere
        (an adaptive material's switch). ``initial_pressure`` [Pa] (n,): each point's
        initial mean pressure, the scale of its unconfined test (default ``confining``)."""
        material = cls(replace(parameters, initial_stress=None, isotropic=False))
        material.backend = material._backend(data)
        material._reset_state(data.n_rve)
        if initial_pressure is not None:
            material._restored_pressure = np.asarray(initial_pressure, dtype=np.float64)
        return material

    def _check_points(self, n_points: Any) -> int:
        """``n_points`` as a count whose RVEs (their discs, about DISC_BYTES each, and the
        point's tables) fit in the memory available now (:func:`check_points`)."""
        from granular_material.checks import DISC_BYTES, rve_file_shape

        p = self.parameters
        discs = rve_file_shape(p.rve, "rve")[1] if p.rve is not None else p.discs
        return check_points(n_points, discs * DISC_BYTES + 8192, "dem")

    def make_isotropic(self, tol: float = 0.01, max_iterations: int = 30) -> int:
        """Relax every committed RVE to the isotropic stress −``confining`` I and commit it as
        the new reference (``committed_grad_u`` is zero again: the strain of the relaxation
        is not the specimen's); returns the iterations used. See
        :func:`~granular_material.multiscale.isotropic.relax_to_isotropic`."""
        iterations = relax_to_isotropic(self, self.confining, tol, max_iterations)
        self._committed_grad = np.zeros((self._allocated().n_rve, 2, 2))
        return iterations

    def _reset_state(self, n_points: int) -> None:
        self._track_allocate(n_points)
        self._committed_response = self._last_response = None
        self._initial_tangent = None
        self._restored_pressure = None

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
        in ``reasons`` (:class:`~granular_material.fem.materials.protocol.FailureReason`:
        ``max_dem_steps``, ``cell_inverted``, ``cell_too_thin``, ``blow_up``,
        ``overcompressed``, ``coincident_discs``, ``non_finite_input``; ``aborted`` for
        the other points when an RVE of the batch blew up, which sends the whole batch back
        to its committed state), and the stress, tangent and fields of its committed state
        (never NaN). A :class:`UnconfinedWarning` is issued (once) when a point's mean
        pressure falls below 1 % of ``confining``.
        """
        if self.backend is None:
            raise RuntimeError("allocate() the DEM material before evaluate()")
        grad_u = check_grad(grad_u, self.n_points)
        self._track_evaluate(grad_u)
        ev = self.backend.evaluate(grad_u)
        response = self._check_confinement(self._response_of(ev))
        self._last_response = response
        return response

    def _response_of(self, ev: Evaluation) -> MaterialResponse:
        """The material response of a backend's evaluation (:func:`response_of`)."""
        return response_of(ev, self._committed)

    def _committed(self) -> MaterialResponse:
        """The response of the committed state: the last committed evaluation's, else
        measured on the committed RVEs (:func:`measured_response`)."""
        if self._committed_response is None:
            p = self.parameters
            self._committed_response = measured_response(self.committed_rves(), p.device,
                                                         p.shards)
        return self._committed_response

    def _initial_pressure(self) -> float | np.ndarray:
        """Each point's initial mean pressure [Pa] (its prepared stress), else the confining
        pressure."""
        if self.preparation is not None:
            return -0.5 * np.trace(self.preparation.prepared, axis1=1, axis2=2)
        if self._restored_pressure is not None:
            return self._restored_pressure
        return self.confining

    def _check_confinement(self, response: MaterialResponse) -> MaterialResponse:
        """``response`` with the tangent of unconfined points floored
        (:func:`~granular_material.multiscale.confinement.floored_tangent`: by their initial
        tangent), and a warning, once, that there are some."""
        ok = response.status == PointStatus.OK
        if self._initial_tangent is None:  # the first evaluation's: the initial state's
            self._initial_tangent = response.tangent.copy()
        mask = unconfined(response.stress, ok, self._initial_pressure())
        if mask.any():
            response = replace(response, tangent=floored_tangent(
                response.tangent, self._initial_tangent, mask))
        if self._warned_unconfined:
            return response
        pressure = -0.5 * np.trace(response.stress, axis1=1, axis2=2)
        named = (f"{self.confining:g} Pa" if self.preparation is None
                 else "its initial mean pressure")
        loose = np.flatnonzero(mask)
        if loose.size:
            self._warned_unconfined = True
            warnings.warn(
                f"{loose.size} of {len(pressure)} DEM points have lost their confinement "
                f"(mean pressure below {UNCONFINED_FRACTION:.0%} of {named}, "
                f"e.g. {pressure[loose[0]]:.3g} Pa at point {loose[0]}): an unconfined RVE "
                "relaxes into a stress-free gas of discs (Newton iterates with a floor of "
                "its initial tangent there). A specimen needs a confining pressure on its "
                "boundary (see docs/guide/scikit-fem.md); in a boundary-value problem, soil "
                "that unloads to nothing (beside a footing's edge) is physical",
                UnconfinedWarning, stacklevel=user_stacklevel())
        return response

    def hold_tangent(self, hold: bool) -> None:
        """``hold``: the next evaluation's tangent is returned by the later ones too, up to
        the next commit or revert, without measuring it again (the condensed and
        perturbation tangents cost a condensation or four DEM drives each time). Asked by
        the Newton driver's ``tangent_update="hold"``, which uses that tangent alone; both
        backends hold it (on MPI every rank its shard's)."""
        self._allocated().hold_tangent(hold)

    def commit(self) -> None:
        """The RVE states of the last evaluation become the committed states (and its total
        ∇u :attr:`committed_grad_u`). RuntimeError, and the committed state kept, when a
        point failed in that evaluation (its RVE need not be in its committed state, nor any
        other of the batch: ``revert()`` it, and evaluate a smaller increment)."""
        backend = self._allocated()
        last = self._last_response
        if last is not None and not last.ok:
            bad = last.failed_points()
            raise RuntimeError(f"commit() refuses an evaluation that failed at {bad.size} "
                               f"points (first {bad[:8].tolist()}: "
                               f"{last.failure_counts()}); revert() it")
        backend.commit()
        self._track_commit()
        self._committed_response = self._last_response

    def revert(self) -> None:
        """Every RVE back to its committed state."""
        if self.backend is not None:
            self.backend.revert()
        self._track_revert()

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed RVE states (an RVE file, B = n_points) to ``path``, with the
        committed total ∇u and what unconfined and failed points are answered by (the
        initial tangent, the initial pressures, the committed response); with the ``mpi``
        backend rank 0 gathers the shards and writes the one file, which either backend, on
        any number of ranks, restores."""
        data = self._allocated().checkpoint_data()
        extra = {**data.extra, _GRAD_KEY: self.committed_grad_u, **self._answers()}
        # a run's own state, checked whole when a resume reads it: written fast
        save_rve(path, replace(data, extra=extra), compress=False, validate=False)

    def _answers(self) -> dict[str, np.ndarray]:
        """The checkpoint's arrays of what unconfined and failed points are answered by (see
        ``_FLOOR_KEY``): without them a resumed run floors its unconfined points by the
        tangent of its first evaluation after the resume, and answers failed points by a
        measured response, so that it is another run."""
        floor = self._initial_tangent
        if floor is None:  # not evaluated yet: NaN, batch-first as every RVE array
            floor = np.full((self._allocated().n_rve, 2, 2, 2, 2), np.nan)
        answers = {_FLOOR_KEY: floor}
        if self.preparation is not None:
            answers[_PRESSURE_KEY] = np.asarray(self._initial_pressure(), dtype=np.float64)
        committed = self._committed_response
        if committed is not None:
            answers[_COMMITTED_PREFIX + "stress"] = committed.stress
            answers[_COMMITTED_PREFIX + "tangent"] = committed.tangent
            for name, values in committed.fields.items():
                answers[f"{_COMMITTED_PREFIX}field_{name}"] = np.asarray(values)
        return answers

    def restore(self, path: str | Path) -> None:
        """Load the committed state written by :meth:`checkpoint` (RVE states with contact
        history, what reuse and ``continue`` carry between steps, the committed total ∇u,
        what unconfined and failed points are answered by); ValueError naming the material
        for another material's checkpoint, and for one written before the material kept its
        initial tangent (the floor of unconfined points: the committed RVEs no longer hold
        it, and another floor gives another run)."""
        with checkpoint_archive(path, "dem", ()):
            pass  # another material's checkpoint is refused by its name
        data = load_rve(path)
        if _FLOOR_KEY not in data.extra:
            raise ValueError(f"{path} was written before the DEM material kept its initial "
                             "tangent (the floor of the points that lose their confinement) "
                             "in its checkpoint: resumed, it would give another run than "
                             "the one that was stopped; start the run afresh")
        self.backend = self._backend(data, resume=True)
        self._reset_state(self.backend.n_rve)
        extra = data.extra
        if _GRAD_KEY in extra:
            self._committed_grad = np.array(extra[_GRAD_KEY], dtype=np.float64)
        floor = np.array(extra[_FLOOR_KEY], dtype=np.float64)
        self._initial_tangent = floor if floor.size and not np.isnan(floor).all() else None
        if _PRESSURE_KEY in extra:
            self._restored_pressure = np.array(extra[_PRESSURE_KEY], dtype=np.float64)
        if _COMMITTED_PREFIX + "stress" in extra:
            fields = {k.removeprefix(_COMMITTED_PREFIX + "field_"): np.array(v)
                      for k, v in extra.items() if k.startswith(_COMMITTED_PREFIX + "field_")}
            stress = np.array(extra[_COMMITTED_PREFIX + "stress"], dtype=np.float64)
            self._committed_response = MaterialResponse(
                stress=stress,
                tangent=np.array(extra[_COMMITTED_PREFIX + "tangent"], dtype=np.float64),
                status=np.zeros(len(stress), dtype=np.int8), fields=fields)
