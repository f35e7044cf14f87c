"""FEM side of the FEM×DEM coupling: material protocol, Newton driver, problems, runner.

A material is anything that follows :class:`Material` (found by name through the
``granular_material.materials`` entry points: ``linear-elastic``, ``dem``); the
:class:`NewtonSolver` drives it on a scikit-fem basis; :func:`run_biaxial` runs the drained
biaxial test (one element or a specimen) and collects its tables (written, plotted and
summarised by :mod:`granular_material.results`), saving them into a :class:`RunStore` (the
run folder's checkpoint is :mod:`granular_material.runs.checkpoint`).
:func:`default_settings` holds the Newton settings the commands use.
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
from granular_material.fem.run_store import RunStore, SavedRun, SavedStep
from granular_material.fem.runner import BiaxialResult, RunObserver, run_biaxial
from granular_material.fem.tracking import (
    Tracking,
    available_postprocessors,
    load_postprocessor,
)

__all__ = [
    "MEASURES",
    "BiaxialProblem",
    "BiaxialResult",
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
    "RunObserver",
    "RunStore",
    "SavedRun",
    "SavedStep",
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
    "run_biaxial",
    "to_points",
    "to_quadrature",
]
