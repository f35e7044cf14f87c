"""FEM × DEM at a Gauss point: the DEM material, one periodic DEM RVE per point.

Registered as the ``dem`` entry point of ``granular_material.materials``::

    from granular_material.fem import create_material
    material = create_material("dem", particles=400, seed=1, confining=100e3)

A scikit-fem user calls ``material.response(basis.interpolate(u))`` with the total
displacement (see docs/guide/scikit-fem.md). It joins the two cores, :mod:`granular_material.fem`
and :mod:`granular_material.dem`, through the :class:`~granular_material.fem.Material`
protocol alone: its settings (:mod:`.parameters`), the RVEs it starts from
(:mod:`.preparation`), the batch in this process (:mod:`.backend`) or on the ranks of an MPI
job (:mod:`.mpi`), what an evaluation gives (:mod:`.evaluation`) and its run hooks
(:mod:`.run_hooks`).
"""

from granular_material.multiscale.backend import InProcessBackend
from granular_material.multiscale.confinement import (
    UNCONFINED_FRACTION,
    UnconfinedWarning,
    unconfined,
)
from granular_material.multiscale.evaluation import DEMBackend, Evaluation
from granular_material.multiscale.material import DEMMaterial
from granular_material.multiscale.parameters import (
    BACKENDS,
    DEMDriving,
    DEMMaterialParameters,
    DEMRVEs,
)
from granular_material.multiscale.run_hooks import DEMParameters

__all__ = ["BACKENDS", "UNCONFINED_FRACTION", "DEMBackend", "DEMDriving", "DEMMaterial",
           "DEMMaterialParameters", "DEMParameters", "DEMRVEs", "Evaluation",
           "InProcessBackend", "UnconfinedWarning", "unconfined"]
