"""The DEM material in a run specification: its own parameters (:class:`DEMParameters`) and
what a run asks of it before any work (checks, the discs it will hold, its summary) and to
build it (:func:`material_keywords`). :class:`~granular_material.multiscale.DEMMaterial` offers
these as its ``Parameters`` and its run hooks."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from granular_material.checks import (
    RVE_MATERIAL_DEFAULTS,
    WordedError,
    packing_parameters,
    rve_file_shape,
    rve_material_given,
    rve_meta,
)
from granular_material.dem.tangents import TANGENTS
from granular_material.errors import ParameterError
from granular_material.multiscale.parameters import DRIVES, REUSE_CORRECTIONS, DEMRVEs
from granular_material.reference_values import DEFAULT_DISCS
from granular_material.vocabulary import accept_old_keywords

if TYPE_CHECKING:
    from granular_material.fem.materials.run_context import RunContext
    from granular_material.procedures.packing import PackingParameters

__all__ = ["RUN_TANGENT", "SHARE_TOLERANCE", "TWIN_AXIAL_STRAIN", "TWIN_RVES", "DEMParameters",
           "check_run", "continuum_twin", "lowest_pressure",
           "material_keywords", "problem_keywords", "run_summary", "unit_weight"]

#: a boundary-value problem's default: points whose initial stresses agree within this
#: fraction of their σv share one prepared RVE. Measured on a 96-point geostatic footing
#: (64 discs, 8 depths): sharing identical targets alone makes 8 packings in ~1 s against
#: 96 in 8-16 s; 0.02 keeps every component within ~0.1 % (RMS) of its target, 0.05 adds
#: ~2 % for 3 fewer packings; on an unstructured mesh every point has its own depth, and
#: 0.02 keeps the packings to ~1 per 2 % of σv
SHARE_TOLERANCE = 0.02

#: the tangent of a run (and so of the commands) where its spec names none: the condensed
#: tangent with every touching contact sticking, held over each increment with Aitken
#: relaxation by the commands' Newton loop
#: (:data:`~granular_material.fem.solver.defaults.NOISY_DEFAULTS`;
#: issue 26: plain Newton reaches 10 % with it too). A material built in Python defaults to
#: the objective tangent instead (:class:`~granular_material.multiscale.parameters.DEMDriving`):
#: a user's own loop asks for a tangent at every iterate, and a condensation costs more than
#: the DEM run of an evaluation.
RUN_TANGENT = "condensed-sticking"


@accept_old_keywords("dem")
@dataclass(frozen=True, kw_only=True)
class DEMParameters(DEMRVEs):
    """The DEM material of a run (SI units, angles in rad): the fields of
    :class:`~granular_material.multiscale.parameters.DEMRVEs` (how the RVEs are driven and
    where they come from, each documented there; the tangent defaults to
    :data:`RUN_TANGENT`), and

    Attributes:
        independent: single element: four independent RVEs instead of one replicated.
        compare_dem: single element: also the pure-DEM drained biaxial test of RVE 0.
        target_void_ratio … thickness: the material and packing of prepared RVEs (those of
            ``granular-material prepare``; Wu et al. 2025, Table 1 by default): 2D void ratio
            e0 [-], radii [m], contact law, kn and kt [N/m], ``contact_young`` [Pa] and
            ``kt_over_kn`` [-] (law frictmat), ``contact_friction_angle`` [rad] (the contacts'
            friction; its old name ``friction_angle`` is still read, with a
            :class:`~granular_material.vocabulary.RenamedWarning`, as is ``young``), damping
            [-], density [kg/m³], thickness [m].

    The run's problem gives the confining pressure, its ``[run]`` fields the device, CPU
    shards and backend (:func:`material_keywords`).
    """

    #: the RVE tangents the material offers, its drives and corrections of reused responses
    tangents: ClassVar[tuple[str, ...]] = tuple(TANGENTS)
    drives: ClassVar[tuple[str, ...]] = DRIVES
    reuse_corrections: ClassVar[tuple[str, ...]] = REUSE_CORRECTIONS
    #: discs per prepared RVE where neither the spec nor the specimen's scale says
    default_particles: ClassVar[int] = DEFAULT_DISCS

    tangent: str = RUN_TANGENT
    independent: bool = False
    compare_dem: bool = False
    target_void_ratio: float | None = RVE_MATERIAL_DEFAULTS["target_void_ratio"]
    radius_min: float = RVE_MATERIAL_DEFAULTS["radius_min"]
    radius_max: float = RVE_MATERIAL_DEFAULTS["radius_max"]
    law: str = RVE_MATERIAL_DEFAULTS["law"]
    kn: float = RVE_MATERIAL_DEFAULTS["kn"]
    kt: float = RVE_MATERIAL_DEFAULTS["kt"]
    contact_young: float = RVE_MATERIAL_DEFAULTS["contact_young"]
    kt_over_kn: float = RVE_MATERIAL_DEFAULTS["kt_over_kn"]
    contact_friction_angle: float = RVE_MATERIAL_DEFAULTS["contact_friction_angle"]
    damping: float = RVE_MATERIAL_DEFAULTS["damping"]
    density: float = RVE_MATERIAL_DEFAULTS["density"]
    thickness: float = RVE_MATERIAL_DEFAULTS["thickness"]


def _particles(p: DEMParameters, context: RunContext) -> int:
    """The discs per RVE the run holds: the file's, else the spec's, the scale's or 400."""
    if p.rve is not None:
        return rve_file_shape(p.rve)[1]
    return p.particles or context.scale_discs or DEFAULT_DISCS


def _replicate(p: DEMParameters, context: RunContext) -> bool:
    """single-element: whether one RVE is copied to the element's points (else one each)."""
    n_points = context.n_points
    if context.test != "single-element":
        return False
    if p.rve is None:
        return not p.independent
    n_rve, _ = rve_file_shape(p.rve)
    if n_rve == n_points:
        return False
    if n_rve != 1:
        raise ParameterError("rve", f"{p.rve} holds {n_rve} RVEs; single-element takes 1 "
                                    f"(replicated to the {n_points} Gauss points) or "
                                    f"{n_points} (one per point)")
    if p.independent:
        raise ParameterError("independent", f"needs {n_points} RVEs, `rve` {p.rve} holds 1")
    return True


def _packing(p: DEMParameters, context: RunContext) -> PackingParameters | None:
    """The material and packing of the RVEs the run prepares (None with an RVE file, which
    carries its own: then no RVE material field may be set)."""
    if p.rve is None:
        return packing_parameters(p, _particles(p, context), context.confining, "confining")
    given = rve_material_given(p)
    if given:
        named = ", ".join(f"`{name}`" for name in given)
        raise WordedError(given[0], f"{named} set{'s' if len(given) == 1 else ''} the material "
                                    f"of the RVEs a run prepares, but `rve` {p.rve} carries "
                                    "its own (give them to `granular-material prepare` "
                                    "instead)")
    return None


def check_run(p: DEMParameters, context: RunContext) -> int:
    """Before any work: the parameters can run in ``context``; the discs per Gauss point."""
    if p.rve is not None and not p.rve.exists():
        raise ParameterError("rve", f"{p.rve} does not exist")
    if p.reuse_tol > 0 and context.convergence in ("displacement", "residual-displacement"):
        raise ParameterError("reuse_tol", f"{p.reuse_tol:g} needs `convergence` force (with "
                                          "`relaxation` aitken, as measured): a reused RVE "
                                          "answers the same stress for any change of grad u "
                                          "below the tolerance, so the Newton corrections "
                                          "stall above `rtol` and no increment passes the "
                                          "displacement test")
    for name in ("independent", "compare_dem"):
        if getattr(p, name) and context.test != "single-element":
            raise ParameterError(name, "is single-element's")
    return _particles(p, context)


def material_keywords(p: DEMParameters, context: RunContext) -> dict[str, Any]:
    """The keywords of :class:`~granular_material.multiscale.DEMMaterial` for the run (the
    spec's own settings, each passed on as it is, and the run's), its inputs checked first
    (its ``for_run`` hook builds the material of them)."""
    driving = {f.name: getattr(p, f.name) for f in fields(DEMRVEs)}
    return {**driving, "particles": _particles(p, context), "confining": context.confining,
            "replicate": _replicate(p, context), "device": context.device,
            "shards": context.shards, "backend": context.backend,
            "packing": _packing(p, context), "progress": context.progress}


def run_summary(p: DEMParameters, context: RunContext) -> dict[str, Any]:
    """What the run's summary says of the material: its RVEs' (``rve_material``), SI units,
    angles in rad (``friction_angle``, as the RVE file's meta calls it)."""
    packing = _packing(p, context)
    if packing is None:
        from granular_material.dem import load_rve

        data = load_rve(p.rve)
        meta, source, target = data.meta, str(p.rve), None
        radii = (float(data.radius.min()), float(data.radius.max()))
    else:
        meta, source, target = packing.meta, "prepared", packing.target_void_ratio
        radii = packing.radius_range
    return {"rve_material": {
        "source": source, "radius_min": radii[0], "radius_max": radii[1],
        "target_void_ratio": target, "stiffness": dict(meta.stiffness),
        "friction_angle": meta.friction_angle, "damping": meta.damping,
        "density": meta.density, "thickness": meta.thickness}}



def problem_keywords(p: DEMParameters, context: RunContext,
                     initial_stress: np.ndarray) -> dict[str, Any]:
    """The keywords of :class:`~granular_material.multiscale.DEMMaterial` for a
    boundary-value problem whose Gauss points start at ``initial_stress`` [Pa] (n, 2, 2),
    tension positive: each point's RVE is brought to its own tensor (the shear included),
    points whose targets agree within :data:`SHARE_TOLERANCE` of their σv sharing one
    preparation (a uniform state: one RVE, prepared or the file's, copied to every point, as
    Guo & Zhao's footing and wall have it); an RVE file of n RVEs gives one a point."""
    keywords = material_keywords(p, context)
    sigma = np.asarray(initial_stress, dtype=np.float64)
    n_rve = rve_file_shape(p.rve)[0] if p.rve is not None else 1
    keywords["replicate"] = n_rve != context.n_points
    keywords["confining"] = float(np.max(-0.5 * np.trace(sigma, axis1=1, axis2=2)))
    if p.rve is None:
        keywords["packing"] = packing_parameters(p, _particles(p, context),
                                                 keywords["confining"], "initial")
    keywords["initial_stress"] = tuple(tuple(tuple(float(v) for v in row) for row in s)
                                       for s in sigma)
    keywords["share_tolerance"] = SHARE_TOLERANCE if n_rve != context.n_points else None
    return keywords


def unit_weight(p: DEMParameters, gravity: float) -> float:
    """The dry unit weight [N/m³] of the RVEs: ρ_s·g/(1 + e), the grain density ρ_s and void
    ratio e of the RVE file (its first RVE), else of the packings the run prepares (their
    target e0, or e = 0.2 where none is set)."""
    if p.rve is not None:
        from granular_material.dem import load_rve
        from granular_material.dem.homogenization import void_ratio

        data = load_rve(p.rve)
        e = float(void_ratio(data.radius[:1], data.cell[:1])[0])
        return float(data.meta.density * gravity / (1.0 + e))
    e = p.target_void_ratio if p.target_void_ratio is not None else 0.2
    return float(p.density * gravity / (1.0 + e))


def lowest_pressure(p: DEMParameters) -> float:
    """The lowest least principal compression [Pa] an RVE of ``p`` starts at: that of
    :func:`~granular_material.procedures.anisotropic.lowest_target_pressure` (2 % of the
    consolidation floor of the contact law, measured: 15 Pa for kn = 3e6 N/m and a 0.1 m
    thickness), of the RVE file's contact law and radii, else of the packings the run
    prepares. A packing of discs carries stress only while confined: below this it is not
    prepared."""
    from granular_material.procedures.anisotropic import lowest_target_pressure
    from granular_material.procedures.packing import PackingParameters

    if p.rve is not None:
        from granular_material.dem import load_rve

        data = load_rve(p.rve)
        meta, radii = data.meta, (float(data.radius.min()), float(data.radius.max()))
    else:
        meta, radii = rve_meta(p), (p.radius_min, p.radius_max)
    return float(lowest_target_pressure(PackingParameters(meta=meta, radius_range=radii)))


#: RVEs whose drained biaxial tests calibrate a DEM material's continuum twin for a
#: boundary-value problem's continuum start, and the axial strain they go to (past the peak
#: of a 64-disc RVE, 1.4–2.8 % measured at 10 kPa): 4 RVEs of 64 discs, 0.5 s to prepare and
#: 0.7 s to test on a CPU
TWIN_RVES = 4
TWIN_AXIAL_STRAIN = 0.03


def continuum_twin(p: DEMParameters, pressure: float, device: str | None = "cpu",
                   ) -> dict[str, Any]:
    """The Mohr–Coulomb twin of the RVEs at ``pressure`` [Pa]: :data:`TWIN_RVES` of them
    (the file's first, else packings prepared from the run's seed at ``pressure``, at least
    the packing's consolidation floor) in drained biaxial tests to
    :data:`TWIN_AXIAL_STRAIN`
    (:func:`~granular_material.procedures.calibration.calibrate_mohr_coulomb`). Returns
    ``young`` [Pa], ``poisson`` [-] and ``friction_angle`` [°] (the peak, the RVEs' mean),
    ``friction_angles`` (each RVE's), ``pressure`` [Pa] and ``rves``."""
    from granular_material.procedures.calibration import calibrate_mohr_coulomb
    from granular_material.procedures.packing import min_pressure, prepare_packing

    if p.rve is not None:
        from granular_material.dem import load_rve

        source = load_rve(p.rve)
        data = source.take(np.arange(min(TWIN_RVES, source.n_rve)))
        radii = (float(source.radius.min()), float(source.radius.max()))
        pressure = max(float(pressure), min_pressure(source.meta, radii))
    else:
        meta, radii = rve_meta(p), (p.radius_min, p.radius_max)
        pressure = max(float(pressure), min_pressure(meta, radii))
        particles = p.particles or DEFAULT_DISCS
        data = prepare_packing(n_disc=particles, n_rve=TWIN_RVES, seed=p.seed,
                               pressure=pressure, meta=meta, radius_range=radii,
                               target_void_ratio=p.target_void_ratio,
                               device=device).to_data()
    calibration = calibrate_mohr_coulomb(data, confining=pressure,
                                         axial_strain=TWIN_AXIAL_STRAIN, device=device)
    parameters = calibration.parameters
    return {"young": float(parameters["young"]), "poisson": float(parameters["poisson"]),
            "friction_angle": float(parameters["friction_angle"]),
            "friction_angles": [float(v) for v in
                                calibration.readings["friction_angle"].per_rve],
            "pressure": float(pressure), "rves": int(data.n_rve)}
