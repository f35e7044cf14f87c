"""Procedures built on the DEM core: strain paths, stress servo, consolidation, packings,
element tests (each takes a :class:`~granular_material.dem.DEMBatch` and treats its RVEs
independently), and :func:`progress_bar`, the one progress bar every layer uses.

The names are imported when first used (PEP 562): a module that needs one constant of a
procedure does not load the DEM and warp with it (issue 62).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from granular_material.lazy_names import lazy_names

if TYPE_CHECKING:
    from granular_material.procedures.driven_path import DrivenPath, drive_path, plan_path
    from granular_material.procedures.element_tests import biaxial_test
    from granular_material.procedures.packing import PackingParameters, prepare_packing, random_gas
    from granular_material.procedures.servo import consolidate, servo_steps
    from granular_material.procedures.strain_path import (
        CellTooThinError,
        RVECollapseError,
        drive_grad_u,
        has_real_logarithm,
        over_step_cap,
        path_increment,
        path_steps,
    )
    from granular_material.progress import progress_bar

#: the module each public name comes from
_HOME = {
    "DrivenPath": "granular_material.procedures.driven_path",
    "drive_path": "granular_material.procedures.driven_path",
    "plan_path": "granular_material.procedures.driven_path",
    "biaxial_test": "granular_material.procedures.element_tests",
    "PackingParameters": "granular_material.procedures.packing",
    "prepare_packing": "granular_material.procedures.packing",
    "random_gas": "granular_material.procedures.packing",
    "consolidate": "granular_material.procedures.servo",
    "servo_steps": "granular_material.procedures.servo",
    "CellTooThinError": "granular_material.procedures.strain_path",
    "RVECollapseError": "granular_material.procedures.strain_path",
    "drive_grad_u": "granular_material.procedures.strain_path",
    "has_real_logarithm": "granular_material.procedures.strain_path",
    "over_step_cap": "granular_material.procedures.strain_path",
    "path_increment": "granular_material.procedures.strain_path",
    "path_steps": "granular_material.procedures.strain_path",
    "progress_bar": "granular_material.progress",
}


# a public name (or a submodule) of the package, imported on first use
__getattr__, __dir__ = lazy_names(__name__, _HOME, globals(), submodules=True)


__all__ = [
    "CellTooThinError",
    "DrivenPath",
    "PackingParameters",
    "RVECollapseError",
    "biaxial_test",
    "consolidate",
    "drive_grad_u",
    "drive_path",
    "has_real_logarithm",
    "over_step_cap",
    "path_increment",
    "path_steps",
    "plan_path",
    "prepare_packing",
    "progress_bar",
    "random_gas",
    "servo_steps",
]
