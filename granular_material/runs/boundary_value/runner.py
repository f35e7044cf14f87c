"""Run a boundary-value problem
(:class:`~granular_material.runs.boundary_value.spec.BoundaryValueSpec`):
build the mesh, boundaries, conditions and initial state, the material at every Gauss point,
and step the Newton solver through the loading, writing as it goes.

The run folder gets:

- ``steps.csv``: one row per committed step (step 0 is the initial state): the load factor,
  Newton's iterations, cut-backs and residuals, the wall time, the failed and unconfined
  points, and for every boundary that carries a condition its force ``{name}_force_x``,
  ``{name}_force_y`` [N/m] (the reaction of the supports on the body, or the load a pressure
  puts on it) and its mean displacement ``{name}_displacement_x``, ``_y`` [m]; a rigid body
  also ``{name}_displacement`` [m] along its motion (a footing pushed down: its settlement,
  also as ``{name}_settlement``); then the mean displacement ``{name}_displacement_x``,
  ``_y`` [m] of every other named boundary (each name of ``[boundaries]``, and every
  boundary group of a mesh file: a crest, a slope face);
- ``points.npy``: every Gauss point at every step (coordinates, stress [Pa], strain, shear
  strain, mean pressure, the material's own fields such as the void ratio; with materials by
  region, the point's ``region`` and NaN in a field its region's material does not report),
  a NumPy table of records (:mod:`~granular_material.results.point_table`), appended a step
  at a time before that step's ``steps.csv`` row (read it with
  :func:`~granular_material.results.writers.read_points`, also of a killed run); with
  ``points_csv``, also as text, ``points.csv``;
- ``fields.xdmf``: the same for ParaView at every committed step (its values in
  ``fields.h5``, HDF5);
- ``load_displacement.png``, ``mechanism.png`` and ``summary.json``.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.errors import ParameterError
from granular_material.fem import NewtonError, NewtonSolver, PointStatus, StepRecord
from granular_material.fem.boundary_value.boundaries import select_boundaries
from granular_material.fem.boundary_value.conditions import (
    Displacement,
    Fixed,
    Gravity,
    Pressure,
    RigidBody,
    Roller,
    build_problem,
)
from granular_material.fem.boundary_value.ground import ground_stress, lift_to_floor, overburden
from granular_material.fem.boundary_value.initial_stress import geostatic_stress
from granular_material.fem.boundary_value.meshes import MeshData, read_mesh, rectangle_mesh
from granular_material.fem.forms import gauss_points_grad
from granular_material.fem.materials.regions import RegionalMaterial
from granular_material.multiscale.confinement import UNCONFINED_FRACTION
from granular_material.results.bvp_plots import plot_load_displacement, plot_mechanism
from granular_material.results.writers import (
    FieldWriter,
    SyncClock,
    sync_files,
    write_csv,
    write_json,
    write_points,
)
from granular_material.runs.boundary_value.checks import check_disk, check_memory, generated_size
from granular_material.runs.boundary_value.continuum import continuum_stress, settles
from granular_material.runs.boundary_value.material import (
    material_for_problem,
    region_elements,
    region_unit_weights,
    unit_weight_of,
)
from granular_material.runs.boundary_value.phases import (
    PhasePlan,
    ends_phase,
    inward_direction,
    phase_pressures,
    phase_view,
    phased_figure,
    phases_summary,
    reported_gradient,
    run_phases,
    with_phase,
)
from granular_material.runs.boundary_value.reduction import (
    PHASE,
    reduction_columns,
    reduction_figure,
    reduction_summary,
    run_reduction,
)
from granular_material.runs.boundary_value.resume import (
    open_bvp_checkpoint,
    remember,
    start_bvp_checkpoint,
)
from granular_material.runs.boundary_value.spec import BoundaryValueSpec, ConditionSpec
from granular_material.runs.run_folder import interrupted_error, starting
from granular_material.runs.spec import SpecError

#: the files a run writes into its folder beside its tables (removed when a run starts, so
#: that an earlier run's never stand beside this one's)
_OUTPUTS = ("fields.xdmf", "fields.h5", "load_displacement.png", "mechanism.png", "summary.json",
            "strength_reduction.png")

__all__ = [
    "OUT_OF_EQUILIBRIUM",
    "BVPOutcome",
    "Built",
    "FiniteStrainCollapseWarning",
    "OutOfEquilibriumWarning",
    "boundary_length",
    "build",
    "run_boundary_value",
]


@dataclass
class BVPOutcome:
    """What a boundary-value run produced.

    Attributes:
        steps: the steps table (see the module docstring).
        summary: what ``summary.json`` holds.
        error: why the run stopped short (None: it reached the end).
        points: the Gauss-point table of the last committed step.
        u: the last committed nodal displacement [m].
        interrupt: the Ctrl-C or stop signal (SIGTERM, SIGHUP) that stopped the run, if one
            did (its exit code: :func:`~granular_material.cli.signals.interrupt_exit_code`).
    """

    steps: pd.DataFrame
    summary: dict[str, Any]
    error: str | None = None
    points: pd.DataFrame = field(default_factory=pd.DataFrame)
    u: np.ndarray = field(default_factory=lambda: np.zeros(0))
    interrupt: KeyboardInterrupt | None = None


def _mesh(spec: BoundaryValueSpec) -> MeshData:
    m = spec.mesh
    if m.file is not None:
        data = read_mesh(m.file)
    else:
        data = rectangle_mesh(m.size[0], m.size[1], m.elements[0], m.elements[1], m.element,
                              grading=m.grading)
        _align(data, 0, m.align_x)
        _align(data, 1, m.align_y)
    aliases = {name: data.boundaries[value] for name, value in spec.boundaries.items()
               if value in data.boundaries}
    predicates = {name: value for name, value in spec.boundaries.items() if name not in aliases}
    return select_boundaries(data.with_boundaries(aliases), predicates)


def _align(data: MeshData, axis: int, values: tuple[float, ...]) -> None:
    """Move the grid line of a generated mesh nearest each of ``values`` [m] onto it (along
    ``axis``), in place; refused where that would fold an element."""
    p = data.mesh.p
    for value in values:
        lines = np.unique(p[axis])
        if not lines[0] < value < lines[-1]:  # the mesh's own edges stay where they are
            raise SpecError("mesh.align_" + "xy"[axis], f"{value:g} m lies outside the mesh "
                                                        f"({lines[0]:g} to {lines[-1]:g} m)")
        k = int(np.argmin(np.abs(lines - value)))
        low = lines[k - 1] if k > 0 else -np.inf
        high = lines[k + 1] if k + 1 < lines.size else np.inf
        if not low < value < high:
            raise SpecError("mesh.align_" + "xy"[axis], f"{value:g} m lies outside the mesh or "
                                                        "would fold an element")
        p[axis, p[axis] == lines[k]] = value


def _condition(c: ConditionSpec) -> Any:
    if c.type == "fixed":
        return Fixed(c.boundary)
    if c.type == "roller":
        return Roller(c.boundary, c.component)
    if c.type == "displacement":
        return Displacement(c.boundary, c.component, c.value)
    if c.type == "rigid":
        return RigidBody(c.boundary, displacement=tuple(c.displacement), rough=c.rough)
    return Pressure(c.boundary, c.value, c.end)


def _initial_stress(spec: BoundaryValueSpec, problem: Any, f0: float,
                    ) -> tuple[np.ndarray, dict[str, Any]]:
    """The initial Cauchy stress [Pa] (n, 2, 2), tension positive, in equilibrium with
    step 0's weight (``f0`` times each region's), and what the summary says of it: a
    geostatic start's column and correction
    (:func:`~granular_material.fem.boundary_value.ground.ground_stress`) and its floor."""
    s = spec.initial
    xy = problem.points
    if s.state == "uniform":
        return np.broadcast_to(-s.pressure * np.eye(2), (xy.shape[0], 2, 2)).copy(), {}
    mesh = problem.mesh_data
    nqp = xy.shape[0] // mesh.n_elements
    gamma, k0, floor, floors = _ground_of_regions(spec, mesh, nqp, f0)
    if s.state == "continuum":
        return continuum_stress(spec, problem, gamma, floor, floors)
    info: dict[str, Any] = {}
    if s.surface is not None:  # a level surface at the given height (as before regions)
        if np.ptp(gamma) > 0 or np.ptp(k0) > 0:
            raise SpecError("initial.surface", "sets one level surface for one unit weight "
                                               "and one K0; the regions differ (leave it out: "
                                               "each point's overburden is then found from "
                                               "the mesh)")
        sigma = geostatic_stress(xy, s.surface, float(gamma[0]), s.surcharge, float(k0[0]))
        info["surface"] = s.surface
    else:
        try:
            ground = ground_stress(problem, gamma, k0, s.surcharge)
        except ParameterError as exc:
            raise SpecError("initial.state", f"a geostatic start: {exc.message}") from None
        sigma = ground.stress
        info.update(level=ground.level, column_residual=ground.residual_column,
                    corrected_residual=ground.residual, correction=ground.correction)
    lifted = np.zeros(0, dtype=np.int64)
    if np.isfinite(floor).any():  # a continuum's points without a floor are left alone
        sigma, lifted = lift_to_floor(sigma, floor)
    info.update(minimum_pressure=floors, lifted_points=int(lifted.size))
    return sigma, info


def _ground_of_regions(spec: BoundaryValueSpec, mesh: MeshData, nqp: int, f0: float,
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any]:
    """γ at step 0 [N/m³] of every element, K0 [-] and the floor [Pa] of every Gauss point,
    and the floor as the summary gives it (one number, or one per region; None, and −inf
    per point, where there is none: a continuum's points may start at zero stress or in
    tension). SpecError for an
    ``initial.minimum_pressure`` below what a DEM region's RVEs are prepared at."""
    s = spec.initial
    n = mesh.n_elements * nqp
    if spec.materials is None:
        gamma = np.full(mesh.n_elements, f0 * unit_weight_of(spec))
        lowest = _lowest_pressure(spec.material, "material")
        floor = _floor(s.minimum_pressure, lowest, None)
        return gamma, np.full(n, s.k0), np.full(n, -np.inf if floor is None else floor), floor
    weights = region_unit_weights(spec)
    elements = region_elements(spec, mesh)
    gamma = np.zeros(mesh.n_elements)
    k0 = np.zeros(mesh.n_elements)
    floor = np.zeros(mesh.n_elements)
    floors = {}
    for m in spec.materials:
        index = elements[m.region]
        gamma[index] = f0 * weights[m.region]
        k0[index] = s.k0 if m.k0 is None else m.k0
        floors[m.region] = _floor(s.minimum_pressure, _lowest_pressure(m.material,
                                                                        "materials.name"),
                                  m.region)
        floor[index] = -np.inf if floors[m.region] is None else floors[m.region]
    return gamma, np.repeat(k0, nqp), np.repeat(floor, nqp), floors


def _lowest_pressure(material: Any, field_: str) -> float | None:
    """The lowest stress [Pa] the material's points can start at (its class's
    ``lowest_pressure`` hook: DEM RVEs), None for a material without one (a continuum)."""
    hook = getattr(material.cls, "lowest_pressure", None)
    if hook is None:
        return None
    try:
        return float(hook(material.parameters))
    except ParameterError as exc:
        raise SpecError(f"{field_}.{exc.field}", exc.message) from None


def _floor(given: float | None, lowest: float | None, region: str | None) -> float | None:
    """The floor [Pa] of a material's points: ``initial.minimum_pressure`` where given (not
    below ``lowest``, the RVEs'), else the RVEs' lowest, else None (none)."""
    if given is None:
        return lowest
    if lowest is not None and given < lowest:
        where = "" if region is None else f" of region {region!r}"
        raise SpecError("initial.minimum_pressure", f"{given:g} Pa is below the lowest "
                                                    f"stress the RVEs{where} are prepared at, "
                                                    f"{lowest:.4g} Pa (a packing of discs "
                                                    "carries stress only while confined); "
                                                    f"give at least that, or leave it out")
    return float(given)


@dataclass
class Built:
    """The pieces of a boundary-value run before it steps (see :func:`build`)."""

    spec: BoundaryValueSpec
    mesh: MeshData
    problem: Any
    initial_stress: np.ndarray
    unit_weight: float | None  # None: the regions' weights differ
    material: Any
    settings: Any
    moved: dict[str, np.ndarray]  # rigid body / displacement name -> unit direction
    preparation_s: float = 0.0  # seconds to build and allocate the material
    initial: dict[str, Any] = field(default_factory=dict)  # how the initial state was made
    hint: str = ""  # the fix a start out of equilibrium would need
    # a phased run (:mod:`~granular_material.runs.boundary_value.phases`): its phases, the
    # one stepping, and the displacement [m] its reported ones are measured from
    plans: list[PhasePlan] = field(default_factory=list)
    phase: int = 0
    offset: np.ndarray | None = None
    start_residuals: dict[int, float] = field(default_factory=dict)  # by phase, relative
    pressed: dict[str, np.ndarray] = field(default_factory=dict)  # name -> inward direction

    def reported_boundaries(self) -> list[tuple[str, bool]]:
        """(name, loaded) of every boundary whose force and displacement the steps table
        reports (those with a condition; of a phased run, in any phase), ``loaded`` where a
        pressure acts on it (its force is the load's, else the supports' reaction)."""
        if not self.plans:
            conditions = self.spec.conditions
            return [(name, any(c.boundary == name and c.type == "pressure"
                               for c in conditions))
                    for name in sorted({c.boundary for c in conditions})]
        named = {c.boundary for plan in self.plans for c in plan.view.conditions}
        now = self.plans[self.phase].view.conditions
        return [(name, any(c.boundary == name and c.type == "pressure" for c in now))
                for name in sorted(named)]

    def reported(self, u: np.ndarray) -> np.ndarray:
        """The displacement [m] reported for the solver's ``u`` (from the last reset of a
        phased run; ``u`` itself otherwise)."""
        return u if self.offset is None else u - self.offset


def build(spec: BoundaryValueSpec, allocate: bool = True, saved: Path | None = None
          ) -> Built:
    """Mesh, problem, initial stress and material of ``spec`` (no step taken; the material
    not allocated, its RVEs not prepared, unless ``allocate``; ``saved``: the material's
    checkpoint a resume restores, :func:`material_for_problem`). A phased ``spec``: those of
    its first phase, and every phase's problem (:attr:`Built.plans`), each checked."""
    phased = spec
    spec = phase_view(phased, 0) if phased.phases else phased
    if spec.mesh.file is None:  # a generated mesh: checked before it is made
        check_memory(spec, *generated_size(spec))
    mesh = _mesh(spec)
    check_memory(spec, mesh.n_elements, mesh.element)
    problem, unit_weight, start = _problem(spec, mesh)
    f0 = (spec.gravity_factor or (1.0, 1.0))[0]
    xy = problem.points
    sigma0, initial = _initial_stress(spec, problem, f0)  # with step 0's weight
    t0 = time.perf_counter()
    try:
        material = material_for_problem(phased, xy.shape[0], sigma0, allocate, mesh, saved)
    except ParameterError as exc:  # a continuum that refuses its point's stress
        if spec.initial.state == "continuum" and exc.field == "initial_stress":
            raise SpecError("initial.state", f"a continuum start: the material's initial "
                                             f"stress {exc.message}. Its friction cap acts "
                                             "on cohesionless materials only; start a "
                                             "cohesive soil stress-free (initial.state = "
                                             "\"uniform\", pressure = 0) with gravity "
                                             "ramped on ([gravity] factor = [0.0, 1.0])"
                            ) from None
        if spec.initial.state != "geostatic" or exc.field != "initial_stress" \
                or initial.get("level", True):
            raise
        raise SpecError("initial.state", f"a geostatic start: the material's initial stress "
                                         f"{exc.message}. Under a slope the start is an "
                                         "elastic state brought into equilibrium, which "
                                         "exceeds the strength where the slope is near its "
                                         "limit: start stress-free (initial.state = "
                                         "\"uniform\", pressure = 0) with gravity ramped on "
                                         "([gravity] factor = [0.0, 1.0]), so that the "
                                         "material finds its own state") from None
    except RuntimeError as exc:  # RVEs that did not reach their points' stresses
        if spec.initial.state == "continuum" and "did not reach" in str(exc):
            raise RuntimeError(f"{exc}. A continuum start keeps every point's mobilised "
                               "friction within initial.strength_fraction of the RVEs' "
                               "calibrated friction angle: a lower fraction asks less of "
                               "them") from exc
        if spec.initial.state != "geostatic" or "did not reach" not in str(exc):
            raise
        raise RuntimeError(f"{exc}. Near a free face the geostatic start may ask more of an "
                           "RVE than its friction holds: initial.minimum_pressure [Pa] lifts "
                           "every point below it by an isotropic pressure, which lowers its "
                           "stress ratio") from exc
    preparation = time.perf_counter() - t0
    noisy = bool(getattr(material, "noisy", False))
    settings = _settings(spec, problem, noisy)
    b = Built(spec, mesh, problem, sigma0, unit_weight, material, settings, _moved(spec),
              preparation, initial, _equilibrium_hint(spec, problem, start, initial))
    if phased.phases:
        b.plans = _plans(phased, b, noisy)
        for plan in reversed(b.plans):  # a body moved in any phase, along its first motion
            b.moved.update(_moved(plan.view))
        loaded = dict.fromkeys(name for plan in b.plans for name in plan.pressures)
        b.pressed = {name: inward_direction(mesh, name) for name in loaded}
    return b


def _problem(spec: BoundaryValueSpec, mesh: MeshData) -> tuple[Any, float | None, float]:
    """The problem of ``spec``'s conditions and gravity on ``mesh``; the unit weight [N/m³]
    (None: the regions' differ) and γ at step 0."""
    conditions = [_condition(c) for c in spec.conditions]
    f0, f1 = spec.gravity_factor or (1.0, 1.0)
    if spec.materials is None:
        unit_weight: float | None = unit_weight_of(spec)
        start, end = f0 * unit_weight, f1 * unit_weight
        if start > 0 or end > 0:
            conditions.append(Gravity(start, end=end))
    else:
        unit_weight, start = _region_gravity(spec, mesh, conditions, f0, f1)
    return build_problem(mesh, conditions, spec.mesh.quadrature), unit_weight, start


def _settings(spec: BoundaryValueSpec, problem: Any, noisy: bool) -> Any:
    """Newton's settings for ``problem`` (the force tolerance from its free dofs)."""
    settings = spec.newton.settings(noisy)
    stress_tol = spec.newton.stress_tolerance(noisy, spec.reference_pressure)
    if stress_tol > 0:
        settings = replace(settings, atol=problem.force_tolerance(stress_tol))
    return settings


def _moved(spec: BoundaryValueSpec) -> dict[str, np.ndarray]:
    """The unit direction of every boundary a condition moves (rigid, displacement)."""
    moved = {}
    for c in spec.conditions:
        if c.type == "rigid":
            d = np.asarray(c.displacement, dtype=float)
            moved[c.boundary] = d / max(float(np.linalg.norm(d)), 1e-300)
        elif c.type == "displacement":
            direction = np.zeros(2)
            direction[c.component] = math.copysign(1.0, c.value) if c.value else 1.0
            moved[c.boundary] = direction
    return moved


def _plans(spec: BoundaryValueSpec, b: Built, noisy: bool) -> list[PhasePlan]:
    """Every phase of the phased ``spec``, its problem built on ``b``'s mesh (the first's
    is ``b``'s own); a phase whose conditions leave the body free is refused naming it."""
    plans = []
    first = 0
    for k, phase in enumerate(spec.phases):
        view = phase_view(spec, k)
        if k == 0:
            problem, settings = b.problem, b.settings
        else:
            try:
                problem = _problem(view, b.mesh)[0]
            except ParameterError as exc:
                raise SpecError("phases.conditions", f"of phase {k + 1} ({phase.name!r}) "
                                                     f"{exc.field}: {exc.message}") from None
            settings = _settings(view, problem, noisy)
        plans.append(PhasePlan(k, phase.name, phase.steps, first, problem, settings, view,
                               phase.reset_displacements, phase_pressures(view)))
        first += phase.steps
    return plans


def _equilibrium_hint(spec: BoundaryValueSpec, problem: Any, start: float,
                      initial: dict[str, Any]) -> str:
    """The fix that fits a start out of equilibrium with its loads (what the
    :class:`OutOfEquilibriumWarning` names)."""
    s = spec.initial
    if s.state == "uniform":
        weighed = start > 0 or any(
            g.unit_weight > 0 for g in problem.conditions if isinstance(g, Gravity))
        if weighed:
            return ("Gravity acts in full from step 0 on this uniform start: ramp it on with "
                    "[gravity] factor = [0.0, 1.0], or start geostatic (initial.state = "
                    "\"geostatic\": each point at the weight of the ground above it, under a "
                    "slope or layers too)")
        return ("The uniform pressure is not what the boundaries carry at step 0: give "
                "each boundary that is not held a pressure of initial.pressure at step 0 (an "
                "end value then ramps it), or start stress-free (initial.pressure = 0, a "
                "continuum material) with the loads ramped from zero")
    if s.state == "continuum":
        return (f"The continuum start was settled to {initial['settled_residual']:.2g} of the "
                f"load from equilibrium, {initial['at_floor']} points at the floor "
                "(initial.minimum_pressure: an isotropic pressure at a free surface is not in "
                "equilibrium; a lower floor unbalances less) and "
                f"{initial['at_cap']} at the friction cap; the rest is how near each RVE "
                "starts to its target (within about 1 %)")
    if initial.get("lifted_points"):
        lifted = (f"{initial['lifted_points']} points were lifted to "
                  "initial.minimum_pressure, above the weight of the ground over them: "
                  "lower it if the lift is what unbalances the start. ")
    else:
        lifted = ""
    if s.surface is not None:
        try:
            tops = overburden(problem.mesh_data.mesh, problem.points, 0.0).surface
        except ParameterError:
            tops = np.array([s.surface])
        if np.ptp(tops) > 1e-9 * max(1.0, abs(s.surface)):
            return (f"{lifted}The scene's initial.surface sets a level surface at y = "
                    f"{s.surface:g} m, "
                    f"but the ground's surface is not level (from {tops.min():.4g} to "
                    f"{tops.max():.4g} m): leave initial.surface out, so that each point's "
                    "overburden is found from the mesh and the start is brought into "
                    "equilibrium")
    if initial.get("level") is False:  # corrected into equilibrium: the rest is the material's
        return (f"{lifted}The geostatic state was in equilibrium with the loads to "
                f"{initial['corrected_residual']:.1g} of them; what remains is how near the "
                "material starts to it (an RVE meets its target stress within about 1 %)")
    return (f"{lifted}The geostatic state does not match the loads at step 0: make "
            "initial.surcharge the pressure on the ground surface and the sides rollers (a "
            "pressure on a side must be K0 times σv); [gravity]'s unit weight at step 0 is "
            "the weight the start carries")


def _region_gravity(spec: BoundaryValueSpec, mesh: MeshData, conditions: list[Any],
                    f0: float, f1: float) -> tuple[float | None, float]:
    """Each region's own gravity appended to ``conditions`` (factors ``f0``, ``f1``); the
    regions' one unit weight [N/m³] (None where they differ) and γ at step 0 (the largest
    region's, where they differ)."""
    weights = region_unit_weights(spec)
    elements = region_elements(spec, mesh)
    for region, weight in weights.items():
        if f0 * weight > 0 or f1 * weight > 0:
            conditions.append(Gravity(f0 * weight, end=f1 * weight, elements=elements[region]))
    values = set(weights.values())
    common = values.pop() if len(values) == 1 else None
    return common, f0 * (common if common is not None else max(weights.values()))


def _rows(b: Built, solver: NewtonSolver, record: StepRecord | None, p0: np.ndarray,
          ) -> tuple[dict[str, Any], pd.DataFrame]:
    problem = b.problem
    kin = solver.kinematics
    grad = solver.grad_u()
    if b.offset is not None:  # a phase reset the reported displacement
        grad = reported_gradient(kin, grad, gauss_points_grad(problem.basis, b.offset))
    u = b.reported(solver.u)
    strain = kin.strain(grad)
    stress = solver.response.stress
    pressure = -0.5 * np.trace(stress, axis1=1, axis2=2)
    failed = np.asarray(solver.response.status) != PointStatus.OK
    unconfined = pressure < UNCONFINED_FRACTION * p0
    reaction = solver.reaction
    _, f_ext = solver.loading.at(solver.load_factor, solver.u if kin.finite else None)
    step = record.step if record else 0
    row: dict[str, Any] = {
        "step": step, "load_factor": solver.load_factor,
        "iterations": record.iterations if record else 0,
        "cutbacks": record.cutbacks if record else 0,
        "stalled": record.stalled if record else 0,
        "wall_time": record.wall_time if record else 0.0,
        "failed_points": int(failed.sum()), "unconfined_points": int(unconfined.sum()),
        "residual_history": json.dumps(record.residual_history if record else []),
        # the material's costs (step 0: none spent, under the names its evaluations use)
        **(dict(record.costs) if record else dict.fromkeys(solver.response.costs, 0)),
    }
    dem_points = getattr(b.material, "dem_points", None)
    if dem_points is not None:  # an adaptive material: the points on DEM RVEs after the step
        row["dem_points"] = int(dem_points)
    for name, loaded in b.reported_boundaries():
        fx, fy = problem.boundary_force(name, f_ext if loaded else reaction)
        ux, uy = problem.boundary_displacement(name, u)
        row.update({f"{name}_force_x": fx, f"{name}_force_y": fy,
                    f"{name}_displacement_x": ux, f"{name}_displacement_y": uy})
        if name in b.moved:
            along = float(b.moved[name] @ np.array([ux, uy]))
            row[f"{name}_displacement"] = along
            if b.moved[name][1] < -0.5:
                row[f"{name}_settlement"] = along
    for name in _free_boundaries(b):
        ux, uy = problem.boundary_displacement(name, u)
        row.update({f"{name}_displacement_x": ux, f"{name}_displacement_y": uy})
    xy = problem.points
    nqp = problem.basis.X.shape[-1]
    fields = {k: np.asarray(v, dtype=float) for k, v in solver.response.fields.items()}
    w = strain
    points = pd.DataFrame({
        "step": step, "point": np.arange(len(stress)),
        "element": np.arange(len(stress)) // nqp, "x": xy[:, 0], "y": xy[:, 1],
        "sxx": stress[:, 0, 0], "syy": stress[:, 1, 1], "sxy": stress[:, 0, 1],
        "exx": w[:, 0, 0], "eyy": w[:, 1, 1], "exy": w[:, 0, 1],
        "volumetric_strain": np.trace(w, axis1=1, axis2=2),
        "shear_strain": np.hypot(w[:, 0, 0] - w[:, 1, 1], 2 * w[:, 0, 1]),
        "rotation": 0.5 * (grad[:, 1, 0] - grad[:, 0, 1]),
        "mean_pressure": pressure, "unconfined": unconfined.astype(np.int8),
        "failed": failed.astype(np.int8), **fields,
    })
    if isinstance(b.material, RegionalMaterial):
        points.insert(5, "region", b.material.regions.astype(str))
    return row, points


def _free_boundaries(b: Built) -> list[str]:
    """The named boundaries that carry no condition, sorted: every [boundaries] name, and
    with a mesh file every physical group of its boundary facets (a generated mesh's sides
    only where a condition or a name uses them)."""
    conditioned = {name for name, _ in b.reported_boundaries()}
    named = set(b.mesh.boundaries) if b.spec.mesh.file is not None else set(b.spec.boundaries)
    return sorted(n for n in named - conditioned if n in b.problem.boundaries)


def _where(points: pd.DataFrame, column: str) -> str:
    """Where the points flagged in ``column`` are: their count and bounding box."""
    flagged = points[points[column] > 0]
    if flagged.empty:
        return ""
    return (f"{len(flagged)} points in x {flagged.x.min():.3g}–{flagged.x.max():.3g} m, "
            f"y {flagged.y.min():.3g}–{flagged.y.max():.3g} m")


def run_boundary_value(spec: BoundaryValueSpec, out: Path | None = None,
                       resume: bool = False) -> BVPOutcome:
    """Run ``spec`` into ``out`` (default ``spec.out``; None: nothing written) and return
    what it produced. A Newton failure or Ctrl-C stops the run with the committed steps kept
    and written (``error`` says why), and its checkpoint in ``out/checkpoint``; ``resume``
    continues such a run (:mod:`~granular_material.runs.boundary_value.resume`)."""
    t_start = time.perf_counter()
    out = out if out is not None else spec.out
    if out is not None:
        out = Path(out)
        if out.exists() and not out.is_dir():
            raise SpecError("out", f"{out} is a file, not a folder")
        check_disk(spec, next(p for p in (out, *out.absolute().parents) if p.exists()),
                   _mesh)
    checkpoint, saved = open_bvp_checkpoint(spec, out, resume)  # read, nothing changed
    b = build(spec, allocate=saved is None,
              saved=None if saved is None else saved.material_path)
    if saved is not None:
        b.material.restore(saved.material_path)  # refused (an older one) before any write
    problem = b.problem
    _collapse_formulation(spec, b.settings)
    try:
        solver = NewtonSolver(problem.basis, b.material, problem.loading, b.settings,
                              spec.regularisation.regularisation())
    except ParameterError as exc:  # the mesh file's elements cannot carry the regularisation
        raise SpecError(f"regularisation.{exc.field}", exc.message) from None
    if saved is not None:
        solver.resume(saved.state)
    p0 = np.maximum(-0.5 * np.trace(b.initial_stress, axis1=1, axis2=2), 1e-300)
    rows: list[dict[str, Any]] = []
    last: dict[str, Any] = {}
    writer = None
    if out is not None:  # every check passed: the run starts writing its folder
        starting()
        out.mkdir(parents=True, exist_ok=True)
        start_bvp_checkpoint(spec, checkpoint, saved)
        for stale in ("points.npy", "points.csv", *_OUTPUTS):  # an earlier run's
            (out / stale).unlink(missing_ok=True)
        if spec.fields:
            writer = FieldWriter(out / "fields.xdmf", problem).__enter__()

    clock = SyncClock()  # the tables flushed to the disk as a biaxial run's

    def keep(row: dict[str, Any], points: pd.DataFrame, u: np.ndarray) -> None:
        rows.append(row)
        last.update(points=points, u=u.copy())
        if out is not None:
            first = row["step"] == 0
            sync = clock.due(first)  # and at the end
            write_points(points, out, append=not first, csv=spec.points_csv, sync=sync)
            write_csv(pd.DataFrame([row]), out / "steps.csv",  # last: the step's commit
                      append=not first, sync=sync)
            if writer is not None:
                writer.write(float(row["load_factor"]), u, points)

    reducing = False  # in the strength reduction (a resumed run: known from its steps below)

    def collect(s: NewtonSolver, record: StepRecord | None) -> None:
        row, points = _rows(b, s, record, p0)
        if b.plans:
            row, points = with_phase(b, row, points)
            if reducing:
                row["phase"] = PHASE
                points["phase"] = PHASE
        if spec.strength_reduction is not None:
            row.update(reduction_columns(s))
        u = b.reported(s.u)
        keep(row, points, u)
        if checkpoint is not None:
            checkpoint.save_step(row, points, u, None)
            step = int(row["step"])
            if checkpoint.due(step, spec.steps) or ends_phase(b, step):
                checkpoint.save_state(step, solver, b.material)

    t_initial = time.perf_counter()
    if saved is None:
        collect(solver, None)
        initial_residual = remember(checkpoint, "initial_residual",
                                    _initial_residual(solver, b.hint, settles(
                                        spec, {"norm": math.inf, "newton_atol": 0.0}, False)))
    else:
        for step in saved.steps:
            keep(step.row, step.points, step.u)
        initial_residual = remember(checkpoint, "initial_residual")
    t_initial = time.perf_counter() - t_initial
    if b.plans:
        b.start_residuals[0] = initial_residual.get("relative")
    error = None
    interrupt = None
    reduction = None
    # a continuum start's settling step comes before the load steps (a run resumed past it
    # took it already)
    ahead = int(settles(spec, initial_residual, False))
    settled = settles(spec, initial_residual, saved is not None and saved.step >= 1)
    reducing = saved is not None and saved.step - ahead > spec.steps
    loaded = None if saved is None else max(min(saved.step - ahead, spec.steps), 0)
    try:
        if settled:
            collect(solver, solver.equilibrate(1))  # the continuum start's own weight
        if b.plans:
            run_phases(b, solver, collect, checkpoint, loaded)
        else:
            solver.run(spec.steps, on_step=collect, progress=spec.progress,
                       description=f"{spec.name} ({problem.basis.nelems} elements)",
                       done=0 if loaded is None else loaded)
        if spec.strength_reduction is not None:
            resumed = reducing
            reducing = True
            reduction = run_reduction(spec, solver, collect, resumed)
    except NewtonError as exc:
        error = str(exc)
        if b.plans:
            error = f"phase {b.phase + 1} ({b.plans[b.phase].name!r}): {error}"
        relative = initial_residual.get("relative", 0.0)
        if relative > OUT_OF_EQUILIBRIUM and initial_residual.get("norm", 0.0) > b.settings.atol \
                and not settled:
            error += (f" (the initial state was not in equilibrium with the loads: its "
                      f"residual {relative:.3g} times the load; a start in equilibrium, e.g. "
                      "geostatic, lets the steps carry the load alone)")
    except KeyboardInterrupt as exc:
        error = interrupted_error(len(rows) - 1, spec.steps)
        interrupt = exc
    finally:
        if writer is not None:
            writer.__exit__(None, None, None)
        if out is not None:
            sync_files([out / "points.npy", out / "points.csv", out / "steps.csv"])
    steps = pd.DataFrame(rows)
    summary = _summary(b, solver, steps, last.get("points", pd.DataFrame()), error,
                       initial_residual, t_initial, time.perf_counter() - t_start)
    summary["resumed_from_step"] = None if saved is None else saved.step
    if b.plans:
        summary.update(phases_summary(b, solver, steps, error, interrupt is not None))
    regularisation = solver.regularisation_summary()
    if regularisation is not None:
        summary["regularisation"] = regularisation
    if b.settings.continuation == "arc-length":
        summary["continuation"] = _continuation_summary(spec, solver, error,
                                                        interrupt is not None)
    if spec.strength_reduction is not None:
        summary["strength_reduction"] = reduction_summary(reduction, spec)
    if checkpoint is not None and error is None:
        checkpoint.remove()  # finished: nothing to resume
    if out is not None:
        if spec.figures:
            _figures(b, steps, last, out)
            if reduction is not None:
                reduction_figure(steps[steps["step"] > spec.steps + ahead],
                                 summary["strength_reduction"], out)
        summary["out"] = str(out)
        write_json(summary, out / "summary.json")
    return BVPOutcome(steps, summary, error, last.get("points", pd.DataFrame()),
                      last.get("u", np.zeros(0)), interrupt)


def _continuation_summary(spec: BoundaryValueSpec, solver: NewtonSolver,
                          error: str | None, interrupted: bool) -> dict[str, Any]:
    """An arc-length run's path: why it stopped ("stopped" by an interrupt, "failed" by
    Newton, else the path's own reason), its peak load factor (and step), the collapse it
    found (None: none) and, with a gravity factor, the gravity factor at the peak and at
    the collapse (the gravity-increase factor)."""
    path = solver.continuation
    stopped = ("stopped" if interrupted else "failed" if error is not None
               else solver.stopped_by or "stopped")
    peak = path.peak if path.values else solver.load_factor
    out: dict[str, Any] = {
        "model": "arc-length", "stopped_by": stopped, "peak_load_factor": peak,
        "peak_step": path.peak_step, "collapse": path.collapse}
    if spec.gravity_factor is not None:
        f0, f1 = spec.gravity_factor
        out["gravity_factor_at_peak"] = f0 + (f1 - f0) * peak
        out["gravity_factor_at_collapse"] = (None if path.collapse is None
                                             else f0 + (f1 - f0) * path.collapse["value"])
    return out


class FiniteStrainCollapseWarning(UserWarning):
    """A collapse sought (a strength reduction, or a gravity factor followed by arc length)
    in the updated-Lagrangian formulation, whose changing geometry can keep a slope gaining
    load at strains past any collapse: factors of safety are small-strain notions."""


def _collapse_formulation(spec: BoundaryValueSpec, settings: Any) -> None:
    """Warn (:class:`FiniteStrainCollapseWarning`) where ``spec`` seeks a collapse in finite
    strain."""
    seeks = spec.strength_reduction is not None or (
        settings.continuation == "arc-length" and spec.gravity_factor is not None)
    if seeks and settings.formulation == "updated-lagrangian":
        warnings.warn("a collapse load (strength reduction, or gravity increased by arc "
                      "length) in the updated-Lagrangian formulation follows the changing "
                      "geometry: a slope can keep gaining load at strains far past its "
                      "collapse (a user's gravity ramp went on to 2.24 at shear strains "
                      "above 100 %, against 1.458 in small strain); set [newton] "
                      'formulation = "small-strain" for a factor of safety',
                      FiniteStrainCollapseWarning, stacklevel=3)


class OutOfEquilibriumWarning(UserWarning):
    """The initial state of a boundary-value run is not in equilibrium with its loads at
    step 0 (:data:`OUT_OF_EQUILIBRIUM`)."""


#: the initial residual, relative to the load, above which the start is reported out of
#: equilibrium (a geostatic start is in it to round-off; DEM RVEs meet their targets within
#: about 1 %)
OUT_OF_EQUILIBRIUM = 0.01


def _initial_residual(solver: NewtonSolver, fix: str = "",
                      settling: bool = False) -> dict[str, float]:
    """‖R‖ [N/m] of the initial state at λ = 0 over the free dofs, against ‖f_ext‖ there (the
    load; where none acts on the free dofs, ‖f_int‖ over all dofs, the forces the initial
    stress puts on the supports): zero when the initial stress is in equilibrium with the
    loads (a geostatic start). One out of equilibrium (:data:`OUT_OF_EQUILIBRIUM`) is said
    with an :class:`OutOfEquilibriumWarning` naming ``fix``, the fix that fits the run
    (``settling``: the run settles it in a step of its own before the load changes)."""
    _, f_ext = solver.loading.at(0.0, solver.u if solver.kinematics.finite else None)
    residual = solver.f_int - f_ext
    free = np.ones(residual.size, dtype=bool)
    free[solver.loading.dirichlet_dofs] = False
    norm = float(np.linalg.norm(residual[free]))
    load = float(np.linalg.norm(f_ext[free]))
    scale = load or float(np.linalg.norm(solver.f_int)) or 1.0
    relative = norm / scale
    balanced = relative <= OUT_OF_EQUILIBRIUM or norm <= solver.settings.atol
    if not balanced:
        against = ("the load" if load else
                   "the forces of the initial stress (no load acts on the free nodes)")
        warnings.warn(f"the initial state is not in equilibrium with the loads at step 0: its "
                      f"residual is {norm:.3g} N/m, {relative:.3g} times {against}; "
                      + ("step 1 settles it at the start's load factor before the load "
                         "changes. " if settling else
                         "the first load step brings it to equilibrium as well as applying "
                         "its increment, so its response holds both. ")
                      + (fix or "A geostatic start with the scene's unit weight starts in "
                                "equilibrium"),
                      OutOfEquilibriumWarning, stacklevel=3)
    return {"norm": norm, "relative": relative, "newton_atol": solver.settings.atol}


def _summary(b: Built, solver: NewtonSolver, steps: pd.DataFrame, points: pd.DataFrame,
             error: str | None, initial: dict[str, float], t_initial: float,
             wall: float) -> dict[str, Any]:
    spec = b.spec
    timings: dict[str, float] = {"preparation": b.preparation_s, "initial_state": t_initial}
    for record in solver.records:
        for name, seconds in record.timings.items():
            timings[name] = timings.get(name, 0.0) + seconds
        timings["steps"] = timings.get("steps", 0.0) + record.wall_time
    last = steps.iloc[-1].to_dict() if len(steps) else {}
    bodies = {name: {"force_x": last.get(f"{name}_force_x"),
                     "force_y": last.get(f"{name}_force_y"),
                     "displacement": last.get(f"{name}_displacement")}
              for name in b.moved}
    regions = None
    if isinstance(b.material, RegionalMaterial):
        weights = region_unit_weights(spec)
        regions = {m.region: {"material": m.material.name, "unit_weight": weights[m.region],
                              "gauss_points": int(b.material.points_of(m.region).size)}
                   for m in spec.materials}
    return {
        "name": spec.name, "mesh": b.mesh.source, "element": b.mesh.element,
        "elements": int(b.problem.basis.nelems),
        "gauss_points": int(b.initial_stress.shape[0]),
        "material": spec.material.name if regions is None else "regions",
        **({} if regions is None else {"regions": regions}),
        "unit_weight": b.unit_weight,
        "gravity_factor": list(spec.gravity_factor or (1.0, 1.0)),
        "initial_state": spec.initial.state, "initial_residual": initial,
        **({"initial": b.initial} if b.initial else {}),
        "steps": int(len(steps) - 1), "steps_planned": spec.steps, "error": error,
        "iterations": [int(i) for i in steps["iterations"].iloc[1:]],
        "failed_points_last": int(last.get("failed_points", 0)),
        "unconfined_points_last": int(last.get("unconfined_points", 0)),
        "unconfined_where": _where(points, "unconfined") if len(points) else "",
        "bodies": bodies, "timing_s": {k: round(v, 3) for k, v in timings.items()},
        "wall_s": round(wall, 3),
        **({} if spec.adaptivity is None
           else {"adaptivity": b.material.summary()}),
    }


def _figures(b: Built, steps: pd.DataFrame, last: dict[str, Any], out: Path) -> None:
    if len(steps) < 2 or "points" not in last:
        return
    bodies = []
    for name, direction in b.moved.items():
        axis = "y" if abs(direction[1]) >= abs(direction[0]) else "x"
        bodies.append((name, axis, boundary_length(b.mesh, name)))
    x0, x1, y0, y1 = b.mesh.bounding_box
    if b.plans:
        phased_figure(b, steps, bodies, out, size=max(x1 - x0, y1 - y0))
    elif bodies:
        plot_load_displacement(steps, bodies, out / "load_displacement.png",
                               size=max(x1 - x0, y1 - y0))
    xy, cells, kind, dofs = b.problem.nodes()
    u = last["u"]
    by_element = last["points"].groupby("element")
    gamma = by_element["shear_strain"].mean().to_numpy()
    dem = by_element["dem"].max().to_numpy() > 0 if "dem" in last["points"] else None
    plot_mechanism(xy, cells, kind, u[dofs[0]], u[dofs[1]], gamma, out / "mechanism.png",
                   title=f"{b.spec.name}: shear strain at step {int(steps['step'].iloc[-1])}",
                   dem_elements=dem)


def boundary_length(mesh: MeshData, name: str) -> float:
    """The reference length [m] of the boundary ``name`` (the sum of its facets')."""
    m = mesh.mesh
    ends = m.facets[:, mesh.boundaries[name]]
    return float(np.linalg.norm(m.p[:, ends[0]] - m.p[:, ends[1]], axis=0).sum())
