"""Runs as data: the typed run specification (:mod:`~granular_material.runs.spec`), its
forms as dicts, JSON, TOML and flat option names (:mod:`~granular_material.runs.serial`),
and :func:`run`, the one entry point of a FEM run (:mod:`~granular_material.runs.execute`),
which keeps the run's checkpoint in its folder (:class:`RunCheckpoint`,
:mod:`~granular_material.runs.checkpoint`) to resume from; :func:`run_biaxial`
(:mod:`~granular_material.runs.runner`) is its run loop, for any material. :func:`run` also
runs the DEM runs ``prepare``, ``biaxial-dem`` and ``dem-drive``, whose specs
(:class:`PrepareSpec`, :class:`BiaxialDemSpec`, :class:`DriveSpec`) are
:mod:`~granular_material.runs.dem`'s.

::

    from granular_material.runs import MaterialSpec, ProblemSpec, RunSpec, run

    spec = RunSpec(problem=ProblemSpec(test="single-element", steps=20, axial_strain=0.02),
                   material=MaterialSpec(name="dem", parameters={"particles": 64}))
    outcome = run(spec)
    outcome.result.steps[["axial_strain", "stress_ratio"]]
"""

from granular_material.fem.materials.run_context import RunContext
from granular_material.results.biaxial import BiaxialResult
from granular_material.runs.checkpoint import CheckpointError, RunCheckpoint, SavedRun
from granular_material.runs.dem import BiaxialDemSpec, DemOutcome, DriveSpec, PrepareSpec
from granular_material.runs.execute import RunOutcome, RunPlan, check, run
from granular_material.runs.resume import differences_from_saved
from granular_material.runs.runner import RunObserver, run_biaxial
from granular_material.runs.serial import from_dict, from_flat, load, save, to_dict, to_flat
from granular_material.runs.spec import (
    MaterialSpec,
    NewtonSpec,
    OutputSpec,
    ProblemSpec,
    RunSpec,
    SpecError,
)

__all__ = ["BiaxialDemSpec", "BiaxialResult", "CheckpointError", "DemOutcome", "DriveSpec",
           "MaterialSpec", "NewtonSpec", "OutputSpec", "PrepareSpec", "ProblemSpec",
           "RunCheckpoint", "RunContext", "RunObserver", "RunOutcome", "RunPlan", "RunSpec",
           "SavedRun", "SpecError", "check", "differences_from_saved", "from_dict", "from_flat",
           "load", "run", "run_biaxial", "save", "to_dict", "to_flat"]
