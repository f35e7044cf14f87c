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
(:mod:`.run_hooks`); beside it, :class:`AdaptiveMaterial` (:mod:`.adaptive`): the
calibrated Mohr–Coulomb twin at every point and a DEM RVE only where the twin is no longer
trusted.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from granular_material.lazy_names import lazy_names

if TYPE_CHECKING:
    from granular_material.multiscale.adaptive import AdaptiveMaterial
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
    from granular_material.multiscale.switching import SwitchCriterion

#: the module each public name comes from: imported on first use (PEP 562), so that the DEM
#: material's parameters (the command line's defaults) load neither warp nor the DEM
_HOME = {
    "AdaptiveMaterial": "granular_material.multiscale.adaptive",
    "SwitchCriterion": "granular_material.multiscale.switching",
    "InProcessBackend": "granular_material.multiscale.backend",
    "UNCONFINED_FRACTION": "granular_material.multiscale.confinement",
    "UnconfinedWarning": "granular_material.multiscale.confinement",
    "unconfined": "granular_material.multiscale.confinement",
    "DEMBackend": "granular_material.multiscale.evaluation",
    "Evaluation": "granular_material.multiscale.evaluation",
    "DEMMaterial": "granular_material.multiscale.material",
    "BACKENDS": "granular_material.multiscale.parameters",
    "DEMDriving": "granular_material.multiscale.parameters",
    "DEMMaterialParameters": "granular_material.multiscale.parameters",
    "DEMRVEs": "granular_material.multiscale.parameters",
    "DEMParameters": "granular_material.multiscale.run_hooks",
}

# a public name (or a submodule) of the package, imported on first use
__getattr__, __dir__ = lazy_names(__name__, _HOME, globals(), submodules=True)

__all__ = ["BACKENDS", "UNCONFINED_FRACTION", "AdaptiveMaterial", "DEMBackend", "DEMDriving",
           "DEMMaterial", "DEMMaterialParameters", "DEMParameters", "DEMRVEs", "Evaluation",
           "InProcessBackend", "SwitchCriterion", "UnconfinedWarning", "unconfined"]
