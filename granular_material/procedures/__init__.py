"""Procedures built on the DEM core: strain paths, stress servo, consolidation, packings,
element tests (each takes a :class:`~granular_material.dem.DEMBatch` and treats its RVEs
independently), and :func:`progress_bar`, the one progress bar every layer uses."""

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
