"""Where the modules moved after release 0.1.0 live now, and the import hook that keeps their old
names working for one release: ``import granular_material.fem.mohr_coulomb`` gives the module
:mod:`granular_material.fem.materials.mohr_coulomb` itself, with a DeprecationWarning naming
the new path. The packages' own names (``from granular_material.fem import MohrCoulomb``)
never moved."""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType
from typing import Any

__all__ = ["MOVED", "install"]

#: old module name -> new, both under ``granular_material.``; the internal modules
#: ``dem.kernels`` and ``dem.condensed`` are packages now (their code is in ``dem.kernels.sets``
#: and ``dem.condensed.tangent``), so their old names cannot be kept
MOVED: dict[str, str] = {
    "fem.material": "fem.materials.protocol",
    "fem.response": "fem.materials.response",
    "fem.run_context": "fem.materials.run_context",
    "fem.scikit_fem_interface": "fem.materials.scikit_fem_interface",
    "fem.material_checks": "fem.materials.checks",
    "fem.linear_elastic": "fem.materials.linear_elastic",
    "fem.mohr_coulomb": "fem.materials.mohr_coulomb",
    "fem.mohr_coulomb_parameters": "fem.materials.mohr_coulomb_parameters",
    "fem.mohr_coulomb_return": "fem.materials.mohr_coulomb_return",
    "fem.newton": "fem.solver.newton",
    "fem.newton_records": "fem.solver.records",
    "fem.newton_settings": "fem.solver.settings",
    "fem.convergence": "fem.solver.convergence",
    "fem.acceleration": "fem.solver.acceleration",
    "fem.defaults": "fem.solver.defaults",
    "fem.problems": "fem.boundary_value.biaxial",
    "fem.meshes": "fem.boundary_value.meshes",
    "fem.boundaries": "fem.boundary_value.boundaries",
    "fem.conditions": "fem.boundary_value.conditions",
    "fem.geostatic": "fem.boundary_value.initial_stress",
    "fem.loading": "fem.boundary_value.loading",
    "fem.reactions": "fem.boundary_value.reactions",
    "dem.kernel_common": "dem.kernels.common",
    "dem.kernels_block": "dem.kernels.block",
    "dem.kernels_lists": "dem.kernels.lists",
    "dem.kernels_measures": "dem.kernels.measures",
    "dem.kernels_step": "dem.kernels.step",
    "dem.laws": "dem.kernels.laws",
    "dem.condensation": "dem.condensed.dispatch",
    "dem.condensed_cg": "dem.condensed.cg",
    "dem.condensed_cg_kernels": "dem.condensed.cg_kernels",
    "dem.condensed_cg_solve": "dem.condensed.cg_solve",
    "dem.condensed_device": "dem.condensed.device",
    "dem.condensed_device_kernels": "dem.condensed.device_kernels",
    "dem.rve_checks": "dem.rve.checks",
    "dem.rve_data": "dem.rve.data",
    "dem.rve_file": "dem.rve.file",
    "dem.rve_format": "dem.rve.format",
    "runs.bvp_checks": "runs.boundary_value.checks",
    "runs.bvp_material": "runs.boundary_value.material",
    "runs.bvp_resume": "runs.boundary_value.resume",
    "runs.bvp_runner": "runs.boundary_value.runner",
    "runs.bvp_spec": "runs.boundary_value.spec",
    # RunContext moved beside the Material protocol before 0.1.0; its old module went now
    "runs.context": "fem.materials.run_context",
}


class _Alias(importlib.abc.Loader):
    """Loads an old name as the module that now holds its code (no second copy)."""

    def __init__(self, new: str) -> None:
        self.new = new

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        warnings.warn(f"{spec.name} moved to {self.new}; import it from there (the old "
                      "name goes in the next release)", DeprecationWarning, stacklevel=2)
        return importlib.import_module(self.new)

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run: the new module was executed when it was imported."""


class _MovedModules(importlib.abc.MetaPathFinder):
    """Finds the old names of :data:`MOVED`, and nothing else."""

    def find_spec(self, fullname: str, path: Any, target: Any = None
                  ) -> importlib.machinery.ModuleSpec | None:
        new = MOVED.get(fullname.removeprefix("granular_material."))
        if new is None or not fullname.startswith("granular_material."):
            return None
        return importlib.machinery.ModuleSpec(fullname, _Alias(f"granular_material.{new}"))


def install() -> None:
    """Put the finder of old names on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, _MovedModules) for f in sys.meta_path):
        sys.meta_path.append(_MovedModules())
