"""The presets as partial run specifications: the fields a named preset of
:mod:`granular_material.fem.presets` sets (flat names), merged under what a user gives."""

from __future__ import annotations

from typing import Any

from granular_material.fem.presets import load_presets, tangent_settings

__all__ = ["PRESET_NAMES", "preset_fields"]

#: the presets' names
PRESET_NAMES = tuple(load_presets())
#: what the presets were measured with beyond their own values: the force test and 25
#: iterations an increment
_MEASURED_WITH = {"convergence": "force", "max_iterations": 25}


def preset_fields(name: str, confining: float, with_discs: bool = True) -> dict[str, Any]:
    """The flat spec fields of preset ``name`` for a run at ``confining`` [Pa] (its stress
    floor is a fraction of it); ``with_discs``: the discs per prepared RVE too (not for a
    run of an RVE file, whose discs are the file's). Its tangent is read as
    :func:`~granular_material.fem.presets.tangent_settings` says."""
    preset = load_presets()[name]
    predictor, relaxation = preset.acceleration.split("/")
    values: dict[str, Any] = {
        **_MEASURED_WITH, "rtol": preset.rtol, "stress_tol": preset.stress_floor * confining,
        **tangent_settings(preset.tangent), "predictor": predictor,
        "relaxation": relaxation, "reuse_tol": preset.reuse_tol,
        "max_strain_per_step": preset.strain_per_step,
    }
    if with_discs:
        values["particles"] = preset.discs
    return values
