"""FEM side of the FEM×DEM coupling: material protocol, Newton driver, problems, outputs.

A material is anything that follows :class:`Material` (found by name through the
``granular_material.materials`` entry points: ``linear-elastic``, ``dem``); the
:class:`NewtonSolver` drives it on a scikit-fem basis; :func:`run_biaxial` runs the drained
biaxial test (one element or a specimen) and collects tables for :func:`write_outputs`.
"""

from granular_material.fem.layout import to_points, to_quadrature
from granular_material.fem.linear_elastic import LinearElastic, LinearElasticParameters
from granular_material.fem.material import (
    Material,
    MaterialResponse,
    PointStatus,
    available_materials,
    create_material,
    load_material,
)
from granular_material.fem.newton import (
    Loading,
    NewtonError,
    NewtonSettings,
    NewtonSolver,
    StepRecord,
)
from granular_material.fem.output import write_outputs
from granular_material.fem.problems import BiaxialProblem, BiaxialSetup, build_biaxial
from granular_material.fem.runner import BiaxialResult, run_biaxial

__all__ = [
    "BiaxialProblem",
    "BiaxialResult",
    "BiaxialSetup",
    "LinearElastic",
    "LinearElasticParameters",
    "Loading",
    "Material",
    "MaterialResponse",
    "NewtonError",
    "NewtonSettings",
    "NewtonSolver",
    "PointStatus",
    "StepRecord",
    "available_materials",
    "build_biaxial",
    "create_material",
    "load_material",
    "run_biaxial",
    "to_points",
    "to_quadrature",
    "write_outputs",
]
