"""What a boundary-value run needs, told before it is made: the memory of its mesh, basis
and solver, and the disk of its Gauss-point table; a :class:`~granular_material.runs.spec.SpecError`
naming ``mesh`` or ``steps`` with the estimate where the machine cannot give it."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

from granular_material.fem.boundary_value.biaxial import DEFAULT_GAUSS, TRIANGLES
from granular_material.fem.boundary_value.meshes import MeshData
from granular_material.memory import available_memory, memory_refusal, size_in_words
from granular_material.runs.boundary_value.spec import BoundaryValueSpec
from granular_material.runs.spec import SpecError

__all__ = ["check_disk", "check_memory", "generated_size", "points_of"]

#: memory of a boundary-value run per Gauss point [bytes] (basis, assembly, the solver's
#: factorisation, the tables of a step): the peak RSS over the build and one linear-elastic
#: step of 150 x 150 meshes, measured at 4.8 kB (quad4), 10.1 kB (tri6) and 8.3 kB (quad9)
#: (3.7 kB for quad4 at 300 x 300: a fixed part shared); the largest, rounded
_POINT_BYTES = 10_000
#: the least a Gauss point's record of points.npy takes on disk [bytes]: its 17 columns of
#: 8 bytes each
_POINT_RECORD_BYTES = 17 * 8
#: the least a Gauss point's row of points.csv (on request) takes on disk [bytes]: its 17
#: columns at a few characters each (a committed step's floats take 18-24; step 0's zeros 3)
_POINT_ROW_BYTES = 17 * 6


def generated_size(spec: BoundaryValueSpec) -> tuple[int, str]:
    """The elements of the generated mesh of ``spec`` (a rectangle is two triangles): their
    count and their kind."""
    m = spec.mesh
    return m.elements[0] * m.elements[1] * (2 if m.element in TRIANGLES else 1), m.element


def points_of(spec: BoundaryValueSpec, n_elements: int, element: str) -> int:
    """Gauss points of ``n_elements`` elements ``element`` under ``spec``'s quadrature (per
    triangle, or per direction of a quadrilateral)."""
    n = spec.mesh.quadrature or DEFAULT_GAUSS[element]
    return n_elements * (n if element in TRIANGLES else n * n)


def check_memory(spec: BoundaryValueSpec, n_elements: int, element: str) -> None:
    """Before the mesh (of a generated one) and the basis are made: the run's memory
    (:data:`_POINT_BYTES` a Gauss point), a SpecError naming the mesh with the estimate
    where it cannot be had."""
    points = points_of(spec, n_elements, element)
    refusal = memory_refusal(float(points) * _POINT_BYTES,
                             f"{n_elements} {element} elements ({points} Gauss points)",
                             available_memory())
    if refusal:
        raise SpecError("mesh", refusal)


def check_disk(spec: BoundaryValueSpec, out: Path,
               mesh_of: Callable[[BoundaryValueSpec], MeshData]) -> None:
    """Before the run: ``points.npy`` (every Gauss point at every step,
    :data:`_POINT_RECORD_BYTES` a record at least) and, where the spec asks for it,
    ``points.csv`` (at least :data:`_POINT_ROW_BYTES` a row) must fit the free space of
    ``out``'s disk; a SpecError naming ``steps`` with the estimate otherwise. ``mesh_of``:
    the mesh of a spec whose mesh is a file (read to count its elements)."""
    if spec.mesh.file is None:
        check_memory(spec, *generated_size(spec))
        points = points_of(spec, *generated_size(spec))
    else:
        mesh = mesh_of(spec)
        points = points_of(spec, mesh.n_elements, mesh.element)
    row = _POINT_RECORD_BYTES + (_POINT_ROW_BYTES if spec.points_csv else 0)
    needed = float(points) * (spec.steps + 1) * row
    free = shutil.disk_usage(out).free
    if needed > free:
        tables = "points.npy and points.csv" if spec.points_csv else "points.npy"
        raise SpecError("steps", f"{spec.steps} load steps of {points} Gauss points write "
                                 f"at least {size_in_words(needed)} of {tables}; {out} has "
                                 f"{size_in_words(free)} free; take fewer steps or a coarser "
                                 "mesh")
