"""granular-material: multiscale FEM x DEM simulation of granular geomaterials.

Packages: :mod:`granular_material.dem` (batched periodic DEM on warp),
:mod:`granular_material.homogenization` (Love stress, Kruyt–Rothenburg tangent),
:mod:`granular_material.fem` (material protocol, Newton driver, problems).
"""

__version__ = "0.1.0"
