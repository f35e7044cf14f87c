"""The material of a boundary-value run: built by the material class's ``for_problem`` hook
with the initial stress of every Gauss point, and the unit weight of its soil.

A material class offers ``for_problem(parameters, context, initial_stress) -> Material``
(``initial_stress`` [Pa] (n, 2, 2), tension positive, one tensor per Gauss point; ``context``
a :class:`~granular_material.fem.materials.run_context.RunContext` with
``test = "boundary-value"`` and
the problem's representative pressure as ``confining``). The shipped materials have it;
another is refused with a message that says so.

Materials by region (a scene's ``[regions]`` and ``[[materials]]``): each region's material is
built the same way for its own Gauss points (their initial stresses; the context's
``n_points`` is the region's), and the
:class:`~granular_material.fem.materials.regions.RegionalMaterial` of them all answers for the
mesh. A region is a predicate on each element's centroid or a physical group of the mesh
file's cells (:func:`region_elements`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.boundaries import select_elements
from granular_material.fem.boundary_value.meshes import MeshData
from granular_material.fem.materials.regions import RegionalMaterial, point_regions
from granular_material.fem.materials.run_context import RunContext
from granular_material.runs.boundary_value.spec import BoundaryValueSpec
from granular_material.runs.spec import MaterialSpec, SpecError

__all__ = ["GRAVITY", "adaptive_material", "material_for_problem", "problem_context",
           "region_elements", "region_unit_weights", "unit_weight_of"]

#: standard gravity [m/s²]
GRAVITY = 9.81


def problem_context(spec: BoundaryValueSpec, n_points: int) -> RunContext:
    """The run context a material of ``spec`` is built for (the device resolved: None is
    CUDA where present, else the CPU)."""
    from granular_material.dem import resolve_device

    return RunContext(test="boundary-value", n_points=n_points,
                      confining=spec.reference_pressure, axial_strain=0.0, steps=spec.steps,
                      scale_discs=None, device=resolve_device(spec.device), shards=spec.shards,
                      backend="inprocess", progress=spec.progress,
                      convergence=spec.newton.convergence_test(spec.noisy))


def _one_material(spec: BoundaryValueSpec, material: MaterialSpec, field: str,
                  n_points: int, initial_stress: np.ndarray, allocate: bool) -> Any:
    """``material`` (the scene key ``field``) at ``n_points`` Gauss points."""
    cls = material.cls
    hook = getattr(cls, "for_problem", None)
    if hook is None:
        raise SpecError(field, f"{material.name} cannot start a boundary-value "
                               "problem (its class has no for_problem hook taking an "
                               "initial stress per Gauss point)")
    context = problem_context(spec, n_points)
    check = getattr(cls, "check_run", None)
    if check is not None:
        check(material.parameters, context)
    built = hook(material.parameters, context, np.asarray(initial_stress, float))
    if allocate and built.n_points == 0:
        built.allocate(n_points)
    return built


def region_elements(spec: BoundaryValueSpec, mesh: MeshData) -> dict[str, np.ndarray]:
    """Region name → element indices of ``mesh``, for every ``[[materials]]`` entry of
    ``spec``: its ``[regions]`` predicate at the elements' centroids or the mesh file's
    physical group it names, or (not in ``[regions]``) the physical group of its own name.
    SpecError naming the key of a region that selects nothing or names no group."""
    out: dict[str, np.ndarray] = {}
    groups = ", ".join(sorted(mesh.subdomains)) or "none"
    for m in spec.materials or ():
        given = (spec.regions or {}).get(m.region)
        if given is None:
            if m.region not in mesh.subdomains:
                raise SpecError("materials.region", f"{m.region!r} is neither a region of "
                                                    "[regions] nor a physical group of the "
                                                    f"mesh's cells (it has {groups})")
            out[m.region] = np.asarray(mesh.subdomains[m.region], dtype=np.int64)
        elif given in mesh.subdomains:
            out[m.region] = np.asarray(mesh.subdomains[given], dtype=np.int64)
        else:
            try:
                out[m.region] = select_elements(mesh, given, m.region)
            except ParameterError as exc:
                raise SpecError(f"regions.{m.region}", f"{exc.message} (physical groups of "
                                                       f"the mesh's cells: {groups})") from None
    return out


def _point_regions(spec: BoundaryValueSpec, mesh: MeshData, n_points: int) -> np.ndarray:
    """The region of every Gauss point (SpecError on ``regions`` for an element in no region
    or in two)."""
    n_elements = mesh.n_elements
    try:
        return point_regions(region_elements(spec, mesh), n_elements, n_points // n_elements)
    except ParameterError as exc:
        raise SpecError("regions", exc.message) from None


def material_for_problem(spec: BoundaryValueSpec, n_points: int,
                         initial_stress: np.ndarray, allocate: bool = True,
                         mesh: MeshData | None = None, saved: Path | None = None) -> Any:
    """The material of ``spec`` at ``n_points`` Gauss points starting from
    ``initial_stress`` [Pa] (n, 2, 2), allocated (its RVEs prepared) unless ``allocate`` is
    False; with ``[[materials]]``, a
    :class:`~granular_material.fem.materials.regions.RegionalMaterial` of every region's
    material on the regions of ``mesh``. ``saved``: the material's checkpoint a resume
    restores (an adaptive material is then made from it, :func:`adaptive_material`)."""
    if spec.adaptivity is not None:
        if mesh is None:
            raise ValueError("adaptivity needs the mesh (its Gauss points an element)")
        return adaptive_material(spec, n_points, initial_stress, n_points // mesh.n_elements,
                                 allocate, saved)
    if spec.materials is None:
        return _one_material(spec, spec.material, "material", n_points, initial_stress,
                             allocate)
    if mesh is None:
        raise ValueError("materials by region need the mesh")
    labels = _point_regions(spec, mesh, n_points)
    sigma0 = np.asarray(initial_stress, float)
    materials = {}
    for m in spec.materials:
        index = np.flatnonzero(labels == m.region)
        materials[m.region] = _one_material(spec, m.material, "materials.name", index.size,
                                            sigma0[index], allocate)
    regional = RegionalMaterial(materials, labels)
    if allocate:
        regional.allocate(n_points)
    return regional


def adaptive_material(spec: BoundaryValueSpec, n_points: int, initial_stress: np.ndarray,
                      nqp: int, allocate: bool = True, saved: Path | None = None) -> Any:
    """The :class:`~granular_material.multiscale.adaptive.AdaptiveMaterial` of ``spec``'s
    DEM material: the source RVE is the one the DEM material prepares for the first Gauss
    point (at its initial stress: the packing every point of an all-DEM run of a uniform
    start holds), the twin the Mohr–Coulomb material of ``[adaptivity] calibration`` or,
    without it, of the source RVE calibrated at the scene's reference pressure; every point
    starts on the twin at its ``initial_stress`` [Pa] (n, 2, 2). A resume (``saved``: the
    material's checkpoint) makes the same material from the calibration and source the
    checkpoint holds, preparing and calibrating nothing (an older checkpoint without
    them: as a fresh run)."""
    from granular_material.multiscale.adaptive import adaptive_for_resume, calibrated_adaptive

    a = spec.adaptivity
    sigma0 = np.asarray(initial_stress, float)
    if saved is not None:
        first = _one_material(spec, spec.material, "material", 1, sigma0[:1], False)
        material = adaptive_for_resume(saved, first.parameters, sigma0, a.criterion(),
                                       nqp=nqp, start=a.start, progress=spec.progress)
        if material is not None:
            if allocate:
                material.allocate(n_points)
            return material
    first = _one_material(spec, spec.material, "material", 1, sigma0[:1], True)
    material = calibrated_adaptive(first.committed_rves(), first.parameters,
                                   spec.reference_pressure, sigma0, a.criterion(), nqp=nqp,
                                   start=a.start, calibration=a.calibration,
                                   elastic_window=a.elastic_window, progress=spec.progress)
    if allocate:
        material.allocate(n_points)
    return material


def region_unit_weights(spec: BoundaryValueSpec) -> dict[str, float]:
    """Region name → γ [N/m³] of each ``[[materials]]`` entry: its own ``unit_weight`` (a
    number, or ``"rve"`` from its own RVEs), else the scene's (``"rve"``: the region's RVEs);
    empty without regions."""
    out = {}
    for m in spec.materials or ():
        weight = spec.unit_weight if m.unit_weight is None else m.unit_weight
        if weight != "rve":
            out[m.region] = float(weight)
            continue
        hook = getattr(m.material.cls, "unit_weight", None)
        if hook is None:
            field = ("materials.unit_weight" if m.unit_weight is not None
                     else "gravity.unit_weight")
            raise SpecError(field, f'"rve" needs a material of RVEs (dem); region '
                                   f"{m.region!r} is {m.material.name}: give a number [N/m³]")
        out[m.region] = float(hook(m.material.parameters, GRAVITY))
    return out


def unit_weight_of(spec: BoundaryValueSpec) -> float:
    """γ [N/m³] of the problem's body force: the spec's number, or with ``"rve"`` the dry
    unit weight of the DEM material's RVEs, ρ_s·g/(1 + e) (grain density ρ_s, void ratio e of
    the RVE file, or the target of the RVEs the run prepares; the discs' thickness cancels:
    the solid fraction of a layer of discs of one thickness is 1/(1 + e))."""
    if spec.unit_weight != "rve":
        return float(spec.unit_weight)
    if spec.materials is not None:  # each region's own, from region_unit_weights
        return 0.0
    hook = getattr(spec.material.cls, "unit_weight", None)
    if hook is None:
        raise SpecError("gravity.unit_weight", f'"rve" needs a material of RVEs (dem), not '
                                               f"{spec.material.name}: give a number [N/m³]")
    return float(hook(spec.material.parameters, GRAVITY))
