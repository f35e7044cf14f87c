"""Batched periodic 2D DEM on warp: many RVEs of discs advanced together (numpy + warp only).

Typical use (with the procedures of :mod:`granular_material.procedures`)::

    batch = prepare_packing(n_disc=400, n_rve=8, seed=1, pressure=100e3)
    snap = batch.snapshot()
    drive_grad_u(batch, grad_u)          # (B, 2, 2)
    h = batch.homogenize()               # h.stress (B, 2, 2) Pa, h.tangent (B, 2, 2, 2, 2) Pa
    batch.restore(snap)
"""

from granular_material.dem.batch import DEMBatch
from granular_material.dem.homogenization import Homogenized, homogenize, void_ratio
from granular_material.dem.loading import LoadingControl, ServoSettings
from granular_material.dem.model import Model, build_model, critical_timestep, resolve_device
from granular_material.dem.rve.file import (
    FORMAT_VERSION,
    RVEData,
    RVEFileError,
    RVEMeta,
    load_rve,
    save_rve,
)
from granular_material.dem.solver import (
    CONTROL_STRAIN,
    CONTROL_STRESS,
    DEMInstabilityError,
    Solver,
)
from granular_material.dem.state import State

__all__ = [
    "CONTROL_STRAIN",
    "CONTROL_STRESS",
    "FORMAT_VERSION",
    "DEMBatch",
    "DEMInstabilityError",
    "Homogenized",
    "LoadingControl",
    "Model",
    "RVEData",
    "RVEFileError",
    "RVEMeta",
    "ServoSettings",
    "Solver",
    "State",
    "build_model",
    "critical_timestep",
    "homogenize",
    "load_rve",
    "resolve_device",
    "save_rve",
    "void_ratio",
]
