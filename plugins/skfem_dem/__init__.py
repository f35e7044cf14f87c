"""The DEM material's former home, kept so that old imports go on working.

The DEM material is part of the core now: :mod:`granular_material.multiscale` (registered as
the ``dem`` entry point of ``granular_material.materials``). Import it from there; this name
will be removed in a later version.
"""

import warnings

from granular_material.multiscale import (
    DEMBackend,
    DEMMaterial,
    DEMMaterialParameters,
    Evaluation,
    InProcessBackend,
    UnconfinedWarning,
)

__all__ = ["DEMBackend", "DEMMaterial", "DEMMaterialParameters", "Evaluation",
           "InProcessBackend", "UnconfinedWarning"]

warnings.warn("granular_material_skfem is deprecated: import the DEM material from "
              "granular_material.multiscale", DeprecationWarning, stacklevel=2)
