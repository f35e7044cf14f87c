"""Batched periodic 2D DEM on warp: many RVEs of discs advanced together.

Typical use::

    batch = prepare_packing(n_disc=400, n_rve=8, seed=1, pressure=100e3)
    snap = batch.snapshot()
    drive_grad_u(batch, grad_u)          # (B, 2, 2)
    h = batch.homogenize()               # h.stress (B, 2, 2) Pa, h.tangent (B, 2, 2, 2, 2) Pa
    batch.restore(snap)
"""

from granular_material.dem.batch import DEMBatch
from granular_material.dem.model import Model, State, build_model, critical_timestep
from granular_material.dem.packing import prepare_packing, random_gas
from granular_material.dem.protocols import (
    BiaxialSummary,
    biaxial_test,
    consolidate,
    drive_grad_u,
    has_real_logarithm,
    path_increment,
    servo_steps,
    summarize_biaxial,
)
from granular_material.dem.rve_file import (
    FORMAT_VERSION,
    RVEData,
    RVEFileError,
    RVEMeta,
    load_rve,
    save_rve,
)
from granular_material.dem.solver import DEMInstabilityError, Solver

__all__ = [
    "FORMAT_VERSION",
    "BiaxialSummary",
    "DEMBatch",
    "DEMInstabilityError",
    "Model",
    "RVEData",
    "RVEFileError",
    "RVEMeta",
    "Solver",
    "State",
    "biaxial_test",
    "build_model",
    "consolidate",
    "critical_timestep",
    "drive_grad_u",
    "has_real_logarithm",
    "load_rve",
    "path_increment",
    "prepare_packing",
    "random_gas",
    "save_rve",
    "servo_steps",
    "summarize_biaxial",
]
