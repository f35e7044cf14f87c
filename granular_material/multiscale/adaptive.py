"""Model only what the scene requires: a continuum twin at every Gauss point, a DEM RVE where
the twin is no longer trusted.

:class:`AdaptiveMaterial` answers the :class:`~granular_material.fem.materials.protocol.Material`
protocol for a mesh whose points start on a *twin*, a continuum material calibrated from the
scene's own RVE (the Mohr–Coulomb material of :func:`twin_from_rve`:
:func:`~granular_material.procedures.calibration.calibrate_mohr_coulomb` at the scene's
pressure), and move one by one to a DEM RVE of their own:

- **When.** A point still on the twin is tested by its :class:`SwitchCriterion`: its
  mobilised friction angle φ_mob = asin((σ1 − σ3)/(σ1 + σ3)) (compression positive) against
  a fraction of the twin's peak friction angle, and/or its accumulated shear strain
  γ = √((εxx − εyy)² + (2εxy)²) (of the total ∇u since the start, small-strain) against a
  threshold. By default (``in_step``) the test is made on every evaluation's twin answer: a
  point that passes it during a load step is DEM for that whole step, its RVE made from its
  state at the step's start, and the evaluation answers it by its RVE already; otherwise it
  is made on the committed state after each step, and the point is DEM from the next step
  on. With ``neighbours = "element"`` every point of an element that holds a switching
  point switches with it. A point that has switched stays DEM.
- **How** (``start``). Each switching point's RVE comes from the *source*: a copy of its
  one RVE (a scene's packing, which every point of an all-DEM run of a uniform start holds),
  or, with one RVE a point (a specimen's, each prepared from its own seed), the point's own
  RVE, the one it would hold in an all-DEM run, in its start state. ``"strain"``
  drives the copies through their points' whole deformation F so far in one DEM drive (the
  constant velocity gradient log F) and commits them: each RVE has its point's strain, its
  stress is the DEM's own. ``"stress"`` brings them by the anisotropic stress servo
  (:func:`~granular_material.procedures.anisotropic.bring_to_stress`, every component within
  1 % of the target's scale, the shear included) to their points' committed twin stresses:
  a target whose least principal compression is under the lowest an RVE is prepared to
  (:func:`~granular_material.procedures.anisotropic.lowest_target_pressure`) is lifted to it
  by an isotropic compression (its deviator kept), one past :data:`TARGET_FRICTION` of the
  peak is capped there. The RVEs of one switch form a *cohort*, a
  :class:`~granular_material.multiscale.material.DEMMaterial` of their own, driven from then
  on by their points' ∇u. A point whose RVE fails to be made (the drive fails, the servo
  breaks it or misses its target) stays on the twin for good (a warning, and
  :attr:`AdaptiveMaterial.missed`).
- **What is answered.** Twin points: the twin's stress, tangent and fields; DEM points: their
  cohort's. Each field either model reports is NaN where the other model answers; the
  field ``dem`` is 1 at DEM points, 0 on the twin. Costs are summed (``particle_steps`` is
  the cohorts' DEM work), and ``switch_particle_steps`` is the work of making the switched
  RVEs (reported once, by the evaluation that made them or, after a step, the next one).
  The twin is not moved at DEM points (they are given ∇u = 0): it keeps the state the point
  switched from.

The material is noisy when it may hold DEM points (always: the Newton defaults of the DEM
material apply, so that an adaptive run and an all-DEM run are solved alike).
``checkpoint``/``restore`` keep each point's model, every cohort's RVEs and the twin's state
in one file, so a resumed run is the run that was stopped.
"""

from __future__ import annotations

import json
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from granular_material.dem import DEMInstabilityError, RVEData, load_rve, save_rve
from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.continuum_start import cap_friction
from granular_material.fem.boundary_value.ground import lift_to_floor
from granular_material.fem.materials.checks import (
    CHECKPOINT_NAME_KEY,
    check_grad,
    checkpoint_archive,
)
from granular_material.fem.materials.protocol import (
    Material,
    MaterialResponse,
    ScikitFemInterface,
)
from granular_material.filesafe import write_whole
from granular_material.multiscale.material import DEMMaterial
from granular_material.multiscale.parameters import DEMMaterialParameters
from granular_material.multiscale.preparation import SERVO_TOLERANCES
from granular_material.multiscale.switching import (
    SwitchCriterion,
    check_start,
)
from granular_material.reference_values import TWIN_ELASTIC_WINDOW

__all__ = ["TARGET_FRICTION", "AdaptiveMaterial", "SwitchRecord", "adaptive_for_resume",
           "calibrated_adaptive", "twin_from_calibration", "twin_from_rve"]

#: the largest mobilised friction a switching RVE is brought to, as a fraction of the twin's
#: peak friction angle: a twin point at (or near) its peak asks the servo for the RVE's own
#: strength, which it reaches only by shearing on and on (on the reduced footing an RVE
#: servoed to 0.97 of the peak sheared its cell past the engine's limit); the deviator of
#: such a target is scaled down to this, its pressure kept, and the next step's Newton
#: iterations carry the difference
TARGET_FRICTION = 0.9
#: the name an adaptive material's checkpoint carries
_NAME = "adaptive"


def twin_from_rve(source: RVEData, pressure: float, initial_stress: np.ndarray,
                  device: str | None = "cpu", progress: bool = False,
                  elastic_window: float = TWIN_ELASTIC_WINDOW
                  ) -> tuple[Material, dict[str, Any]]:
    """The Mohr–Coulomb twin of the RVE ``source`` (its first RVE): drained biaxial DEM test
    at ``pressure`` P [Pa] read by
    :func:`~granular_material.procedures.calibration.calibrate_mohr_coulomb` (E and ν over
    the first ``elastic_window`` of axial strain, φ, ψ, the critical state and softening),
    at every point's ``initial_stress`` [Pa] (n, 2, 2). Returns the (not allocated) material
    and the calibration's ``as_dict()`` without its curve."""
    from granular_material.fem.materials.mohr_coulomb import MohrCoulomb
    from granular_material.procedures.calibration import calibrate_mohr_coulomb

    calibration = calibrate_mohr_coulomb(source.take([0]), confining=pressure, device=device,
                                         progress=progress, elastic_window=elastic_window)
    keywords = calibration.material_keywords()
    keywords["initial_stress"] = np.asarray(initial_stress, dtype=np.float64)
    described = calibration.as_dict()
    return MohrCoulomb(**keywords), {k: described[k] for k in ("parameters", "pressure",
                                                               "notes")}


def twin_from_calibration(path: str | Path, initial_stress: np.ndarray
                          ) -> tuple[Material, dict[str, Any]]:
    """The Mohr–Coulomb twin of a ``calibration.json`` written by ``granular-material
    calibrate`` (its ``parameters`` and ``pressure``), at every point's ``initial_stress``
    [Pa] (n, 2, 2); the material (not allocated) and the file's content. ParameterError
    naming ``calibration`` for a file without them."""
    from granular_material.procedures.calibration import PARAMETER_UNITS

    content = json.loads(Path(path).read_text())
    parameters = content.get("parameters") if isinstance(content, dict) else None
    missing = [k for k in PARAMETER_UNITS if not isinstance(parameters, dict)
               or k not in parameters]
    if missing or "pressure" not in content:
        raise ParameterError("calibration", f"{path} is no calibration.json of granular-"
                                            f"material calibrate (it lacks "
                                            f"{', '.join(missing) or 'pressure'})")
    twin = _twin(parameters, content["pressure"], initial_stress, str(path))
    return twin, {k: content[k] for k in ("parameters", "pressure")}


def _twin(parameters: dict[str, Any], pressure: float, initial_stress: np.ndarray,
          source: str) -> Material:
    """The Mohr–Coulomb twin of a calibration's ``parameters`` (those of
    :data:`~granular_material.procedures.calibration.PARAMETER_UNITS`) made at ``pressure``
    [Pa], at every point's ``initial_stress`` [Pa] (n, 2, 2); ``source``: where they come
    from."""
    import pandas as pd

    from granular_material.fem.materials.mohr_coulomb import MohrCoulomb
    from granular_material.procedures.calibration import PARAMETER_UNITS, Calibration

    calibration = Calibration(parameters={k: float(parameters[k]) for k in PARAMETER_UNITS},
                              readings={}, curve=pd.DataFrame(), pressure=float(pressure),
                              source=source)
    keywords = calibration.material_keywords()
    keywords["initial_stress"] = np.asarray(initial_stress, dtype=np.float64)
    return MohrCoulomb(**keywords)


@dataclass
class _Cohort:
    """The RVEs of the points that switched together: their indices and their material."""

    points: np.ndarray
    material: DEMMaterial


@dataclass
class SwitchRecord:
    """One switch: the commit after which it happened, the points that switched, those whose
    RVE missed its target, the servo's work [disc-steps], the targets lifted to the lowest
    prepared pressure and those capped at :data:`TARGET_FRICTION`, the seconds it took and
    the largest error of a reached RVE (of its target's scale)."""

    commit: int
    points: np.ndarray
    missed: np.ndarray
    particle_steps: int
    lifted: int = 0
    capped: int = 0
    seconds: float = 0.0
    error: float = 0.0


class AdaptiveMaterial(ScikitFemInterface):
    """A twin at every Gauss point, a DEM RVE where the twin is no longer trusted (see the
    module docstring).

    Args:
        twin: the continuum material (not yet allocated), e.g. :func:`twin_from_rve`'s.
        peak_friction: the twin's peak friction angle [deg] (the criterion's reference).
        dem: the DEM material's parameters, which every cohort is made with (``device``,
            ``shards``, ``tangent``, ``drive``, …).
        source: the RVEs the switching points' RVEs come from, in the state an all-DEM run's
            start from: one RVE, copied to every point, or one RVE a point (the point's
            own; :meth:`allocate` then checks the count).
        criterion: when a point switches.
        nqp: Gauss points an element (points ``e·nqp … e·nqp + nqp − 1`` are element e's).
        start: how a switching point's RVE starts
            (:data:`~granular_material.multiscale.switching.STARTS`).
        progress: show the servo's progress at a switch.
    """

    noisy = True

    def __init__(self, twin: Material, peak_friction: float, dem: DEMMaterialParameters,
                 source: RVEData, criterion: SwitchCriterion | None = None, nqp: int = 1,
                 start: str = "strain", progress: bool = False) -> None:
        if not isinstance(twin, Material):
            raise ParameterError("twin", f"{type(twin).__name__} does not implement the "
                                         "Material protocol")
        if not (isinstance(peak_friction, int | float) and 0 < peak_friction < 90):
            raise ParameterError("peak_friction", f"must be an angle in (0, 90) degrees, got "
                                                  f"{peak_friction!r}")
        if isinstance(nqp, bool) or not isinstance(nqp, int) or nqp < 1:
            raise ParameterError("nqp", f"must be an integer >= 1, got {nqp!r}")
        check_start(start)
        if dem.backend != "inprocess":
            raise ParameterError("backend", "an adaptive material holds its RVEs in this "
                                            f"process, not {dem.backend!r}")
        self.twin = twin
        self.peak_friction = float(peak_friction)
        self.dem = dem
        if not isinstance(source, RVEData) or source.n_rve < 1:
            raise ParameterError("source", "must be an RVEData of one RVE, or of one a point")
        self.source = source
        self.criterion = criterion or SwitchCriterion()
        self.nqp = nqp
        self.start = start
        self._deformation = np.zeros((0, 2, 2))
        self._committed_stress = np.zeros((0, 2, 2))
        self._increment: np.ndarray | None = None
        self.progress = progress
        self._measured: MaterialResponse | None = None
        self._cohorts: list[_Cohort] = []
        self._is_dem = np.zeros(0, dtype=bool)
        self._missed = np.zeros(0, dtype=bool)
        self._last: MaterialResponse | None = None
        self._dem_fields = tuple(self._source_response().fields)
        self._pending_steps = 0
        self._commits = 0
        #: every switch so far, in order (:class:`SwitchRecord`)
        self.switches: list[SwitchRecord] = []
        #: how the twin was made (a calibration's parameters and pressure), where known
        self.calibration: dict[str, Any] | None = None

    def _check_source(self, n_points: int) -> None:
        """ParameterError naming ``source`` unless it holds one RVE or ``n_points``."""
        if self.source.n_rve not in (1, n_points):
            raise ParameterError("source", f"holds {self.source.n_rve} RVEs: give one (copied "
                                           f"to every point) or one a point ({n_points})")

    def _sources(self, points: np.ndarray) -> RVEData:
        """The start RVEs of ``points`` (indices): copies of the one source RVE, or each
        point's own."""
        if self.source.n_rve == 1:
            return self.source.replicate(points.size)
        return self.source.take(points)

    def _source_pressure(self, points: np.ndarray) -> np.ndarray:
        """The mean pressure [Pa] of the start RVE of each of ``points``, compression
        positive (its measured stress)."""
        stress = self._source_response().stress
        index = np.zeros(points.size, dtype=np.int64) if self.source.n_rve == 1 else points
        return -0.5 * np.trace(stress[index], axis1=1, axis2=2)

    def _source_response(self) -> MaterialResponse:
        """The source RVEs' responses as they are (measured once: no step)."""
        if self._measured is None:
            from granular_material.multiscale.responses import measured_response

            self._measured = measured_response(self.source, self.dem.device, 1)
        return self._measured

    # -- what it holds ---------------------------------------------------------------------
    @property
    def n_points(self) -> int:
        """Number of Gauss points allocated (0 before :meth:`allocate`)."""
        return int(self._is_dem.size)

    @property
    def is_dem(self) -> np.ndarray:
        """Whether each point is answered by a DEM RVE, (n,) bool (a copy)."""
        return self._is_dem.copy()

    @property
    def dem_points(self) -> int:
        """Number of points answered by DEM RVEs."""
        return int(self._is_dem.sum())

    @property
    def missed(self) -> np.ndarray:
        """The points whose RVE the servo did not bring to their stress (they stay on the
        twin), indices."""
        return np.flatnonzero(self._missed)

    def progress_fields(self) -> dict[str, str]:
        """The progress bar's count of DEM points (of all)."""
        return {"DEM": f"{self.dem_points}/{self.n_points}"}

    def summary(self) -> dict[str, Any]:
        """What the run did (a run summary's ``adaptivity``): its criterion and start, its
        twin's calibration (``calibration``, where the run set it), its DEM points and every
        switch."""
        c = self.criterion
        return {
            "mobilised_fraction": c.mobilised_fraction, "shear_strain": c.shear_strain,
            "neighbours": c.neighbours, "start": self.start,
            "switch": "in-step" if c.in_step else "after-step",
            "twin": self.calibration,
            "dem_points_final": self.dem_points, "gauss_points": self.n_points,
            "missed_points": self.missed.tolist(),
            "switches": [{"after_commit": s.commit, "points": int(s.points.size),
                          "missed": int(s.missed.size), "lifted": s.lifted,
                          "capped": s.capped, "particle_steps": s.particle_steps,
                          "seconds": round(s.seconds, 3), "largest_error": s.error}
                         for s in self.switches],
        }

    # -- protocol --------------------------------------------------------------------------
    def allocate(self, n_points: int) -> None:
        """Allocate the twin at ``n_points`` points, every one on the twin. ParameterError
        naming ``source`` where it holds neither one RVE nor one a point."""
        self._check_source(int(n_points))
        self.twin.allocate(n_points)
        n = int(self.twin.n_points)
        self._cohorts = []
        self._is_dem = np.zeros(n, dtype=bool)
        self._deformation = np.repeat(np.eye(2)[None], n, axis=0)
        self._committed_stress = self.twin.evaluate(np.zeros((n, 2, 2))).stress.copy()
        self.twin.revert()
        self._missed = np.zeros(n, dtype=bool)
        self._track_allocate(n)
        self._last = None

    def evaluate(self, grad_u: np.ndarray) -> MaterialResponse:
        """σ [Pa] (n, 2, 2), D [Pa] (n, 2, 2, 2, 2), status and fields for ∇u [-] (n, 2, 2)
        since the last commit: each point's from its model (see the module docstring)."""
        n = self.n_points
        grad = check_grad(grad_u, n)
        self._track_evaluate(grad)
        self._increment = grad
        r = self.twin.evaluate(np.where(self._is_dem[:, None, None], 0.0, grad))
        if self.criterion.in_step:  # a point that passes the threshold in this step is DEM
            points = self.switching(r.stress, self.committed_grad_u + grad)  # in all of it
            if points.size:
                self._switch(points, self._committed_stress)
                r = self.twin.evaluate(np.where(self._is_dem[:, None, None], 0.0, grad))
        dem = self._is_dem
        stress, tangent = r.stress.copy(), r.tangent.copy()
        status = r.status.copy()
        reasons = np.asarray(r.reasons, dtype=object).copy()
        costs: dict[str, int | float] = dict(r.costs)
        timings = {k: float(v) for k, v in r.timings.items()}
        fields = {k: np.where(dem, np.nan, np.asarray(v, dtype=np.float64).reshape(-1))
                  for k, v in r.fields.items()}
        for name in self._dem_fields:
            fields.setdefault(name, np.full(n, np.nan))
        for cohort in self._cohorts:
            index = cohort.points
            c = cohort.material.evaluate(grad[index])
            stress[index], tangent[index] = c.stress, c.tangent
            status[index], reasons[index] = c.status, c.reasons
            for key, value in c.costs.items():
                costs[key] = costs.get(key, 0) + value
            for key, value in c.timings.items():
                timings[key] = timings.get(key, 0.0) + float(value)
            for key, values in c.fields.items():
                fields.setdefault(key, np.full(n, np.nan))[index] = np.asarray(
                    values, dtype=np.float64).reshape(-1)
        for key in ("particle_steps", "dem_steps", "rve_evaluations"):
            costs.setdefault(key, 0)
        costs["switch_particle_steps"] = self._pending_steps
        self._pending_steps = 0
        fields["dem"] = dem.astype(np.float64)
        response = MaterialResponse(stress=stress, tangent=tangent, status=status,
                                    costs=costs, fields=fields, reasons=reasons,
                                    timings=timings)
        self._last = response
        return response

    def commit(self) -> None:
        """Commit the twin and every cohort (and each point's deformation and stress); with
        ``in_step`` False, then switch the points whose committed state meets the
        criterion."""
        self.twin.commit()
        for cohort in self._cohorts:
            cohort.material.commit()
        last = self._last
        failed = None
        if last is not None:
            failed = np.zeros(self.n_points, dtype=bool)
            failed[last.failed_points()] = True
        self._track_commit(failed)
        if self._increment is not None:  # F ← (I + ∇u) F: the points' whole deformation
            self._deformation = (np.eye(2) + self._increment) @ self._deformation
            self._increment = None
        self._commits += 1
        if last is not None:
            self._committed_stress = last.stress.copy()
            if not self.criterion.in_step:
                points = self.switching(last.stress, self.committed_grad_u)
                if points.size:
                    self._switch(points, last.stress)
        self._last = None

    def revert(self) -> None:
        """Revert the twin and every cohort."""
        self.twin.revert()
        for cohort in self._cohorts:
            cohort.material.revert()
        self._track_revert()
        self._last = None

    def hold_tangent(self, hold: bool) -> None:
        """Pass ``hold`` to every cohort (the Newton driver's ``tangent_update="hold"``)."""
        for cohort in self._cohorts:
            cohort.material.hold_tangent(hold)

    # -- the switch -------------------------------------------------------------------------
    def switching(self, stress: np.ndarray, grad_u: np.ndarray) -> np.ndarray:
        """The twin points that switch at ``stress`` [Pa] (n, 2, 2) and the total ∇u [-]
        (n, 2, 2) (their neighbours included), indices."""
        met = self.criterion.met(stress, grad_u, self.peak_friction)
        met &= ~self._is_dem & ~self._missed
        if self.criterion.neighbours == "element" and met.any():
            elements = np.unique(np.flatnonzero(met) // self.nqp)
            met[(elements[:, None] * self.nqp + np.arange(self.nqp)).reshape(-1)] = True
            met &= ~self._is_dem & ~self._missed
        return np.flatnonzero(met)

    def _switch(self, points: np.ndarray, stress: np.ndarray) -> None:
        """Give ``points`` their RVEs in the committed state (:attr:`start` says how: the
        committed deformation, or the committed ``stress`` [Pa] (n, 2, 2))."""
        import time

        began = time.perf_counter()
        if self.start == "strain":
            material, reached, work, error, lifted, capped = self._by_strain(points)
        else:
            material, reached, work, error, lifted, capped = self._by_stress(points, stress)
        self._pending_steps += work
        missed = points[~reached]
        if missed.size:
            self._missed[missed] = True
            warnings.warn(f"{missed.size} of {points.size} switching points' RVEs did not "
                          f"reach their {'deformation' if self.start == 'strain' else 'stress'}"
                          f" (points {missed[:8].tolist()}{' …' if missed.size > 8 else ''}):"
                          " they stay on the twin", UserWarning, stacklevel=3)
        if material is not None:
            self._cohorts.append(_Cohort(points[reached], material))
            self._is_dem[points[reached]] = True
        self.switches.append(SwitchRecord(
            commit=self._commits, points=points[reached], missed=missed,
            particle_steps=work, lifted=lifted, capped=capped,
            seconds=time.perf_counter() - began, error=error))

    def _by_strain(self, points: np.ndarray
                   ) -> tuple[DEMMaterial | None, np.ndarray, int, float, int, int]:
        """The points' start RVEs (:meth:`_sources`) driven through their deformation F − I
        in one evaluation (the DEM's constant velocity gradient log F), committed; a point
        whose RVE fails stays on the twin. The cohort, which points reached, the work
        [disc-steps], the largest error (0: the deformation is reached exactly) and no
        target lifted or capped."""
        reached = np.ones(points.size, dtype=bool)
        work = 0
        pressure = self._source_pressure(points)
        grad = self._deformation[points] - np.eye(2)
        while reached.any():
            kept = np.flatnonzero(reached)
            material = DEMMaterial.holding(self._sources(points[kept]), self.dem,
                                           pressure[kept])
            response = material.evaluate(grad[kept])
            work += int(response.costs.get("particle_steps", 0))
            if response.ok:
                material.commit()
                return material, reached, work, 0.0, 0, 0
            causes = response.failure_causes()  # not those its batch's failure sent back
            reached[kept[causes if causes.size else response.failed_points()]] = False
        return None, reached, work, 0.0, 0, 0

    def _by_stress(self, points: np.ndarray, stress: np.ndarray
                   ) -> tuple[DEMMaterial | None, np.ndarray, int, float, int, int]:
        """The points' start RVEs (:meth:`_sources`) brought by the stress servo to their
        committed stresses (lifted to the lowest prepared pressure, capped at
        :data:`TARGET_FRICTION`); an RVE that the servo breaks or does not bring to its
        target stays on the twin. The cohort, which points reached, the work
        [disc-steps], the largest error of the target's scale, the targets lifted and
        capped."""
        from granular_material.procedures.anisotropic import (
            bring_to_stress,
            lowest_target_pressure,
        )
        from granular_material.procedures.packing import PackingParameters

        target = 0.5 * (stress[points] + np.swapaxes(stress[points], 1, 2))
        radius = self.source.radius
        lowest = lowest_target_pressure(PackingParameters(
            meta=self.source.meta, radius_range=(float(radius.min()), float(radius.max()))))
        target, lifted = lift_to_floor(target, lowest)
        target, capped = cap_friction(target, TARGET_FRICTION * self.peak_friction)
        reached = np.zeros(points.size, dtype=bool)
        trying = np.arange(points.size)
        work = 0
        while trying.size:  # an RVE that the servo breaks is left out, the others redone
            try:
                data, servo = bring_to_stress(self._sources(points[trying]),
                                              target[trying], device=self.dem.device,
                                              shards=self.dem.shards, strict=False,
                                              progress=self.progress,
                                              **SERVO_TOLERANCES)
            except DEMInstabilityError as exc:
                broken = np.zeros(trying.size, dtype=bool)
                broken[np.asarray(exc.rve, dtype=int)] = True
                trying = trying[~broken]
                continue
            work += int(np.asarray(servo.rve_steps).sum()) * int(self.source.n_disc)
            done = np.asarray(servo.reached, dtype=bool)
            reached[trying] = done
            if not done.any():
                break
            kept = np.flatnonzero(reached)
            pressure = -0.5 * np.trace(target[kept], axis1=1, axis2=2)
            material = DEMMaterial.holding(data.take(np.flatnonzero(done)), self.dem,
                                           pressure)
            error = float(np.asarray(servo.error)[done].max())
            return material, reached, work, error, lifted.size, capped.size
        return None, reached, work, 0.0, lifted.size, capped.size

    # -- checkpoints -------------------------------------------------------------------------
    def checkpoint(self, path: str | Path) -> None:
        """Write the committed state to ``path``: one ``.npz`` holding the twin's and every
        cohort's own checkpoints (bytes), the cohorts' points, each point's model, the
        source RVE, the committed total ∇u and deformation, and how the twin was made
        (:attr:`calibration`, JSON: a resume makes the twin from it,
        :func:`adaptive_for_resume`); whole or not at all."""
        arrays: dict[str, np.ndarray] = {
            CHECKPOINT_NAME_KEY: np.array(_NAME), "is_dem": self._is_dem,
            "missed": self._missed, "grad_u": self.committed_grad_u,
            "deformation": self._deformation, "stress": self._committed_stress,
            "commits": np.array(self._commits), "pending": np.array(self._pending_steps),
            "cohorts": np.array(len(self._cohorts))}
        if self.calibration is not None:
            arrays["calibration"] = np.array(json.dumps(self.calibration))
        with tempfile.TemporaryDirectory(prefix="adaptive-") as folder:
            own = Path(folder) / "twin.npz"
            self.twin.checkpoint(own)
            arrays["twin"] = np.frombuffer(own.read_bytes(), dtype=np.uint8)
            own = Path(folder) / "source.npz"
            save_rve(own, self.source, compress=False, validate=False)
            arrays["source"] = np.frombuffer(own.read_bytes(), dtype=np.uint8)
            for k, cohort in enumerate(self._cohorts):
                own = Path(folder) / f"cohort_{k}.npz"
                cohort.material.checkpoint(own)
                arrays[f"cohort_{k}"] = np.frombuffer(own.read_bytes(), dtype=np.uint8)
                arrays[f"cohort_{k}_points"] = cohort.points

        def write(tmp: Path) -> None:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)

        write_whole(path, write)

    def restore(self, path: str | Path) -> None:
        """Read a :meth:`checkpoint`: the twin, every cohort and each point's model.
        ValueError for another material's checkpoint."""
        keys = ("is_dem", "missed", "grad_u", "deformation", "stress", "commits", "pending",
                "cohorts", "twin", "source")
        with checkpoint_archive(path, _NAME, keys) as data:
            is_dem = np.array(data["is_dem"], dtype=bool)
            missed = np.array(data["missed"], dtype=bool)
            grad = np.array(data["grad_u"], dtype=np.float64)
            deformation = np.array(data["deformation"], dtype=np.float64)
            committed_stress = np.array(data["stress"], dtype=np.float64)
            commits, pending = int(data["commits"]), int(data["pending"])
            count = int(data["cohorts"])
            blobs = {"twin": np.array(data["twin"]), "source": np.array(data["source"])}
            for k in range(count):
                blobs[f"cohort_{k}"] = np.array(data[f"cohort_{k}"])
                blobs[f"cohort_{k}_points"] = np.array(data[f"cohort_{k}_points"])
        with tempfile.TemporaryDirectory(prefix="adaptive-") as folder:
            def unpack(name: str) -> Path:
                return _unpacked(blobs[name], Path(folder) / f"{name}.npz")

            self.twin.restore(unpack("twin"))
            self.source = load_rve(unpack("source"))
            self._measured = None
            cohorts = []
            for k in range(count):
                material = DEMMaterial(self.dem)
                material.restore(unpack(f"cohort_{k}"))
                cohorts.append(_Cohort(blobs[f"cohort_{k}_points"].astype(np.int64),
                                       material))
        if self.twin.n_points != is_dem.size:
            raise ValueError(f"{path}: the twin holds {self.twin.n_points} points, the "
                             f"models {is_dem.size}")
        self._cohorts = cohorts
        self._is_dem, self._missed = is_dem, missed
        self._track_allocate(int(is_dem.size))
        self._committed_grad = grad
        self._deformation = deformation
        self._committed_stress = committed_stress
        self._increment = None
        self._commits, self._pending_steps = commits, pending
        self._last = None


def _unpacked(blob: np.ndarray, path: Path) -> Path:
    """``path``, written whole with the bytes ``blob`` (a file a checkpoint holds as bytes:
    the twin's, a cohort's or the source RVEs' own)."""
    data = blob.tobytes()
    write_whole(path, lambda tmp: tmp.write_bytes(data))
    return path


def calibrated_adaptive(source: RVEData, dem: DEMMaterialParameters, pressure: float,
                        initial_stress: np.ndarray, criterion: SwitchCriterion, *, nqp: int,
                        start: str = "strain", calibration: str | Path | None = None,
                        elastic_window: float = TWIN_ELASTIC_WINDOW, progress: bool = False
                        ) -> AdaptiveMaterial:
    """The adaptive material of the RVEs ``source`` (one, or one a point) and the DEM
    parameters ``dem``: its twin read from the ``calibration`` file
    (:func:`twin_from_calibration`) or, without one, the first RVE calibrated at ``pressure``
    [Pa] (:func:`twin_from_rve`), every point starting on it at ``initial_stress`` [Pa]
    (n, 2, 2); its ``calibration`` says how the twin was made. Not allocated."""
    if calibration is not None:
        twin, made = twin_from_calibration(calibration, initial_stress)
    else:
        twin, made = twin_from_rve(source, pressure, initial_stress, device=dem.device,
                                   progress=progress, elastic_window=elastic_window)
    material = AdaptiveMaterial(twin, made["parameters"]["friction_angle"], dem, source,
                                criterion, nqp=nqp, start=start, progress=progress)
    material.calibration = made
    return material


def adaptive_for_resume(path: str | Path, dem: DEMMaterialParameters,
                        initial_stress: np.ndarray, criterion: SwitchCriterion, *, nqp: int,
                        start: str = "strain", progress: bool = False,
                        ) -> AdaptiveMaterial | None:
    """The adaptive material a resume restores the checkpoint ``path`` into, made from what
    the checkpoint holds: the twin from the calibration it was made with, at every point's
    ``initial_stress`` [Pa] (n, 2, 2), and the source RVEs, so that a resume neither
    prepares RVEs nor calibrates again. The material :func:`calibrated_adaptive` made for
    the run, not allocated and not yet restored (:meth:`AdaptiveMaterial.restore`); None
    for a checkpoint written before it held its calibration."""
    with checkpoint_archive(path, _NAME, ("source",)) as data:
        if "calibration" not in data.files:
            return None
        made = json.loads(str(data["calibration"]))
        blob = np.array(data["source"])
    with tempfile.TemporaryDirectory(prefix="adaptive-") as folder:
        source = load_rve(_unpacked(blob, Path(folder) / "source.npz"))
    parameters = made["parameters"]
    twin = _twin(parameters, made["pressure"], initial_stress, f"{path} (its calibration)")
    material = AdaptiveMaterial(twin, parameters["friction_angle"], dem, source, criterion,
                                nqp=nqp, start=start, progress=progress)
    material.calibration = made
    return material
