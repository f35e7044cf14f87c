"""Materials by region: one material per region of the mesh, answering the protocol as one.

:class:`RegionalMaterial` holds a material for every region (a layer of clay, a sand fill, a
DEM zone) and the region of every Gauss point. ``evaluate(∇u)`` splits ∇u by region, asks each
material for its own points, and puts the answers back in the points' order:

- stress, tangent, status and reasons: each point's from the material of its region;
- fields: every name any region's material reports; a point whose material does not report
  a field holds NaN there (e.g. ``plastic_shear_strain`` in a linear-elastic layer);
- costs and timings: summed over the regions, by name (a cost that is a count over the
  points, such as the DEM's ``dem_steps``, is then the whole mesh's; Mohr–Coulomb's
  ``return_iterations``, the iterations of its vectorised return, becomes the sum of the
  regions' counts).

``commit``, ``revert`` and ``hold_tangent`` are passed to every region's material (``commit``
region by region: a material that refuses its commit, as Mohr–Coulomb does after a failed
evaluation, stops it there; the Newton driver commits only a converged evaluation).
``noisy`` is True when any region's material is noisy (a DEM region), so the Newton driver
and the runs use the looser defaults of noisy materials. ``checkpoint(path)`` writes one
``.npz`` file holding every region's own checkpoint (as bytes), the regions' names and the
region of every point; ``restore(path)`` gives each material back its own, so a resumed run
is the run that was stopped.

Each point belongs to exactly one region. :meth:`RegionalMaterial.from_elements` builds the
point regions from element sets (a mesh's ``MeshData.subdomains``, gmsh's physical groups of
cells); an element in no region or in two, a region without a material and a material without
points are refused with a :class:`~granular_material.errors.ParameterError` naming them.
Points are batch-first: point ``p`` of a mesh is ``element * nqp + q``
(:mod:`granular_material.fem.layout`).

In a scikit-fem script::

    layers = RegionalMaterial.from_elements(
        {"clay": MohrCoulomb(cohesion=20e3, friction_angle=5.0, initial_stress=-50e3),
         "sand": LinearElastic(young=80e6, initial_stress=-50e3)},
        mesh_data.subdomains, n_elements=basis.nelems, nqp=basis.X.shape[-1])
    solver = NewtonSolver(basis, layers, loading)
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from granular_material.errors import ParameterError
from granular_material.fem.materials.checks import (
    CHECKPOINT_NAME_KEY,
    check_grad,
    checkpoint_archive,
)
from granular_material.fem.materials.mohr_coulomb_parameters import number
from granular_material.fem.materials.protocol import (
    FailureReason,
    Material,
    MaterialResponse,
    ScikitFemInterface,
)
from granular_material.filesafe import write_whole

__all__ = ["RegionalMaterial", "point_regions"]

#: the name a regional material's checkpoint carries
_NAME = "regions"
#: the prefix of a region's checkpoint bytes in the regional checkpoint
_STATE = "state_"


def point_regions(elements: Mapping[str, Any], n_elements: int, nqp: int) -> np.ndarray:
    """The region of every Gauss point, shape (n_elements · nqp,), str: ``elements`` maps a
    region's name to its element indices; point ``p = element · nqp + q`` is in its
    element's region. ParameterError (field ``regions``) for an element in no region or in
    two, an index outside the mesh, or a region with no element, naming them."""
    n_elements, nqp = int(n_elements), int(nqp)
    if n_elements < 1 or nqp < 1:
        raise ParameterError("regions", f"need n_elements >= 1 and nqp >= 1, got "
                                        f"{n_elements} and {nqp}")
    owner = np.full(n_elements, -1, dtype=np.int64)
    names = [str(name) for name in elements]
    for k, (name, index) in enumerate(elements.items()):
        index = np.asarray(index)
        if index.dtype.kind not in "iu" or index.ndim != 1:
            raise ParameterError("regions", f"region {name!r} must be a 1-D array of element "
                                            f"indices, got {index.dtype} of shape "
                                            f"{index.shape}")
        if index.size == 0:
            raise ParameterError("regions", f"region {name!r} holds no element")
        outside = index[(index < 0) | (index >= n_elements)]
        if outside.size:
            raise ParameterError("regions", f"region {name!r} names element "
                                            f"{int(outside[0])}; the mesh has elements 0 to "
                                            f"{n_elements - 1}")
        twice = index[owner[index] >= 0]
        if twice.size:
            e = int(twice[0])
            raise ParameterError("regions", f"element {e} lies in two regions, "
                                            f"{names[owner[e]]!r} and {name!r} ({twice.size} "
                                            f"elements do): every element belongs to one")
        owner[index] = k
    none = np.flatnonzero(owner < 0)
    if none.size:
        raise ParameterError("regions", f"{none.size} of {n_elements} elements lie in no "
                                        f"region (first {none[:8].tolist()}): every element "
                                        f"belongs to one of {', '.join(map(repr, names))}")
    labels = np.array(names, dtype=object)[owner]
    return np.repeat(labels, nqp)


class RegionalMaterial(ScikitFemInterface):
    """One material per region, answering the :class:`Material` protocol as one material
    (see the module docstring for how the answers are put together).

    Args:
        materials: region name → material (any :class:`Material`, allocated for its own
            points or not yet allocated: :meth:`allocate` allocates those that are not).
        regions: the region name of every Gauss point, shape (n,), batch-first
            (:func:`point_regions` makes it from element sets).

    ParameterError naming ``regions`` for a point in no region ("" or None) or in a region
    without a material (its first point named), naming ``materials`` for a material whose
    region holds no point or an object that is not a material.
    """

    def __init__(self, materials: Mapping[str, Material], regions: Sequence[str] | np.ndarray
                 ) -> None:
        if not isinstance(materials, Mapping) or not materials:
            raise ParameterError("materials", "must map at least one region's name to its "
                                              f"material, got {materials!r}"[:200])
        for name, material in materials.items():
            if not isinstance(material, Material):
                raise ParameterError("materials", f"region {name!r}: {type(material).__name__}"
                                                  " does not implement the Material protocol")
        labels = np.asarray(regions, dtype=object).reshape(-1)
        if labels.size == 0:
            raise ParameterError("regions", "must name the region of every Gauss point, "
                                            "got none")
        names = tuple(str(name) for name in materials)
        unnamed = np.flatnonzero([r is None or str(r) == "" for r in labels])
        if unnamed.size:
            raise ParameterError("regions", f"{unnamed.size} of {labels.size} points lie in no "
                                            f"region (first point {int(unnamed[0])}): every "
                                            "point belongs to one")
        labels = np.array([str(r) for r in labels], dtype=object)
        known = np.isin(labels, np.array(names, dtype=object))
        if not known.all():
            p = int(np.flatnonzero(~known)[0])
            raise ParameterError("regions", f"point {p} lies in region {labels[p]!r}, which has "
                                            f"no material (materials are given for "
                                            f"{', '.join(map(repr, names))})")
        self._materials = dict(zip(names, materials.values(), strict=True))
        self._labels = labels
        self._index = {name: np.flatnonzero(labels == name) for name in names}
        empty = [name for name, index in self._index.items() if index.size == 0]
        if empty:
            raise ParameterError("materials", f"region {empty[0]!r} holds no Gauss point, so "
                                              "its material would do nothing")
        self._last: MaterialResponse | None = None

    @classmethod
    def from_elements(cls, materials: Mapping[str, Material], elements: Mapping[str, Any],
                      n_elements: int, nqp: int) -> RegionalMaterial:
        """The regional material of a mesh whose regions are element sets (``elements``:
        name → element indices, e.g. ``MeshData.subdomains``), ``nqp`` Gauss points an
        element. The sets the materials name must cover every element once
        (:func:`point_regions`); other sets (a file's group of the whole body) are not used.
        A material whose region is no set is refused."""
        missing = [name for name in materials if name not in elements]
        if missing:
            raise ParameterError("materials", f"region {missing[0]!r} is not one of the "
                                              f"element sets ({', '.join(map(repr, elements))})")
        used = {name: elements[name] for name in materials}
        return cls(materials, point_regions(used, n_elements, nqp))

    # -- what it holds -------------------------------------------------------------------
    @property
    def materials(self) -> dict[str, Material]:
        """Region name → material (the materials themselves, not copies)."""
        return dict(self._materials)

    @property
    def regions(self) -> np.ndarray:
        """The region name of every Gauss point, shape (n,), str (a copy)."""
        return self._labels.copy()

    @property
    def region_names(self) -> tuple[str, ...]:
        """The regions' names, in the order the materials were given."""
        return tuple(self._materials)

    def points_of(self, region: str) -> np.ndarray:
        """The Gauss points of ``region``, ascending indices (a copy); KeyError otherwise."""
        return self._index[region].copy()

    @property
    def noisy(self) -> bool:
        """True when any region's material is noisy (its stress carries noise: DEM RVEs)."""
        return any(bool(getattr(m, "noisy", False)) for m in self._materials.values())

    @property
    def n_points(self) -> int:
        """Number of Gauss points once every region's material is allocated for its own
        points (0 before)."""
        ready = all(m.n_points == self._index[name].size
                    for name, m in self._materials.items())
        return int(self._labels.size) if ready else 0

    # -- protocol ------------------------------------------------------------------------
    def allocate(self, n_points: int) -> None:
        """Allocate every region's material that is not yet allocated for its own points;
        ParameterError naming ``n_points`` when it is not the number of points the regions
        were given for, or a material already holds another number of points."""
        if isinstance(n_points, bool) or not isinstance(n_points, int | np.integer) \
                or int(n_points) != self._labels.size:
            raise ParameterError("n_points", f"must be the {self._labels.size} points the "
                                             f"regions were given for, got {n_points!r}")
        for name, material in self._materials.items():
            count = int(self._index[name].size)
            if material.n_points == 0:
                material.allocate(count)
            elif material.n_points != count:
                raise ParameterError("n_points", f"region {name!r}'s material holds "
                                                 f"{material.n_points} points; the region "
                                                 f"has {count}")
        self._track_allocate(int(n_points))
        self._last = None

    def evaluate(self, grad_u: np.ndarray) -> MaterialResponse:
        """σ [Pa] (n, 2, 2), D [Pa] (n, 2, 2, 2, 2), status, reasons and fields at every
        point for ∇u [-] (n, 2, 2) since the last commit, each point answered by its
        region's material; costs and timings summed over the regions."""
        n = self.n_points
        grad = check_grad(grad_u, n)
        self._track_evaluate(grad)
        stress = np.empty((n, 2, 2))
        tangent = np.empty((n, 2, 2, 2, 2))
        status = np.empty(n, dtype=np.int8)
        reasons = np.full(n, FailureReason.NONE.value, dtype=object)
        answers: list[tuple[np.ndarray, MaterialResponse]] = []
        costs: dict[str, int | float] = {}
        timings: dict[str, float] = {}
        for name, material in self._materials.items():
            index = self._index[name]
            r = material.evaluate(grad[index])
            stress[index], tangent[index] = r.stress, r.tangent
            status[index], reasons[index] = r.status, r.reasons
            answers.append((index, r))
            for key, value in r.costs.items():
                costs[key] = costs.get(key, 0) + value
            for key, value in r.timings.items():
                timings[key] = timings.get(key, 0.0) + float(value)
        fields: dict[str, np.ndarray] = {}
        for index, r in answers:
            for key, values in r.fields.items():
                if key not in fields:
                    fields[key] = np.full(n, np.nan)
                fields[key][index] = np.asarray(values, dtype=np.float64).reshape(-1)
        response = MaterialResponse(stress=stress, tangent=tangent, status=status, costs=costs,
                                    fields=fields, reasons=reasons, timings=timings)
        self._last = response
        return response

    def commit(self) -> None:
        """Commit every region's material (in the order given; one that refuses stops the
        commit there, with its error)."""
        for material in self._materials.values():
            material.commit()
        last = self._last
        failed = None
        if last is not None:
            failed = np.zeros(self._labels.size, dtype=bool)
            failed[last.failed_points()] = True
        self._track_commit(failed)
        self._last = None

    def revert(self) -> None:
        """Revert every region's material."""
        for material in self._materials.values():
            material.revert()
        self._track_revert()
        self._last = None

    # -- strength reduction ----------------------------------------------------------------
    def _reducible(self) -> list[Material]:
        return [m for m in self._materials.values()
                if callable(getattr(m, "reduce_strength", None))]

    @property
    def strength_factor(self) -> float:
        """The strength reduction factor F [-] of the regions whose material can be
        reduced (the first such region's; :meth:`reduce_strength` sets them all alike), 1.0
        when none can."""
        reducible = self._reducible()
        return float(getattr(reducible[0], "strength_factor", 1.0)) if reducible else 1.0

    def reduce_strength(self, factor: float) -> None:
        """Divide the strength of every region whose material offers ``reduce_strength``
        (Mohr–Coulomb: c and tan φ) by ``factor`` F from the committed state; the other
        regions (linear-elastic, DEM) keep theirs. ParameterError naming ``factor`` for a
        factor that is not > 0 and finite, or when no region's material can be reduced
        (nothing would change)."""
        reducible = self._reducible()
        if not reducible:
            kinds = ", ".join(f"{name!r} ({type(m).__name__})"
                              for name, m in self._materials.items())
            raise ParameterError("factor", "no region's material can have its strength "
                                           f"reduced: {kinds}")
        factor = number("factor", factor)
        if not factor > 0:
            raise ParameterError("factor", "must be a strength reduction factor > 0, got "
                                           f"{factor!r}")
        for material in reducible:
            material.reduce_strength(factor)  # type: ignore[attr-defined]

    def hold_tangent(self, hold: bool) -> None:
        """Pass ``hold`` to every region's material that offers ``hold_tangent`` (the
        Newton driver's ``tangent_update="hold"``); the others are evaluated as always."""
        for material in self._materials.values():
            method = getattr(material, "hold_tangent", None)
            if callable(method):
                method(hold)

    def checkpoint(self, path: str | Path) -> None:
        """Write every region's committed state to ``path``: one ``.npz`` file holding each
        material's own checkpoint (bytes), the regions' names, the region of every point and
        the committed total ∇u; whole or not at all (a temporary file renamed)."""
        names = self.region_names
        arrays: dict[str, np.ndarray] = {
            CHECKPOINT_NAME_KEY: np.array(_NAME),
            "regions": np.array(names, dtype=str),
            "labels": np.array([names.index(r) for r in self._labels], dtype=np.int64),
            "grad_u": self.committed_grad_u}
        with tempfile.TemporaryDirectory(prefix="regions-") as folder:
            for k, material in enumerate(self._materials.values()):
                own = Path(folder) / f"region_{k}.npz"
                material.checkpoint(own)
                arrays[f"{_STATE}{k}"] = np.frombuffer(own.read_bytes(), dtype=np.uint8)

        def write(tmp: Path) -> None:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)

        write_whole(path, write)

    def restore(self, path: str | Path) -> None:
        """Read a :meth:`checkpoint`: each region's material restores its own state.
        ValueError for another material's checkpoint, or one of other regions or another
        region of some point."""
        names = self.region_names
        with checkpoint_archive(path, _NAME, ("regions", "labels", "grad_u")) as data:
            saved = tuple(str(s) for s in data["regions"].reshape(-1))
            if saved != names:
                raise ValueError(f"{path} holds the regions {', '.join(saved)}; this material "
                                 f"has {', '.join(names)}")
            labels = np.array(data["labels"], dtype=np.int64)
            mine = np.array([names.index(r) for r in self._labels], dtype=np.int64)
            if labels.shape != mine.shape or not np.array_equal(labels, mine):
                raise ValueError(f"{path} was written for other points' regions ("
                                 f"{labels.size} points; this material has {mine.size}, "
                                 "or their regions differ)")
            missing = [k for k in range(len(names)) if f"{_STATE}{k}" not in data.files]
            if missing:
                raise ValueError(f"{path} lacks the state of region {names[missing[0]]!r}")
            states = [np.array(data[f"{_STATE}{k}"], dtype=np.uint8)
                      for k in range(len(names))]
            grad = np.array(data["grad_u"], dtype=np.float64)
        with tempfile.TemporaryDirectory(prefix="regions-") as folder:
            for k, material in enumerate(self._materials.values()):
                own = Path(folder) / f"region_{k}.npz"
                data_k = states[k].tobytes()
                write_whole(own, lambda tmp, data_k=data_k: tmp.write_bytes(data_k))
                material.restore(own)
        for name, material in self._materials.items():
            if material.n_points != self._index[name].size:
                raise ValueError(f"{path}: region {name!r} restored {material.n_points} "
                                 f"points; the region has {self._index[name].size}")
        self._track_allocate(int(self._labels.size))
        if grad.shape == (self._labels.size, 2, 2):
            self._committed_grad = grad
        self._last = None

