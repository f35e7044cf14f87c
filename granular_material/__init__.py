"""granular-material: multiscale FEM x DEM simulation of granular geomaterials.

Floors, bottom up, each importing only from those below it:
:mod:`granular_material.dem` (batched periodic DEM on warp, homogenisation),
:mod:`granular_material.procedures` (strain paths, servo, packings, element tests),
:mod:`granular_material.fem` (material protocol, Newton driver, problems, runner),
:mod:`granular_material.results` (tables, writers, plots, localisation, summaries),
:mod:`granular_material.cli` (the ``granular-material`` command line).
"""

__version__ = "0.1.0"
