"""FEM side of the FEM×DEM coupling: material protocol, Newton driver, problems.

A material is anything that follows :class:`Material` (found by name through the
``granular_material.materials`` entry points: ``linear-elastic``, ``mohr-coulomb``, ``dem``);
the :class:`NewtonSolver` drives it on a scikit-fem basis, on the drained biaxial problems of
:func:`build_biaxial` (one element or a specimen) or on any boundary-value problem of
:func:`build_problem` (a mesh from a file, :func:`read_mesh`, or :func:`rectangle_mesh`; named
boundaries, :func:`select_boundaries`; the conditions :class:`Fixed`, :class:`Roller`,
:class:`Displacement`, :class:`RigidBody`, :class:`Pressure`, :class:`Gravity`; an initial
state, :func:`geostatic_stress`, or under sloping and layered ground :func:`ground_stress`);
:class:`RegionalMaterial` holds one material per region
of the mesh (a layer, a fill) and answers as one; :class:`RunContext` is what a material is
told of the run it is built for; :class:`Tracking` names the
post-processors run on chosen Gauss points. ``NewtonSettings(continuation="arc-length")``
follows a path past its limit points (:class:`ContinuationState` keeps it), and
:func:`strength_reduction` finds a factor of safety by reducing the strength to the
collapse. :func:`default_settings` holds the Newton settings
the commands use. The run loop that collects a run's tables and keeps its checkpoint is
:func:`granular_material.runs.run_biaxial`.
"""

from granular_material.fem.boundary_value.biaxial import BiaxialProblem, BiaxialSetup, build_biaxial
from granular_material.fem.boundary_value.boundaries import select_boundaries, select_facets
from granular_material.fem.boundary_value.conditions import (
    Condition,
    Displacement,
    Fixed,
    Gravity,
    Pressure,
    Problem,
    RigidBody,
    Roller,
    build_problem,
)
from granular_material.fem.boundary_value.ground import (
    GroundState,
    ground_stress,
    lift_to_floor,
    overburden,
)
from granular_material.fem.boundary_value.initial_stress import geostatic_stress, uniform_stress
from granular_material.fem.boundary_value.loading import Loading
from granular_material.fem.boundary_value.meshes import (
    MeshData,
    make_basis,
    read_mesh,
    rectangle_mesh,
)
from granular_material.fem.boundary_value.reactions import BoundaryDofs, boundary_dofs
from granular_material.fem.layout import Layout, grad_points, to_points, to_quadrature
from granular_material.fem.materials.linear_elastic import LinearElastic, LinearElasticParameters
from granular_material.fem.materials.mohr_coulomb import MohrCoulomb, MohrCoulombParameters
from granular_material.fem.materials.protocol import (
    MEASURES,
    FailureReason,
    Material,
    MaterialResponse,
    PointStatus,
    QuadratureResponse,
    RunContext,
    ScikitFemInterface,
    available_materials,
    create_material,
    load_material,
)
from granular_material.fem.materials.regions import RegionalMaterial, point_regions
from granular_material.fem.regularisation import (
    REGULARISATIONS,
    Regularisation,
    SecondGradient,
    add_second_gradient,
)
from granular_material.fem.solver.continuation import ContinuationState
from granular_material.fem.solver.defaults import (
    default_settings,
    default_stress_tol,
)
from granular_material.fem.solver.newton import (
    CommittedState,
    NewtonError,
    NewtonSettings,
    NewtonSolver,
    StepRecord,
)
from granular_material.fem.solver.strength_reduction import (
    StrengthReductionResult,
    strength_reduction,
)
from granular_material.fem.tracking import (
    Tracking,
    available_postprocessors,
    load_postprocessor,
)

__all__ = [
    "MEASURES",
    "REGULARISATIONS",
    "BiaxialProblem",
    "BiaxialSetup",
    "BoundaryDofs",
    "CommittedState",
    "Condition",
    "ContinuationState",
    "Displacement",
    "FailureReason",
    "Fixed",
    "Gravity",
    "GroundState",
    "Layout",
    "LinearElastic",
    "LinearElasticParameters",
    "Loading",
    "Material",
    "MaterialResponse",
    "MeshData",
    "MohrCoulomb",
    "MohrCoulombParameters",
    "NewtonError",
    "NewtonSettings",
    "NewtonSolver",
    "PointStatus",
    "Pressure",
    "Problem",
    "QuadratureResponse",
    "RegionalMaterial",
    "Regularisation",
    "RigidBody",
    "Roller",
    "RunContext",
    "ScikitFemInterface",
    "SecondGradient",
    "StepRecord",
    "StrengthReductionResult",
    "Tracking",
    "add_second_gradient",
    "available_materials",
    "available_postprocessors",
    "boundary_dofs",
    "build_biaxial",
    "build_problem",
    "create_material",
    "default_settings",
    "default_stress_tol",
    "geostatic_stress",
    "grad_points",
    "ground_stress",
    "lift_to_floor",
    "load_material",
    "load_postprocessor",
    "make_basis",
    "overburden",
    "point_regions",
    "read_mesh",
    "rectangle_mesh",
    "select_boundaries",
    "select_facets",
    "strength_reduction",
    "to_points",
    "to_quadrature",
    "uniform_stress",
]
