"""Batched periodic 2D DEM on warp: many RVEs of discs advanced together (numpy + warp only).

Typical use (with the procedures of :mod:`granular_material.procedures`)::

    batch = prepare_packing(n_disc=400, n_rve=8, seed=1, pressure=100e3)
    snap = batch.snapshot()
    drive_grad_u(batch, grad_u)          # (B, 2, 2)
    h = batch.homogenize()               # h.stress (B, 2, 2) Pa, h.tangent (B, 2, 2, 2, 2) Pa
    batch.restore(snap)

The names below are imported when first used (PEP 562): importing one module of the package
(the RVE file format, say) loads neither warp nor the rest of the DEM, so that a run of a
continuum material never does (issue 62).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from granular_material.lazy_names import lazy_names

if TYPE_CHECKING:
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

#: the module each public name comes from
_HOME = {
    "DEMBatch": "granular_material.dem.batch",
    "Homogenized": "granular_material.dem.homogenization",
    "homogenize": "granular_material.dem.homogenization",
    "void_ratio": "granular_material.dem.homogenization",
    "LoadingControl": "granular_material.dem.loading",
    "ServoSettings": "granular_material.dem.loading",
    "Model": "granular_material.dem.model",
    "build_model": "granular_material.dem.model",
    "critical_timestep": "granular_material.dem.model",
    "resolve_device": "granular_material.dem.model",
    "FORMAT_VERSION": "granular_material.dem.rve.file",
    "RVEData": "granular_material.dem.rve.file",
    "RVEFileError": "granular_material.dem.rve.file",
    "RVEMeta": "granular_material.dem.rve.file",
    "load_rve": "granular_material.dem.rve.file",
    "save_rve": "granular_material.dem.rve.file",
    "CONTROL_STRAIN": "granular_material.dem.solver",
    "CONTROL_STRESS": "granular_material.dem.solver",
    "DEMInstabilityError": "granular_material.dem.solver",
    "Solver": "granular_material.dem.solver",
    "State": "granular_material.dem.state",
}


# a public name (or a submodule) of the package, imported on first use
__getattr__, __dir__ = lazy_names(__name__, _HOME, globals(), submodules=True)


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
