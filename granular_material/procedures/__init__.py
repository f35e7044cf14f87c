"""Procedures built on the DEM core: strain paths, stress servo, consolidation, packings,
element tests. Each takes a :class:`~granular_material.dem.DEMBatch` and treats its RVEs
independently."""

from granular_material.procedures.element_tests import (
    BiaxialSummary,
    biaxial_test,
    summarize_biaxial,
)
from granular_material.procedures.packing import prepare_packing, random_gas
from granular_material.procedures.servo import consolidate, servo_steps
from granular_material.procedures.strain_path import (
    drive_grad_u,
    has_real_logarithm,
    path_increment,
)

__all__ = [
    "BiaxialSummary",
    "biaxial_test",
    "consolidate",
    "drive_grad_u",
    "has_real_logarithm",
    "path_increment",
    "prepare_packing",
    "random_gas",
    "servo_steps",
    "summarize_biaxial",
]
