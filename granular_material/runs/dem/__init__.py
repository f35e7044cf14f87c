"""The DEM runs as data: ``prepare``, ``biaxial-dem`` and ``dem-drive`` as specifications
(:class:`PrepareSpec`, :class:`BiaxialDemSpec`, :class:`DriveSpec`;
:mod:`~granular_material.runs.dem.spec`), their dict, JSON and TOML forms
(:mod:`~granular_material.runs.dem.serial`), and their runs
(:mod:`~granular_material.runs.dem.runner`), checked before any work, locked, and a
biaxial test or a path checkpointed beside its output file to resume from
(:mod:`~granular_material.runs.dem.checkpoint`). :func:`granular_material.runs.run` runs
them as it runs a FEM spec::

    from granular_material.runs import run
    from granular_material.runs.dem import BiaxialDemSpec, PrepareSpec

    run(PrepareSpec(particles=64, seed=1, out="rve64.npz", device="cpu"))
    outcome = run(BiaxialDemSpec(rve="rve64.npz", axial_strain=0.01, out="curve.csv"))
    outcome.table[["axial_strain", "stress_ratio"]]
"""

from granular_material.runs.dem.checkpoint import DemCheckpoint, SavedRecord, checkpoint_folder
from granular_material.runs.dem.runner import (
    RESUME_FREE,
    SERVO_FAIL,
    SERVO_WARN,
    DemOutcome,
    DemPlan,
    check,
    run_dem,
)
from granular_material.runs.dem.serial import (
    from_dict,
    is_dem,
    load,
    save,
    to_dict,
    to_flat,
    to_toml,
)
from granular_material.runs.dem.spec import (
    DEM_TESTS,
    BiaxialDemSpec,
    DemSpec,
    DriveSpec,
    PrepareSpec,
)

__all__ = ["DEM_TESTS", "RESUME_FREE", "SERVO_FAIL", "SERVO_WARN",
           "BiaxialDemSpec", "DemCheckpoint", "DemOutcome", "DemPlan", "DemSpec", "DriveSpec",
           "PrepareSpec", "SavedRecord", "check", "checkpoint_folder", "from_dict", "is_dem",
           "load", "run_dem", "save", "to_dict", "to_flat", "to_toml"]
