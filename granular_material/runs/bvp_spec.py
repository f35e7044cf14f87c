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
    align-x = [0.05]                # move the nearest grid line onto these x [m] (a footing's edge)
    quadrature = 3                  # optional: Gauss points (per direction for quads)

    [boundaries]                    # name = predicate, or a physical group of the file
    footing = "y = top and x <= 0.05"

    [[conditions]]                  # fixed | roller | displacement | rigid | pressure
    type = "rigid"
    boundary = "footing"
    displacement = [0.0, -0.0145]   # [m] at the last step
    rough = true

    [gravity]
    unit_weight = 0.0               # [N/m³]; "rve": from the RVEs' grain density and e

    [initial]
    state = "uniform"               # or "geostatic"
    pressure = 20e3                 # uniform: isotropic stress [Pa], compression positive
    # geostatic: sigma_v = surcharge + unit_weight * depth, sigma_h = k0 * sigma_v
    # k0 = 0.5, surcharge = 20e3, surface = 0.4 (default: the top of the mesh)

    [material]                      # as a run specification's: name and parameters
    name = "mohr-coulomb"
    [material.parameters]
    phi = 30.0

    [newton]                        # NewtonSpec's fields
    [output]                        # out, device, shards, progress, fields
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from granular_material.runs.spec import MaterialSpec, NewtonSpec, SpecError

__all__ = ["CONDITION_TYPES", "INITIAL_STATES", "BoundaryValueSpec", "ConditionSpec",
           "InitialStateSpec", "MeshSpec", "bvp_from_dict"]

#: the conditions a boundary may carry
CONDITION_TYPES = ("fixed", "roller", "displacement", "rigid", "pressure")
#: the initial states of a problem
INITIAL_STATES = ("uniform", "geostatic")
#: the components by name
_COMPONENTS = {"x": 0, "y": 1, 0: 0, 1: 1}
_ELEMENTS = ("tri3", "tri6", "quad4", "quad8", "quad9")


def _number(name: str, value: Any, *, positive: bool = False, at_least: float | None = None,
            ) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SpecError(name, f"must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise SpecError(name, f"must be finite, got {value!r}")
    if positive and value <= 0:
        raise SpecError(name, f"must be > 0, got {value:g}")
    if at_least is not None and value < at_least:
        raise SpecError(name, f"must be >= {at_least:g}, got {value:g}")
    return value


def _pair(name: str, value: Any, kind: type = float) -> tuple:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise SpecError(name, f"must be a pair [a, b], got {value!r}")
    if kind is int:
        if any(isinstance(v, bool) or not isinstance(v, int) or v < 1 for v in value):
            raise SpecError(name, f"must be two integers >= 1, got {value!r}")
        return tuple(int(v) for v in value)
    return tuple(_number(name, v) for v in value)


def _table(name: str, value: Any) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise SpecError(name, f"must be a table, got {value!r}")
    return dict(value)


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
        if (self.file is not None) and (self.align_x or self.align_y):
            raise SpecError("mesh.align-x", "aligns a generated mesh's grid lines; a mesh "
                                            "file has its own nodes")
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
            current length, constant through the run).
        boundary: the boundary's name.
        component: 0 (x) or 1 (y), for roller and displacement.
        value: the end displacement [m] or the pressure [Pa].
        displacement: (dx, dy) [m] of a rigid body at the end.
        rough: a rigid body's nodes keep both components tied (True) or slide (False).
    """

    type: str
    boundary: str
    component: int | None = None
    value: float | None = None
    displacement: tuple[float, float] | None = None
    rough: bool = True

    def __post_init__(self) -> None:
        if self.type not in CONDITION_TYPES:
            raise SpecError("conditions.type", f"must be one of {', '.join(CONDITION_TYPES)}, "
                                               f"got {self.type!r}")
        if self.type in ("roller", "displacement") and self.component not in (0, 1):
            raise SpecError("conditions.component", f"a {self.type} needs component x or y")
        if self.type in ("displacement", "pressure") and self.value is None:
            raise SpecError("conditions.value", f"a {self.type} needs a value")
        if self.type == "pressure" and self.value is not None and self.value < 0:
            raise SpecError("conditions.value", f"a pressure is compression positive, >= 0 "
                                                f"Pa, got {self.value:g}")
        if self.type == "rigid" and self.displacement is None:
            raise SpecError("conditions.displacement", "a rigid body needs displacement "
                                                       "[dx, dy] [m]")


@dataclass(frozen=True, kw_only=True)
class InitialStateSpec:
    """The stress every Gauss point starts from (compression positive here).

    Attributes:
        state: "uniform" (isotropic ``pressure`` [Pa]) or "geostatic" (σv = surcharge +
            γ·(surface − y), σh = k0·σv, γ the problem's unit weight).
        pressure: the uniform state's pressure [Pa], > 0.
        k0: the geostatic ratio σh/σv [-], > 0.
        surcharge: the stress on the surface [Pa], >= 0.
        surface: y of the free surface [m]; None: the top of the mesh.
    """

    state: str = "uniform"
    pressure: float | None = None
    k0: float = 0.5
    surcharge: float = 0.0
    surface: float | None = None

    def __post_init__(self) -> None:
        if self.state not in INITIAL_STATES:
            raise SpecError("initial.state", f"must be one of {', '.join(INITIAL_STATES)}, "
                                             f"got {self.state!r}")
        if self.state == "uniform" and (self.pressure is None or self.pressure <= 0):
            raise SpecError("initial.pressure", "a uniform initial state needs a pressure "
                                                f"> 0 Pa, got {self.pressure!r}")
        if self.k0 <= 0:
            raise SpecError("initial.k0", f"must be > 0, got {self.k0:g}")
        if self.surcharge < 0:
            raise SpecError("initial.surcharge", f"must be >= 0 Pa, got {self.surcharge:g}")

    @property
    def reference_pressure(self) -> float:
        """A representative pressure [Pa] (for the material's and Newton's scales): the
        uniform pressure, else the surcharge (or 1 kPa where there is none)."""
        if self.state == "uniform":
            return float(self.pressure)
        return float(self.surcharge) if self.surcharge > 0 else 1e3


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
        initial: the initial state.
        steps: load steps.
        material: the material (as in a run specification).
        newton: the Newton solver.
        out: the run folder (None: nothing written).
        device: the DEM device ("cpu", "cuda", "cuda:N"; None: CUDA where present); shards:
            CPU shards; progress: progress bars.
        fields: write the ParaView fields (fields.xdmf) at every committed step.
        name: the problem's name (tables and figures).
    """

    mesh: MeshSpec
    boundaries: dict[str, str] = field(default_factory=dict)
    conditions: tuple[ConditionSpec, ...] = ()
    unit_weight: float | str = 0.0
    initial: InitialStateSpec = field(default_factory=lambda: InitialStateSpec(
        pressure=100e3))
    steps: int = 10
    material: MaterialSpec = field(default_factory=lambda: MaterialSpec(name="linear-elastic"))
    newton: NewtonSpec = field(default_factory=NewtonSpec)
    out: Path | None = None
    device: str | None = None
    shards: int | None = None
    progress: bool = False
    fields: bool = True
    name: str = "problem"

    def __post_init__(self) -> None:
        if isinstance(self.steps, bool) or not isinstance(self.steps, int) or self.steps < 1:
            raise SpecError("steps", f"must be an integer >= 1, got {self.steps!r}")
        if not self.conditions:
            raise SpecError("conditions", "a problem needs at least one condition")
        named = {c.boundary for c in self.conditions}
        missing = sorted(named - set(self.boundaries) - _GENERATED_SIDES
                         if self.mesh.file is None else set())
        if missing:
            raise SpecError("conditions.boundary", f"{missing[0]!r} is no boundary of "
                                                   "[boundaries] nor a side of the mesh")
        if self.unit_weight != "rve":
            _number("gravity.unit_weight", self.unit_weight, at_least=0.0)

    @property
    def reference_pressure(self) -> float:
        """The problem's representative pressure [Pa] (see :class:`InitialStateSpec`)."""
        return self.initial.reference_pressure


#: the sides every generated rectangle names
_GENERATED_SIDES = frozenset({"left", "right", "bottom", "top"})


def _condition(entry: Any, index: int) -> ConditionSpec:
    entry = _table(f"conditions[{index}]", entry)
    _unknown("conditions", entry, {"type", "boundary", "component", "value", "displacement",
                                   "rough"})
    component = entry.get("component")
    if component is not None:
        if component not in _COMPONENTS:
            raise SpecError("conditions.component", f"must be x or y, got {component!r}")
        component = _COMPONENTS[component]
    value = entry.get("value")
    if value is not None:
        value = _number("conditions.value", value)
    displacement = entry.get("displacement")
    if displacement is not None:
        displacement = _pair("conditions.displacement", displacement)
    rough = entry.get("rough", True)
    if not isinstance(rough, bool):
        raise SpecError("conditions.rough", f"must be true or false, got {rough!r}")
    if not isinstance(entry.get("boundary"), str):
        raise SpecError("conditions.boundary", f"must name a boundary, got "
                                               f"{entry.get('boundary')!r}")
    return ConditionSpec(type=str(entry.get("type")), boundary=entry["boundary"],
                         component=component, value=value, displacement=displacement,
                         rough=rough)


def _mesh(table: dict[str, Any], folder: Path) -> MeshSpec:
    _unknown("mesh", table, {"file", "size", "elements", "element", "grading", "quadrature",
                             "align-x", "align-y"})
    align = {}
    for key in ("align-x", "align-y"):
        values = table.get(key, [])
        if not isinstance(values, list):
            raise SpecError(f"mesh.{key}", f"must be a list of coordinates [m], got {values!r}")
        align[key.replace("-", "_")] = tuple(_number(f"mesh.{key}", v) for v in values)
    file = table.get("file")
    if file is not None:
        if not isinstance(file, str):
            raise SpecError("mesh.file", f"must be a path, got {file!r}")
        file = (folder / file) if not Path(file).is_absolute() else Path(file)
        if not file.is_file():
            raise SpecError("mesh.file", f"{file} does not exist")
    size = table.get("size")
    elements = table.get("elements")
    return MeshSpec(
        file=file, size=None if size is None else _pair("mesh.size", size),
        elements=None if elements is None else _pair("mesh.elements", elements, int),
        element=str(table.get("element", "quad4")),
        grading=(None if table.get("grading") is None
                 else _pair("mesh.grading", table["grading"])),
        quadrature=table.get("quadrature"), **align)


def _initial(table: dict[str, Any]) -> InitialStateSpec:
    _unknown("initial", table, {"state", "pressure", "k0", "surcharge", "surface"})
    numbers = {k: _number(f"initial.{k}", table[k])
               for k in ("pressure", "k0", "surcharge", "surface") if k in table}
    return InitialStateSpec(state=str(table.get("state", "uniform")), **numbers)


_SCENE_KEYS = {"test", "steps", "name", "out", "mesh", "boundaries", "conditions", "gravity",
               "initial", "material", "newton", "output"}
_OUTPUT_KEYS = {"out", "device", "shards", "progress", "fields"}


def bvp_from_dict(data: Mapping[str, Any], folder: Path | str = ".") -> BoundaryValueSpec:
    """The spec of a boundary-value scene (a TOML file's table); paths are relative to
    ``folder``. Every key is checked; a refusal is a SpecError naming it."""
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
    _unknown("gravity", gravity, {"unit_weight"})
    material = _table("material", data.get("material"))
    _unknown("material", material, {"name", "parameters"})
    newton = _table("newton", data.get("newton"))
    output = _table("output", data.get("output"))
    _unknown("output", output, _OUTPUT_KEYS)
    try:
        newton_spec = NewtonSpec(**newton)
    except TypeError as exc:
        raise SpecError("newton", str(exc)) from None
    out = output.get("out", data.get("out"))
    shards = output.get("shards")
    if shards is not None and (isinstance(shards, bool) or not isinstance(shards, int)
                               or shards < 1):
        raise SpecError("output.shards", f"must be an integer >= 1, got {shards!r}")
    device = output.get("device")
    if device is not None and not isinstance(device, str):
        raise SpecError("output.device", f"must be a device name, got {device!r}")
    return BoundaryValueSpec(
        mesh=_mesh(_table("mesh", data.get("mesh")), folder),
        boundaries={str(k): v for k, v in boundaries.items()},
        conditions=tuple(_condition(c, i) for i, c in enumerate(conditions)),
        unit_weight=gravity.get("unit_weight", 0.0),
        initial=_initial(_table("initial", data.get("initial"))),
        steps=data.get("steps", 10),
        material=MaterialSpec(name=str(material.get("name", "linear-elastic")),
                              parameters=_table("material.parameters",
                                                material.get("parameters"))),
        newton=newton_spec,
        out=None if out is None else Path(out),
        device=device, shards=shards, progress=bool(output.get("progress", False)),
        fields=bool(output.get("fields", True)),
        name=str(data.get("name", "problem")),
    )
