"""The specification of a boundary-value problem run: a mesh, named boundaries, conditions on
them, gravity, an initial state, the load steps, the material, Newton and the outputs.

A scene file (``granular-material run SCENE.toml``) with ``test = "boundary-value"`` is read
into a :class:`BoundaryValueSpec` by :func:`bvp_from_dict` (every key checked, a refusal a
:class:`~granular_material.runs.spec.SpecError` naming the key). The layout of the file::

    test = "boundary-value"
    steps = 58                      # load steps: every condition reaches its end value

    [mesh]                          # a file read through meshio ...
    file = "footing.msh"            # relative to the scene's folder
    # ... or a generated rectangle with its sides named left, right, bottom, top
    size = [0.6, 0.4]               # width, height [m]
    elements = [12, 8]
    element = "tri6"                # tri3, tri6, quad4, quad8, quad9
    grading = [4.0, 0.25]           # last/first element size along x and y (refine a corner)
    align_x = [0.05]                # move the nearest grid line onto these x [m] (a footing's edge)
    quadrature = 3                  # optional: Gauss points (per direction for quads)

    [boundaries]                    # name = predicate, or a physical group of the file
    footing = "y = top and x <= 0.05"

    [[conditions]]                  # fixed | roller | displacement | rigid | pressure
    type = "rigid"
    boundary = "footing"
    displacement = [0.0, -0.0145]   # [m] at the last step
    rough = true

    [[conditions]]
    type = "pressure"
    boundary = "top"
    value = 20e3                    # [Pa], compression positive, at step 0 ...
    end = 60e3                      # ... and at the last step (default: value throughout)

    [gravity]
    unit_weight = 0.0               # [N/m³]; "rve": from the RVEs' grain density and e
    factor = [1.0, 1.5]             # γ's multiple at step 0 and at the last step (default: 1)

    [initial]
    state = "uniform"               # or "geostatic"
    pressure = 20e3                 # uniform: isotropic stress [Pa], compression positive;
                                    # 0: stress-free (a continuum material only)
    # geostatic: sigma_v = surcharge + the weight of the column above each point (each
    # region's f0 * unit_weight), sigma_h = k0 * sigma_v, corrected into equilibrium under a
    # slope, a step or layers (fem.boundary_value.ground); k0 = 0.5 (a region's own: k0 in
    # its [[materials]] entry), surcharge = 20e3, minimum_pressure = 1e3 [Pa] (default: a
    # DEM region's RVE floor, none elsewhere), surface = 0.4 (a level surface at that y, one
    # unit weight and K0; default: found from the mesh)

    [material]                      # as a run specification's: name and parameters
    name = "mohr-coulomb"
    [material.parameters]
    phi = 30.0

    # ... or materials by region, in place of [material]:
    [regions]                       # name = predicate at each element's centroid, or a
    fill = "y >= 0.2"               # physical group of the mesh file's cells
    [[materials]]                   # one per region; a region not in [regions] is the
    region = "fill"                 # mesh file's physical group of that name
    name = "linear-elastic"
    unit_weight = 18e3              # optional: this region's γ [N/m³] (else [gravity]'s)
    k0 = 0.6                        # optional, geostatic: this region's K0 (else [initial]'s)
    [materials.parameters]
    young = 80e6

    # ... or the loading in phases (each from the state the previous one committed), in
    # place of the scene's steps and [gravity] factor; [[conditions]] are then common to
    # every phase (a phase's own come after them and win on a shared degree of freedom)
    [[phases]]
    name = "gravity"
    steps = 4
    [phases.gravity]
    factor = [0.0, 1.0]             # first phase: at its start and end; later: its end
    [[phases.conditions]]           # as [[conditions]]; loads are totals at the phase's
    type = "pressure"               # end, prescribed displacements increments over it
    boundary = "top"
    value = 10e3
    [[phases]]
    name = "strip"
    steps = 6
    reset_displacements = true      # report displacement (and strain) from this phase's start

    [strength_reduction]            # after the loading: tan φ and c of the Mohr–Coulomb
    factor_end = 3.0                # regions divided by F, followed by arc length to the
    steps = 20                      # collapse (the factor of safety)

    [adaptivity]                    # a DEM material: the calibrated Mohr–Coulomb twin at every
    mobilised_fraction = 0.7        # point, a DEM RVE once φ_mob reaches this fraction of the
    shear_strain = 0.01             # twin's φ (and/or γ this); neighbours = "element" or
    neighbours = "element"          # "point"; calibration = "calibration.json" (else the
    start = "strain"                # scene's RVE is calibrated at its pressure at the start);
    switch = "in-step"              # the RVE driven through the point's deformation, or
                                    # "stress": servoed to its stress; DEM in the step a
                                    # threshold is met, or "after-step"

    [newton]                        # NewtonSpec's fields
    [regularisation]                # past a peak: model = "second-gradient" (quad8, quad9,
    internal_length = 0.005         # tri6), ℓ [m]; default model = "none"
    [output]                        # out, device, shards, progress, fields, points_csv,
                                    # figures
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from granular_material.multiscale.parameters import MAX_SHARDS
from granular_material.runs.spec import (
    AdaptivitySpec,
    MaterialSpec,
    NewtonSpec,
    RegularisationSpec,
    SpecError,
)
from granular_material.typed_fields import conform, conform_fields
from granular_material.vocabulary import RenamedWarning, key_of, user_stacklevel

__all__ = ["CONDITION_KEYS", "CONDITION_TYPES", "INITIAL_KEYS", "INITIAL_STATES", "SCENE_KEYS",
           "STRENGTH_FRACTION", "AdaptivitySpec", "BoundaryValueSpec", "ConditionSpec",
           "InitialStateSpec", "MeshSpec", "PhaseSpec", "RegionMaterialSpec",
           "StrengthReductionSpec", "bvp_from_dict"]

#: the conditions a boundary may carry
CONDITION_TYPES = ("fixed", "roller", "displacement", "rigid", "pressure")
#: the initial states of a problem
INITIAL_STATES = ("uniform", "geostatic", "continuum")
#: the keys each type of condition acts on (any other is refused, not ignored)
CONDITION_KEYS: dict[str, frozenset[str]] = {
    "fixed": frozenset({"type", "boundary"}),
    "roller": frozenset({"type", "boundary", "component"}),
    "displacement": frozenset({"type", "boundary", "component", "value"}),
    "rigid": frozenset({"type", "boundary", "displacement", "rough"}),
    "pressure": frozenset({"type", "boundary", "value", "end"}),
}
#: the keys each initial state acts on (any other is refused, not ignored)
INITIAL_KEYS: dict[str, frozenset[str]] = {
    "uniform": frozenset({"state", "pressure"}),
    "geostatic": frozenset({"state", "k0", "surcharge", "surface", "minimum_pressure"}),
    "continuum": frozenset({"state", "minimum_pressure", "strength_fraction"}),
}
#: a continuum start's default cap on the mobilised friction angle, as a fraction of the
#: material's friction angle (its twin's, for DEM RVEs)
STRENGTH_FRACTION = 0.7
#: the keys of [mesh] that only a generated rectangle acts on
_GENERATED_KEYS = frozenset({"size", "elements", "element", "grading", "align_x", "align_y"})
#: the components by name
_COMPONENTS = {"x": 0, "y": 1, 0: 0, 1: 1}
_ELEMENTS = ("tri3", "tri6", "quad4", "quad8", "quad9")


def _within(section: str, build: Callable[[], Any]) -> Any:
    """``build()``, a SpecError it raises named within ``section`` (``mesh.size``)."""
    try:
        return build()
    except SpecError as exc:
        if exc.field.startswith(section + "."):
            raise
        raise SpecError(f"{section}.{exc.field}", exc.message) from None


def _conditions(conditions: Any, field_name: str) -> tuple[ConditionSpec, ...]:
    """``conditions`` as a tuple of ConditionSpec; SpecError naming ``field_name`` for
    anything else (a table given where a spec object belongs)."""
    if isinstance(conditions, str | bytes | Mapping) or not isinstance(conditions, Iterable):
        raise SpecError(field_name, f"must be a sequence of ConditionSpec, got "
                                    f"{type(conditions).__name__}")
    conditions = tuple(conditions)
    for k, c in enumerate(conditions):
        if not isinstance(c, ConditionSpec):
            raise SpecError(field_name, f"must be ConditionSpec objects; condition {k} is a "
                                        f"{type(c).__name__} (a scene's tables are read by "
                                        "bvp_from_dict)")
    return conditions


def _table(name: str, value: Any) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise SpecError(name, f"must be a table, got {value!r}")
    return dict(value)


def _not_acting(section: str, given: Mapping[str, Any], acting: frozenset[str],
                what: str) -> None:
    """SpecError naming the first key of ``given`` outside ``acting`` (keys ``what`` does not
    act on: refused, where they would be ignored)."""
    extra = sorted(set(given) - acting)
    if extra:
        raise SpecError(f"{section}.{extra[0]}", f"does nothing for {what}, so it is refused "
                                                 f"(it takes {', '.join(sorted(acting))})")


def _unknown(section: str, given: Mapping[str, Any], known: set[str]) -> None:
    extra = sorted(set(given) - known)
    if extra:
        raise SpecError(f"{section}.{extra[0]}" if section else extra[0],
                        f"is not a key of [{section or 'scene'}] (it has "
                        f"{', '.join(sorted(known))})")


@dataclass(frozen=True, kw_only=True)
class MeshSpec:
    """The mesh: a file (``file``), or a generated rectangle (``size``, ``elements``,
    ``element``, ``grading``: the ratios (rx, ry) of the last element's size to the first's
    along x and y, None for uniform); ``quadrature``: Gauss points (None: the element's
    default); ``align_x``, ``align_y``: coordinates [m] onto which the nearest grid line of a
    generated mesh is moved (so that a boundary such as a footing's edge falls on a node)."""

    file: Path | None = None
    size: tuple[float, float] | None = None
    elements: tuple[int, int] | None = None
    element: str = "quad4"
    grading: tuple[float, float] | None = None
    quadrature: int | None = None
    align_x: tuple[float, ...] = ()
    align_y: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        conform_fields(self, error=SpecError)
        if self.elements is not None and min(self.elements) < 1:
            raise SpecError("mesh.elements", f"must be two counts >= 1, got {self.elements}")
        for axis, values in enumerate((self.align_x, self.align_y)):
            lines = None if self.elements is None else self.elements[axis] - 1
            if lines is not None and len(values) > lines:
                raise SpecError(f"mesh.align_{'xy'[axis]}", f"moves {len(values)} grid lines; "
                                                          f"{self.elements[axis]} elements "
                                                          f"along {'xy'[axis]} have {lines} "
                                                          "inside the mesh")
        if (self.file is not None) and (self.align_x or self.align_y):
            raise SpecError("mesh.align_x", "aligns a generated mesh's grid lines; a mesh "
                                            "file has its own nodes")
        if self.file is not None:
            for name, value, default in (("elements", self.elements, None),
                                         ("grading", self.grading, None),
                                         ("element", self.element, "quad4")):
                if value != default:
                    raise SpecError(f"mesh.{name}", "shapes a generated rectangle; a mesh file "
                                                    "has its own elements, so it is refused")
        if (self.file is None) == (self.size is None):
            raise SpecError("mesh", "needs either file (a mesh file) or size and elements "
                                    "(a generated rectangle)")
        if self.size is not None:
            if self.elements is None:
                raise SpecError("mesh.elements", "a generated mesh needs elements [nx, ny]")
            if min(self.size) <= 0:
                raise SpecError("mesh.size", f"must be two lengths > 0 [m], got {self.size}")
            if self.element not in _ELEMENTS:
                raise SpecError("mesh.element", f"must be one of {', '.join(_ELEMENTS)}, "
                                                f"got {self.element!r}")
        if self.grading is not None and not min(self.grading) > 0:
            raise SpecError("mesh.grading", f"must be two ratios > 0, got {self.grading!r}")
        if self.quadrature is not None and (isinstance(self.quadrature, bool)
                                            or not isinstance(self.quadrature, int)
                                            or self.quadrature < 1):
            raise SpecError("mesh.quadrature", f"must be an integer >= 1, got "
                                               f"{self.quadrature!r}")


@dataclass(frozen=True, kw_only=True)
class ConditionSpec:
    """One condition on a named boundary.

    Attributes:
        type: "fixed" (both components 0), "roller" (``component`` 0), "displacement"
            (``component`` prescribed, linear in the load factor to ``value`` [m]), "rigid"
            (the boundary moved as one body by ``displacement`` [m] at the end; ``rough``
            ties both components of every node, smooth only the one along the motion) or
            "pressure" (``value`` [Pa], compression positive, normal to the boundary on its
            current length: constant through the run, or linear to ``end`` at the last
            step).
        boundary: the boundary's name.
        component: 0 (x) or 1 (y), for roller and displacement.
        value: the end displacement [m] or the pressure [Pa] (at step 0).
        end: a pressure's value [Pa] at the last step (None: ``value`` throughout).
        displacement: (dx, dy) [m] of a rigid body at the end.
        rough: a rigid body's nodes keep both components tied (True) or slide (False).
    """

    type: str
    boundary: str
    component: int | None = None
    value: float | None = None
    end: float | None = None
    displacement: tuple[float, float] | None = None
    rough: bool = True

    def __post_init__(self) -> None:
        conform_fields(self, error=SpecError)
        if self.type not in CONDITION_TYPES:
            raise SpecError("conditions.type", f"must be one of {', '.join(CONDITION_TYPES)}, "
                                               f"got {self.type!r}")
        if self.end is not None and self.type != "pressure":
            raise SpecError("conditions.end", f"only a pressure has an end value (a "
                                              f"{self.type}'s value is its end)")
        given = {"component": self.component is not None, "value": self.value is not None,
                 "end": self.end is not None, "displacement": self.displacement is not None,
                 "rough": self.rough is not True}
        _not_acting("conditions", {k for k, on in given.items() if on},
                    CONDITION_KEYS[self.type], f"a {self.type} condition")
        if self.type in ("roller", "displacement") and self.component not in (0, 1):
            raise SpecError("conditions.component", f"a {self.type} needs component x or y")
        if self.type in ("displacement", "pressure") and self.value is None:
            raise SpecError("conditions.value", f"a {self.type} needs a value")
        for name in ("value", "end"):
            p = getattr(self, name)
            if self.type == "pressure" and p is not None and not p >= 0:
                raise SpecError(f"conditions.{name}", f"a pressure is compression positive, "
                                                      f">= 0 Pa, got {p:g}")
        if self.type == "rigid" and self.displacement is None:
            raise SpecError("conditions.displacement", "a rigid body needs displacement "
                                                       "[dx, dy] [m]")


@dataclass(frozen=True, kw_only=True)
class InitialStateSpec:
    """The stress every Gauss point starts from (compression positive here).

    Attributes:
        state: "uniform" (isotropic ``pressure`` [Pa]) or "geostatic" (σv = surcharge + the
            weight of the column above each point, each region's own unit weight; σh =
            k0·σv; corrected into discrete equilibrium where the surface is not level or the
            regions differ: :mod:`~granular_material.fem.boundary_value.ground`).
        pressure: the uniform state's pressure [Pa], >= 0; 0 is a stress-free start (a
            continuum material's: an RVE needs confinement, so a DEM material refuses it).
        k0: the geostatic ratio σh/σv [-], > 0 (a region's own ``k0`` in its
            ``[[materials]]`` entry overrides it there).
        surcharge: the stress on the surface [Pa], >= 0.
        surface: y of a level free surface [m] (one unit weight and one K0); None: the
            surface above each point, found from the mesh.
        minimum_pressure: the floor [Pa] of every point's least principal compression:
            points below it (at the free surface, or in tension near a steep face after the
            correction) are lifted to it by an isotropic pressure
            (:func:`~granular_material.fem.boundary_value.ground.lift_to_floor`); None: the
            lowest stress an RVE is prepared at in a DEM region (15 Pa for the default
            contact law), none elsewhere. A continuum start's floor too.
        strength_fraction: a continuum start's cap on each point's mobilised friction angle,
            as a fraction of its material's friction angle (the Mohr–Coulomb twin calibrated
            from a DEM region's RVEs), in (0, 1]; None: :data:`STRENGTH_FRACTION`.

    A "continuum" state is the loads at step 0 carried by a linear-elastic stand-in of each
    region's material (a DEM region's calibrated twin), then floored, capped and settled
    back towards equilibrium (:mod:`~granular_material.fem.boundary_value.continuum_start`).
    """

    state: str = "uniform"
    pressure: float | None = None
    k0: float = 0.5
    surcharge: float = 0.0
    surface: float | None = None
    minimum_pressure: float | None = None
    strength_fraction: float | None = None

    def __post_init__(self) -> None:
        conform_fields(self, error=SpecError)
        if self.state not in INITIAL_STATES:
            raise SpecError("initial.state", f"must be one of {', '.join(INITIAL_STATES)}, "
                                             f"got {self.state!r}")
        given = {"pressure": self.pressure is not None, "k0": self.k0 != 0.5,
                 "surcharge": self.surcharge != 0.0, "surface": self.surface is not None,
                 "minimum_pressure": self.minimum_pressure is not None,
                 "strength_fraction": self.strength_fraction is not None}
        _not_acting("initial", {k for k, on in given.items() if on}, INITIAL_KEYS[self.state],
                    f"a {self.state} initial state")
        if self.state == "uniform" and (self.pressure is None or not self.pressure >= 0):
            raise SpecError("initial.pressure", "a uniform initial state needs a pressure "
                                                f">= 0 Pa (0: stress-free), got "
                                                f"{self.pressure!r}")
        if self.k0 <= 0:
            raise SpecError("initial.k0", f"must be > 0, got {self.k0:g}")
        if self.surcharge < 0:
            raise SpecError("initial.surcharge", f"must be >= 0 Pa, got {self.surcharge:g}")
        if self.strength_fraction is not None and not 0 < self.strength_fraction <= 1:
            raise SpecError("initial.strength_fraction", f"must lie in (0, 1] (a fraction of "
                                                         f"the material's friction angle), "
                                                         f"got {self.strength_fraction:g}")
        if self.minimum_pressure is not None and not self.minimum_pressure >= 0:
            raise SpecError("initial.minimum_pressure", f"must be >= 0 Pa, got "
                                                        f"{self.minimum_pressure:g}")

    @property
    def reference_pressure(self) -> float:
        """A representative pressure [Pa] (for the material's and Newton's scales): the
        uniform pressure, else the surcharge (or 1 kPa where there is none: a stress-free
        start, a geostatic one without surcharge)."""
        if self.state == "uniform" and self.pressure > 0:
            return float(self.pressure)
        return float(self.surcharge) if self.surcharge > 0 else 1e3


@dataclass(frozen=True, kw_only=True)
class RegionMaterialSpec:
    """The material of one region (a ``[[materials]]`` entry).

    Attributes:
        region: the region's name: a key of the scene's ``[regions]``, or a physical group
            of the mesh file's two-dimensional cells.
        material: the region's material (as a run specification's ``[material]``).
        unit_weight: the region's γ [N/m³] (>= 0), or "rve" (from its RVEs); None: the
            scene's ``[gravity] unit_weight``.
        k0: the region's K0 = σh/σv [-] (> 0) of a geostatic start; None: the scene's
            ``[initial] k0``.
    """

    region: str
    material: MaterialSpec
    unit_weight: float | str | None = None
    k0: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.region, str) or not self.region.strip():
            raise SpecError("materials.region", f"must name a region (text), got "
                                                f"{self.region!r}")
        if not isinstance(self.material, MaterialSpec):
            raise SpecError("materials", f"must hold a MaterialSpec, got "
                                         f"{type(self.material).__name__}")
        if self.unit_weight is not None and self.unit_weight != "rve":
            weight = conform("materials.unit_weight", self.unit_weight, float, SpecError)
            if not weight >= 0:
                raise SpecError("materials.unit_weight", f"must be >= 0 N/m³, got {weight:g}")
            object.__setattr__(self, "unit_weight", weight)
        if self.k0 is not None:
            k0 = conform("materials.k0", self.k0, float, SpecError)
            if not k0 > 0:
                raise SpecError("materials.k0", f"must be > 0, got {k0:g}")
            object.__setattr__(self, "k0", k0)


@dataclass(frozen=True, kw_only=True)
class PhaseSpec:
    """One phase of a staged loading (a ``[[phases]]`` entry).

    A phase starts from the state the one before committed (stress, material state,
    displacement) and steps its load factor λ from 0 to 1:

    - its loads (pressures, gravity) are totals at its end, ramped linearly from what acted
      at its start (the first phase: from their ``value`` and the first gravity factor, as
      a scene without phases); a load of the phase before that the phase does not give is
      ramped off to zero;
    - its prescribed displacements are increments from where the phase starts (a fixed or
      roller boundary is held where it is at the start); a boundary held in the phase before
      and not in this one is free from the phase's first step (its reaction is released at
      once).

    Attributes:
        name: the phase's name (in the tables' ``phase`` column and the summary).
        steps: its load steps, >= 1.
        conditions: its own conditions (after the scene's common ones, so that a phase's
            own wins on a shared degree of freedom). A pressure's ``value`` is its total at
            the phase's end; ``end`` is the first phase's only (from ``value`` at step 0).
        gravity_factor: γ's multiple: the first phase's (f0, f1) at its start and its end,
            or f (constant); a later phase's f at its end (from where the phase before
            ended). None: γ as it stood (the first phase: 1).
        reset_displacements: the displacement (and strain) reported from this phase on is
            measured from the phase's start; the stress, the material state and the
            configuration are kept (refused in the first phase, which starts from zero).
    """

    name: str
    steps: int
    conditions: tuple[ConditionSpec, ...] = ()
    gravity_factor: float | tuple[float, float] | None = None
    reset_displacements: bool = False

    def __post_init__(self) -> None:
        _within("phases", lambda: conform_fields(self, error=SpecError,
                                                 skip=("conditions", "gravity_factor")))
        if not self.name.strip():
            raise SpecError("phases.name", "must name the phase (text), got an empty name")
        if self.steps < 1:
            raise SpecError("phases.steps", f"must be an integer >= 1, got {self.steps!r}")
        object.__setattr__(self, "conditions", _conditions(self.conditions,
                                                           "phases.conditions"))
        factor = self.gravity_factor
        if factor is not None:
            if isinstance(factor, list | tuple):
                factor = conform("phases.gravity.factor", factor, tuple[float, float],
                                 SpecError)
                low = min(factor)
            else:
                factor = conform("phases.gravity.factor", factor, float, SpecError)
                low = factor
            if not low >= 0:
                raise SpecError("phases.gravity.factor", f"must be >= 0, got {factor!r}")
            object.__setattr__(self, "gravity_factor", factor)

    def factors(self, before: float | None) -> tuple[float, float]:
        """γ's multiples (at the phase's start, at its end), given the one the phase before
        ended with (``before``; None: this is the first phase)."""
        f = self.gravity_factor
        if isinstance(f, tuple):
            return f
        if before is None:  # the first phase: constant, 1 where none is given
            return (1.0, 1.0) if f is None else (f, f)
        return before, before if f is None else f


@dataclass(frozen=True, kw_only=True)
class StrengthReductionSpec:
    """The factor of safety by strength reduction, after the loading
    (:func:`~granular_material.fem.solver.strength_reduction.strength_reduction`): tan φ and
    c of every Mohr–Coulomb region divided by F, F followed by arc length to the collapse.

    Attributes:
        factor_end: the largest F tried (> 1); a slope that stands at it has F ≥ it.
        steps: nominal steps from F = 1 to ``factor_end`` (the largest change of F a step;
            the path may take up to ``[newton] arc_length_steps`` times as many).
    """

    factor_end: float = 3.0
    steps: int = 20

    def __post_init__(self) -> None:
        conform_fields(self, error=SpecError)
        if not self.factor_end > 1:
            raise SpecError("strength_reduction.factor_end",
                            f"must be > 1 (F = 1 is the loading's end), got {self.factor_end!r}")
        if self.steps < 1:
            raise SpecError("strength_reduction.steps", f"must be an integer >= 1, got "
                                                        f"{self.steps!r}")


@dataclass(frozen=True, kw_only=True)
class BoundaryValueSpec:
    """One boundary-value problem run (see the module docstring for its file form).

    Attributes:
        mesh: the mesh.
        boundaries: name → predicate (e.g. ``"y = top and x <= 0.05"``) or the name of a
            physical group of the mesh file.
        conditions: the conditions, applied in order (a later one on the same degree of
            freedom wins).
        unit_weight: γ [N/m³] of the body force, or "rve" (from the RVEs).
        gravity_factor: (f0, f1): the body force is f0·γ at step 0 and f1·γ at the last
            step, linear in the load factor between (gravity switched on, or increased);
            None: γ throughout.
        initial: the initial state.
        steps: load steps.
        material: the material (as in a run specification); with ``materials``, left at
            its default.
        regions: name → predicate at each element's centroid (``"y >= 0.2"``) or the name
            of a physical group of the mesh file's cells; None: no regions of its own (the
            materials' regions are then the file's physical groups).
        materials: one :class:`RegionMaterialSpec` per region, in place of ``material``
            (None: ``material`` everywhere). Every element must lie in exactly one region.
        newton: the Newton solver.
        regularisation: the FEM's regularisation (``[regularisation]``: ``model``,
            ``internal_length`` [m]; none by default).
        out: the run folder (None: nothing written).
        device: the DEM device ("cpu", "cuda", "cuda:N"; None: CUDA where present); shards:
            CPU shards; progress: progress bars.
        fields: write the ParaView fields (fields.xdmf) at every committed step.
        points_csv: write the Gauss-point table also as text, points.csv (points.npy is
            written regardless).
        figures: draw the run's figures at its end (load_displacement.png, mechanism.png,
            strength_reduction.png); False: tables, fields and summary only.
        name: the problem's name (tables and figures).
        phases: the loading in stages (:class:`PhaseSpec`), each from the state the one
            before committed; empty: one phase, ``conditions``, ``gravity_factor`` and
            ``steps`` as given. With phases, ``conditions`` are common to every phase (a
            load among them constant), ``gravity_factor`` is the phases' own and ``steps``
            becomes their sum.
        strength_reduction: the factor of safety by strength reduction after the loading
            (``[strength_reduction]``), or None.
        adaptivity: the DEM material where the scene requires it, the calibrated twin
            elsewhere (``[adaptivity]``), or None: DEM at every point.
    """

    mesh: MeshSpec
    boundaries: dict[str, str] = field(default_factory=dict)
    conditions: tuple[ConditionSpec, ...] = ()
    unit_weight: float | str = 0.0
    gravity_factor: tuple[float, float] | None = None
    initial: InitialStateSpec = field(default_factory=lambda: InitialStateSpec(
        pressure=100e3))
    steps: int = 10
    material: MaterialSpec = field(default_factory=lambda: MaterialSpec(name="linear-elastic"))
    regions: dict[str, str] | None = None
    materials: tuple[RegionMaterialSpec, ...] | None = None
    newton: NewtonSpec = field(default_factory=NewtonSpec)
    regularisation: RegularisationSpec = field(default_factory=RegularisationSpec)
    out: Path | None = None
    device: str | None = None
    shards: int | None = None
    progress: bool = False
    fields: bool = True
    points_csv: bool = False
    figures: bool = True
    name: str = "problem"
    phases: tuple[PhaseSpec, ...] = ()
    strength_reduction: StrengthReductionSpec | None = None
    adaptivity: AdaptivitySpec | None = None

    def __post_init__(self) -> None:
        self._check_sections()
        self._check_strength_reduction()
        self._check_adaptivity()
        conform_fields(self, error=SpecError, skip=_SECTIONS)
        if self.phases:
            _check_phases(self)
        if self.shards is not None and not 1 <= self.shards <= MAX_SHARDS:
            raise SpecError("shards", f"must be an integer from 1 to {MAX_SHARDS} (a CPU "
                                      f"thread each), got {self.shards!r}")
        if self.mesh.file is None:
            _within("regularisation", lambda: self.regularisation.check_element(
                self.mesh.element))
        if self.steps < 1:
            raise SpecError("steps", f"must be an integer >= 1, got {self.steps!r}")
        if not self.conditions and not self.phases:
            raise SpecError("conditions", "a problem needs at least one condition")
        named = {c.boundary for c in self.conditions}
        missing = sorted(named - set(self.boundaries) - _GENERATED_SIDES
                         if self.mesh.file is None else set())
        if missing:
            raise SpecError("conditions.boundary", f"{missing[0]!r} is no boundary of "
                                                   "[boundaries] nor a side of the mesh")
        if self.unit_weight != "rve":
            weight = conform("gravity.unit_weight", self.unit_weight, float, SpecError)
            if weight < 0:
                raise SpecError("gravity.unit_weight", f"must be >= 0 N/m³, got {weight:g}")
            object.__setattr__(self, "unit_weight", weight)
        self._check_regions()
        self._check_start()
        if self.gravity_factor is not None:
            factor = conform("gravity.factor", self.gravity_factor, tuple[float, float],
                             SpecError)
            if min(factor) < 0:
                raise SpecError("gravity.factor", f"must be >= 0, got {list(factor)}")
            if self.unit_weight == 0.0 and not any(
                    m.unit_weight not in (None, 0.0) for m in self.materials or ()):
                raise SpecError("gravity.factor", "multiplies a unit weight of 0 N/m³, so it "
                                                  "does nothing and is refused (set "
                                                  "gravity.unit_weight)")
            object.__setattr__(self, "gravity_factor", factor)

    def _check_regions(self) -> None:
        """SpecError naming what is wrong with ``regions`` and ``materials`` (each checked
        against the mesh when the run is built)."""
        regions, materials = self.regions, self.materials
        if regions is not None:
            if not isinstance(regions, Mapping) or not all(
                    isinstance(k, str) and isinstance(v, str) for k, v in regions.items()):
                raise SpecError("regions", f"must map names to predicates or physical groups "
                                           f"(text), got {regions!r}"[:200])
            object.__setattr__(self, "regions", dict(regions))
        if materials is None:
            if regions is not None:
                raise SpecError("regions", "names regions, but no [[materials]] gives them "
                                           "a material, so it is refused")
            return
        if isinstance(materials, str | bytes | Mapping) or not isinstance(materials,
                                                                           Iterable):
            raise SpecError("materials", f"must be a sequence of RegionMaterialSpec, got "
                                         f"{type(materials).__name__}")
        materials = tuple(materials)
        if not materials:
            raise SpecError("materials", "must give at least one region's material")
        for k, m in enumerate(materials):
            if not isinstance(m, RegionMaterialSpec):
                raise SpecError("materials", f"must be RegionMaterialSpec objects; entry {k} "
                                             f"is a {type(m).__name__}")
        named = [m.region for m in materials]
        twice = sorted({r for r in named if named.count(r) > 1})
        if twice:
            raise SpecError("materials.region", f"{twice[0]!r} is given two materials: give "
                                                "each region one")
        if self.material != MaterialSpec(name="linear-elastic"):
            raise SpecError("material", "is given beside [[materials]]: give either one "
                                        "[material] or a material per region")
        unused = sorted(set(regions or {}) - set(named))
        if unused:
            raise SpecError(f"regions.{unused[0]}", "is given no material by [[materials]], "
                                                    "so it is refused (every element belongs "
                                                    "to one region with a material)")
        if self.mesh.file is None:
            loose = [r for r in named if r not in (regions or {})]
            if loose:
                raise SpecError("materials.region", f"{loose[0]!r} is no region of "
                                                    "[regions] (a generated mesh has no "
                                                    "physical groups)")
        object.__setattr__(self, "materials", materials)

    def _check_start(self) -> None:
        """SpecError for a region's k0 that a uniform start ignores, and for a stress-free
        start of a material that needs confinement (DEM RVEs)."""
        initial = self.initial
        if initial.state != "geostatic":
            given = [m.region for m in self.materials or () if m.k0 is not None]
            if given:
                raise SpecError("materials.k0", f"(region {given[0]!r}) does nothing for a "
                                                f"{initial.state} initial state, so it is "
                                                "refused (it is a geostatic start's K0)")
        if initial.state == "uniform" and initial.pressure == 0:
            pairs = ([(m.region, m.material) for m in self.materials]
                     if self.materials is not None else [(None, self.material)])
            for region, material in pairs:
                if hasattr(material.cls, "lowest_pressure"):
                    where = "" if region is None else f" (region {region!r})"
                    raise SpecError("initial.pressure", f"0 Pa, a stress-free start, cannot "
                                                        f"start {material.name}{where}: an "
                                                        "RVE is a packing of discs, which "
                                                        "carries stress only while it is "
                                                        "confined, so it cannot be prepared "
                                                        "at zero pressure; give a pressure "
                                                        "> 0, or start geostatic")

    def _check_strength_reduction(self) -> None:
        """SpecError for a strength reduction that cannot act: one whose materials have no
        strength to reduce (no Mohr–Coulomb region), or beside an arc-length loading."""
        sr = self.strength_reduction
        if sr is None:
            return
        if not isinstance(sr, StrengthReductionSpec):
            raise SpecError("strength_reduction", f"must be a StrengthReductionSpec, got "
                                                  f"{type(sr).__name__}")
        names = ([m.material.name for m in self.materials] if self.materials is not None
                 else [self.material.name])
        if "mohr-coulomb" not in names:
            raise SpecError("strength_reduction", f"divides tan φ and c of Mohr–Coulomb "
                                                  f"materials, and this problem has none "
                                                  f"({', '.join(sorted(set(names)))}); a "
                                                  "gravity-increase factor (a [gravity] "
                                                  "factor with [newton] continuation = "
                                                  '"arc-length") serves every material')
        if self.newton.continuation != "load":
            raise SpecError("newton.continuation", "must be \"load\" with "
                                                   "[strength_reduction]: the loading before "
                                                   "it is stepped by load, the reduction by "
                                                   "its own arc length")

    def _check_adaptivity(self) -> None:
        """SpecError for adaptivity that cannot act: with no DEM material, or with materials
        by region."""
        a = self.adaptivity
        if a is None:
            return
        if not isinstance(a, AdaptivitySpec):
            raise SpecError("adaptivity", f"must be an AdaptivitySpec, got {type(a).__name__}")
        if self.materials is not None:
            raise SpecError("adaptivity", "works on one [material] of DEM RVEs, not on "
                                          "materials by region")
        if self.material.name != "dem":
            raise SpecError("adaptivity", f"moves points from a continuum twin to DEM RVEs, "
                                          f"and this problem's material is "
                                          f"{self.material.name}, not dem: leave "
                                          "[adaptivity] out")

    @property
    def noisy(self) -> bool:
        """Whether any material of the problem is noisy (DEM RVEs): the Newton defaults of
        noisy materials apply."""
        if self.materials is None:
            return self.material.noisy
        return any(m.material.noisy for m in self.materials)

    def _check_sections(self) -> None:
        """SpecError naming the first section that is not of its class (a table given where
        a spec object belongs: ``mesh={...}``), the conditions made a tuple."""
        for name, cls in (("mesh", MeshSpec), ("initial", InitialStateSpec),
                          ("material", MaterialSpec), ("newton", NewtonSpec),
                          ("regularisation", RegularisationSpec)):
            value = getattr(self, name)
            if not isinstance(value, cls):
                raise SpecError(name, f"must be a {cls.__name__}, got "
                                      f"{type(value).__name__} (a scene's tables are read by "
                                      "bvp_from_dict)")
        if not isinstance(self.boundaries, Mapping) or not all(
                isinstance(k, str) and isinstance(v, str) for k, v in self.boundaries.items()):
            raise SpecError("boundaries", f"must map names to predicates (text), got "
                                          f"{self.boundaries!r}")
        object.__setattr__(self, "conditions", _conditions(self.conditions, "conditions"))

    @property
    def reference_pressure(self) -> float:
        """The problem's representative pressure [Pa] (see :class:`InitialStateSpec`)."""
        return self.initial.reference_pressure


#: the fields of BoundaryValueSpec that are sections, each checked by its own class (or,
#: ``unit_weight``, a number or "rve")
_SECTIONS = ("mesh", "boundaries", "conditions", "unit_weight", "gravity_factor", "initial",
             "material", "regions", "materials", "newton", "regularisation", "phases",
             "strength_reduction", "adaptivity")
#: the sides every generated rectangle names
_GENERATED_SIDES = frozenset({"left", "right", "bottom", "top"})


def _condition(entry: Any, index: int) -> ConditionSpec:
    """The condition of the ``index``-th [[conditions]] table; a SpecError it raises carries
    ``entry = ("conditions", index)`` (for the line of its key)."""
    try:
        return _condition_of(entry, index)
    except SpecError as exc:
        exc.entry = ("conditions", index)
        raise


def _condition_of(entry: Any, index: int) -> ConditionSpec:
    entry = _table(f"conditions[{index}]", entry)
    _unknown("conditions", entry, SCENE_KEYS["conditions"])
    if entry.get("type") in CONDITION_KEYS:
        _not_acting("conditions", set(entry) - {"end"},  # end: ConditionSpec's own message
                    CONDITION_KEYS[entry["type"]],
                    f"a {entry['type']} condition")
    component = entry.get("component")
    if component is not None:
        if isinstance(component, bool) or not isinstance(component, str | int) \
                or component not in _COMPONENTS:
            raise SpecError("conditions.component", f"must be x or y, got {component!r}")
        component = _COMPONENTS[component]
    return _within("conditions", lambda: ConditionSpec(
        type=entry.get("type"), boundary=entry.get("boundary"), component=component,
        value=entry.get("value"), end=entry.get("end"),
        displacement=entry.get("displacement"),
        rough=entry.get("rough", True)))


def _region_material(entry: Any, index: int) -> RegionMaterialSpec:
    """The ``index``-th [[materials]] table; a SpecError it raises carries
    ``entry = ("materials", index)`` (for the line of its key)."""
    try:
        entry = _table(f"materials[{index}]", entry)
        _unknown("materials", entry, SCENE_KEYS["materials"])
        if "region" not in entry:
            raise SpecError("materials.region", "each [[materials]] entry names its region")
        if "name" not in entry:
            raise SpecError("materials.name", "each [[materials]] entry names its material "
                                              "(e.g. \"linear-elastic\", \"mohr-coulomb\", "
                                              "\"dem\")")
        try:
            material = MaterialSpec(name=entry["name"], parameters=_table(
                "materials.parameters", entry.get("parameters")))
        except SpecError as exc:
            field_ = exc.field
            if field_ == "material":
                field_ = "materials.name"
            elif not field_.startswith("materials."):
                field_ = f"materials.parameters.{field_}"
            raise SpecError(field_, exc.message) from None
        return RegionMaterialSpec(region=entry["region"], material=material,
                                  unit_weight=entry.get("unit_weight"), k0=entry.get("k0"))
    except SpecError as exc:
        exc.entry = ("materials", index)
        raise


def _mesh(table: dict[str, Any], folder: Path) -> MeshSpec:
    table = _snake_case("mesh", table)
    _unknown("mesh", table, SCENE_KEYS["mesh"])
    if "file" in table:
        _not_acting("mesh", table, SCENE_KEYS["mesh"] - _GENERATED_KEYS, "a mesh file")
    values = dict(table)
    file = values.get("file")
    if isinstance(file, str) and file:
        path = Path(file) if Path(file).is_absolute() else folder / file
        if path.is_dir():
            raise SpecError("mesh.file", f"{path} is a folder, not a mesh file")
        if not path.is_file():
            raise SpecError("mesh.file", f"{path} does not exist")
        values["file"] = path
    return _within("mesh", lambda: MeshSpec(**values))


def _snake_case(section: str, table: dict[str, Any]) -> dict[str, Any]:
    """``table`` with its kebab-case keys of old (``align-x``) read as their snake_case ones,
    each with a :class:`~granular_material.vocabulary.RenamedWarning`; both given: a
    SpecError."""
    out: dict[str, Any] = {}
    for key, value in table.items():
        new = key_of(key)
        if new != key:
            if new in table:
                raise SpecError(f"{section}.{new}", f"is given twice: as {new!r} and as {key!r} "
                                                    f"(its old spelling); give {new!r} only")
            warnings.warn(f"[{section}] key '{key}' is deprecated: it is spelled '{new}' now "
                          "(scene keys are snake_case; the kebab-case spelling is read until "
                          "the next release)", RenamedWarning, stacklevel=user_stacklevel())
        out[new] = value
    return out


def _initial(table: dict[str, Any]) -> InitialStateSpec:
    _unknown("initial", table, SCENE_KEYS["initial"])
    if isinstance(table.get("k0"), Mapping):
        raise SpecError("initial.k0", "is one number; a K0 per region is given in each "
                                      "region's [[materials]] entry (k0 = 0.6 beside its "
                                      "unit_weight), not as a table in [initial]")
    state = table.get("state", "uniform")
    if state in INITIAL_KEYS:
        _not_acting("initial", table, INITIAL_KEYS[state], f"a {state} initial state")
    return _within("initial", lambda: InitialStateSpec(**table))


#: the keys of a boundary-value scene, by table ("": the top level; [newton] takes
#: NewtonSpec's fields, [material.parameters] the material's own, [boundaries] free names)
SCENE_KEYS: dict[str, frozenset[str]] = {
    "": frozenset({"test", "steps", "name", "out", "mesh", "boundaries", "conditions",
                   "gravity", "initial", "material", "regions", "materials", "newton",
                   "output", "regularisation", "phases", "strength_reduction",
                   "adaptivity"}),
    "mesh": frozenset({"file", "size", "elements", "element", "grading", "quadrature",
                       "align_x", "align_y"}),
    "conditions": frozenset({"type", "boundary", "component", "value", "end", "displacement",
                             "rough"}),
    "gravity": frozenset({"unit_weight", "factor"}),
    "initial": frozenset({"state", "pressure", "k0", "surcharge", "surface",
                          "minimum_pressure", "strength_fraction"}),
    "material": frozenset({"name", "parameters"}),
    "materials": frozenset({"region", "name", "parameters", "unit_weight", "k0"}),
    "regularisation": frozenset({"model", "internal_length"}),
    "strength_reduction": frozenset({"factor_end", "steps"}),
    "adaptivity": frozenset({"mobilised_fraction", "shear_strain", "neighbours", "start",
                             "switch", "calibration", "elastic_window"}),
    "output": frozenset({"out", "device", "shards", "progress", "fields", "points_csv",
                         "figures"}),
    "phases": frozenset({"name", "steps", "conditions", "gravity", "reset_displacements"}),
    "phases.gravity": frozenset({"factor"}),
}
_SCENE_KEYS = SCENE_KEYS[""]
_OUTPUT_KEYS = SCENE_KEYS["output"]


def _adaptivity(table: dict[str, Any], folder: Path) -> AdaptivitySpec:
    """The [adaptivity] table: a threshold named alone is the only one (the mobilised
    fraction's default applies when neither is named); a calibration file relative to
    ``folder`` must exist."""
    _unknown("adaptivity", table, SCENE_KEYS["adaptivity"])
    table = dict(table)
    if "shear_strain" in table and "mobilised_fraction" not in table:
        table["mobilised_fraction"] = None
    calibration = table.get("calibration")
    if calibration is not None:
        if not isinstance(calibration, str):
            raise SpecError("adaptivity.calibration", f"must be the path of a "
                                                      f"calibration.json, got {calibration!r}")
        path = folder / calibration
        if not path.is_file():
            raise SpecError("adaptivity.calibration", f"{path} is no file (a calibration.json "
                                                      "written by granular-material "
                                                      "calibrate)")
        table["calibration"] = path
    return _within("adaptivity", lambda: AdaptivitySpec(**table))


def bvp_from_dict(data: Mapping[str, Any], folder: Path | str = ".") -> BoundaryValueSpec:
    """The spec of a boundary-value scene (a TOML file's table); paths are relative to
    ``folder``. Every key is checked; a refusal is a SpecError naming it."""
    if not isinstance(data, Mapping):
        raise SpecError("scene", f"must be a table of keys (a TOML file's), got "
                                 f"{type(data).__name__}")
    folder = Path(folder)
    data = dict(data)
    _unknown("", data, _SCENE_KEYS)
    if data.get("test") != "boundary-value":
        raise SpecError("test", f'must be "boundary-value", got {data.get("test")!r}')
    boundaries = _table("boundaries", data.get("boundaries"))
    for name, predicate in boundaries.items():
        if not isinstance(predicate, str):
            raise SpecError(f"boundaries.{name}", f"must be a predicate or a physical "
                                                  f"group's name, got {predicate!r}")
    conditions = data.get("conditions", [])
    if not isinstance(conditions, list):
        raise SpecError("conditions", "must be an array of tables ([[conditions]])")
    gravity = _table("gravity", data.get("gravity"))
    _unknown("gravity", gravity, SCENE_KEYS["gravity"])
    phases = _phases(data, gravity)
    material = _table("material", data.get("material"))
    _unknown("material", material, SCENE_KEYS["material"])
    regions = data.get("regions")
    if regions is not None:
        regions = _table("regions", regions)
        for name, value in regions.items():
            if not isinstance(value, str) or not value.strip():
                raise SpecError(f"regions.{name}", f"must be a predicate (e.g. \"y >= 0.2\") "
                                                   f"or a physical group's name, got {value!r}")
    materials = data.get("materials")
    if materials is not None:
        if not isinstance(materials, list):
            raise SpecError("materials", "must be an array of tables ([[materials]])")
        if "material" in data:
            raise SpecError("material", "is given beside [[materials]]: give either one "
                                        "[material] or a material per region")
        materials = tuple(_region_material(m, k) for k, m in enumerate(materials))
    newton = _table("newton", data.get("newton"))
    regularisation = _table("regularisation", data.get("regularisation"))
    _unknown("regularisation", regularisation, SCENE_KEYS["regularisation"])
    reduction = data.get("strength_reduction")
    if reduction is not None:
        reduction = _table("strength_reduction", reduction)
        _unknown("strength_reduction", reduction, SCENE_KEYS["strength_reduction"])
        reduction = _within("strength_reduction", lambda: StrengthReductionSpec(**reduction))
    adaptivity = data.get("adaptivity")
    if adaptivity is not None:
        adaptivity = _adaptivity(_table("adaptivity", adaptivity), folder)
    output = _table("output", data.get("output"))
    _unknown("output", output, _OUTPUT_KEYS)
    if "out" in output and "out" in data:
        raise SpecError("out", "is given twice, at the top and in [output]: give one (the "
                               "other would be ignored)")
    try:
        newton_spec = NewtonSpec(**newton)
    except TypeError as exc:
        raise SpecError("newton", str(exc)) from None
    sections = {
        "mesh": _mesh(_table("mesh", data.get("mesh")), folder),
        "conditions": tuple(_condition(c, i) for i, c in enumerate(conditions)),
        "initial": _initial(_table("initial", data.get("initial"))),
        "material": MaterialSpec(name=material.get("name", "linear-elastic"),
                                 parameters=_table("material.parameters",
                                                   material.get("parameters"))),
    }
    try:
        return BoundaryValueSpec(
            **sections, boundaries={str(k): v for k, v in boundaries.items()},
            regions=None if regions is None else {str(k): v for k, v in regions.items()},
            materials=materials,
            unit_weight=gravity.get("unit_weight", 0.0),
            gravity_factor=gravity.get("factor"),
            steps=data.get("steps", sum(p.steps for p in phases) if phases else 10),
            newton=newton_spec, out=output.get("out", data.get("out")),
            regularisation=_within("regularisation",
                                   lambda: RegularisationSpec(**regularisation)),
            device=output.get("device"), shards=output.get("shards"),
            progress=output.get("progress", False), fields=output.get("fields", True),
            points_csv=output.get("points_csv", False), figures=output.get("figures", True),
            name=data.get("name", "problem"), phases=phases, strength_reduction=reduction,
            adaptivity=adaptivity)
    except SpecError as exc:
        if exc.field in _OUTPUT_KEYS:  # the [output] table's, named within it
            raise SpecError(f"output.{exc.field}", exc.message) from None
        raise


def _check_phases(spec: BoundaryValueSpec) -> None:
    """SpecError naming what is wrong with the phases of ``spec`` (each phase's own fields
    are checked by :class:`PhaseSpec`); ``steps`` made their sum."""
    phases = spec.phases
    if isinstance(phases, str | bytes | Mapping) or not isinstance(phases, Iterable):
        raise SpecError("phases", f"must be a sequence of PhaseSpec, got "
                                  f"{type(phases).__name__}")
    phases = tuple(phases)
    for k, p in enumerate(phases):
        if not isinstance(p, PhaseSpec):
            raise SpecError("phases", f"must be PhaseSpec objects; phase {k} is a "
                                      f"{type(p).__name__} (a scene's tables are read by "
                                      "bvp_from_dict)")
    object.__setattr__(spec, "phases", phases)
    names = [p.name for p in phases]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise SpecError("phases.name", f"{twice[0]!r} names two phases: give each its own")
    total = sum(p.steps for p in phases)
    if spec.steps not in (10, total):  # 10: the field's default, not given
        raise SpecError("steps", "a phased problem's steps are its phases' (each phase's "
                                 "steps), so the problem's own is refused")
    object.__setattr__(spec, "steps", total)
    if spec.newton.continuation == "arc-length":
        raise SpecError("newton.continuation", "arc-length continuation takes as many steps "
                                               "as its path needs, and a phase as many as "
                                               "it gives, so the two are refused together "
                                               "(run the phase to collapse as a scene of its "
                                               "own)")
    if spec.gravity_factor is not None:
        raise SpecError("gravity.factor", "a phased problem gives each phase its own gravity "
                                          "factor ([phases.gravity] factor), so [gravity]'s "
                                          "is refused")
    for c in spec.conditions:
        if c.type == "pressure" and c.end is not None:
            raise SpecError("conditions.end", "a condition common to every phase is constant; "
                                              "a load that changes belongs to a phase's "
                                              "[[phases.conditions]]")
    weighted = spec.unit_weight != 0.0 or any(m.unit_weight not in (None, 0.0)
                                              for m in spec.materials or ())
    for k, p in enumerate(phases):
        where = f"phase {k + 1} ({p.name!r})"
        if p.gravity_factor is not None and not weighted:
            raise SpecError("phases.gravity.factor", f"of {where} multiplies a unit weight of "
                                                     "0 N/m³, so it does nothing and is "
                                                     "refused (set gravity.unit_weight)")
        if k == 0 and p.reset_displacements:
            raise SpecError("phases.reset_displacements", f"of {where}: the first phase "
                                                          "starts from zero displacement, so "
                                                          "a reset there does nothing and is "
                                                          "refused")
        if k > 0 and isinstance(p.gravity_factor, tuple):
            raise SpecError("phases.gravity.factor", f"of {where}: a later phase's gravity "
                                                     "starts where the phase before ended; "
                                                     "give its factor at the phase's end (a "
                                                     "number)")
        for c in p.conditions:
            if k > 0 and c.type == "pressure" and c.end is not None:
                raise SpecError("phases.conditions.end", f"of {where}: a later phase's "
                                                         "pressure starts from what acted at "
                                                         "the end of the phase before; give "
                                                         "its total at this phase's end as "
                                                         "value")
        if not spec.conditions and not p.conditions:
            raise SpecError("phases.conditions", f"{where} has no condition (and the problem "
                                                 "has no common [[conditions]])")
        if spec.mesh.file is None:
            missing = sorted({c.boundary for c in p.conditions} - set(spec.boundaries)
                             - _GENERATED_SIDES)
            if missing:
                raise SpecError("phases.conditions.boundary",
                                f"{missing[0]!r} of {where} is no boundary of [boundaries] "
                                "nor a side of the mesh")


def _phases(data: Mapping[str, Any], gravity: Mapping[str, Any]) -> tuple[PhaseSpec, ...]:
    """The [[phases]] of a scene's table ``data`` (() where it has none); the scene's own
    ``steps`` and [gravity] ``factor`` beside them are refused."""
    phases = data.get("phases")
    if phases is None:
        return ()
    if not isinstance(phases, list) or not phases:
        raise SpecError("phases", "must be an array of tables ([[phases]]), at least one")
    if "steps" in data:
        raise SpecError("steps", "a phased scene gives each phase its steps ([[phases]] "
                                 "steps), so the scene's own is refused")
    if "factor" in gravity:
        raise SpecError("gravity.factor", "a phased scene gives each phase its own gravity "
                                          "factor ([phases.gravity] factor), so [gravity]'s "
                                          "is refused")
    return tuple(_phase(p, k) for k, p in enumerate(phases))


def _phase(entry: Any, index: int) -> PhaseSpec:
    """The ``index``-th [[phases]] table; a SpecError it raises carries
    ``entry = ("phases", index)`` (for the line of its key)."""
    try:
        entry = _table(f"phases[{index}]", entry)
        _unknown("phases", entry, SCENE_KEYS["phases"])
        for key in ("name", "steps"):
            if key not in entry:
                raise SpecError(f"phases.{key}", f"each [[phases]] entry gives its {key}")
        gravity = _table("phases.gravity", entry.get("gravity"))
        _unknown("phases.gravity", gravity, SCENE_KEYS["phases.gravity"])
        conditions = entry.get("conditions", [])
        if not isinstance(conditions, list):
            raise SpecError("phases.conditions", "must be an array of tables "
                                                 "([[phases.conditions]])")
        own = []
        for k, c in enumerate(conditions):
            try:
                own.append(_condition_of(c, k))
            except SpecError as exc:
                raise SpecError(f"phases.{exc.field}", exc.message) from None
        return PhaseSpec(name=entry["name"], steps=entry["steps"], conditions=tuple(own),
                         gravity_factor=gravity.get("factor"),
                         reset_displacements=entry.get("reset_displacements", False))
    except SpecError as exc:
        exc.entry = ("phases", index)
        raise
