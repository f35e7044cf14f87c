"""The scikit-fem DEM material plugin: one periodic DEM RVE per Gauss point.

Registered as the ``dem`` entry point of ``granular_material.materials``::

    from granular_material.fem import create_material
    material = create_material("dem", particles=400, seed=1, confining=100e3)

A scikit-fem user calls ``material.response(basis.interpolate(u))`` with the total
displacement (see docs/guide/scikit-fem.md).
"""

from granular_material_skfem.backend import DEMBackend, Evaluation, InProcessBackend
from granular_material_skfem.material import DEMMaterial, DEMMaterialParameters, UnconfinedWarning

__all__ = ["DEMBackend", "DEMMaterial", "DEMMaterialParameters", "Evaluation",
           "InProcessBackend", "UnconfinedWarning"]
