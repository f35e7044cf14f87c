"""FEM side of the FEM×DEM coupling: material protocol, Newton driver, problems.

A material is anything that follows :class:`Material` (found by name through the
``granular_material.materials`` entry points: ``linear-elastic``, ``dem``); the
:class:`NewtonSolver` drives it on a scikit-fem basis, on the drained biaxial problems of
:func:`build_biaxial` (one element or a specimen); :class:`Tracking` names the
post-processors run on chosen Gauss points. :func:`default_settings` holds the Newton settings
the commands use. The run loop that collects a run's tables and keeps its checkpoint is
:func:`granular_material.runs.run_biaxial`.
"""

from granular_material.fem.defaults import (
    default_settings,
    default_stress_tol,
)
from granular_material.fem.layout import Layout, grad_points, to_points, to_quadrature
from granular_material.fem.linear_elastic import LinearElastic, LinearElasticParameters
from granular_material.fem.loading import Loading
from granular_material.fem.material import (
    MEASURES,
    FailureReason,
    Material,
    MaterialResponse,
    PointStatus,
    QuadratureResponse,
    ScikitFemInterface,
    available_materials,
    create_material,
    load_material,
)
from granular_material.fem.newton import (
    CommittedState,
    NewtonError,
    NewtonSettings,
    NewtonSolver,
    StepRecord,
)
from granular_material.fem.problems import BiaxialProblem, BiaxialSetup, build_biaxial
from granular_material.fem.tracking import (
    Tracking,
    available_postprocessors,
    load_postprocessor,
)

__all__ = [
    "MEASURES",
    "BiaxialProblem",
    "BiaxialSetup",
    "CommittedState",
    "FailureReason",
    "Layout",
    "LinearElastic",
    "LinearElasticParameters",
    "Loading",
    "Material",
    "MaterialResponse",
    "NewtonError",
    "NewtonSettings",
    "NewtonSolver",
    "PointStatus",
    "QuadratureResponse",
    "ScikitFemInterface",
    "StepRecord",
    "Tracking",
    "available_materials",
    "available_postprocessors",
    "build_biaxial",
    "create_material",
    "default_settings",
    "default_stress_tol",
    "grad_points",
    "load_material",
    "load_postprocessor",
    "to_points",
    "to_quadrature",
]
