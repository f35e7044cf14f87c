"""Named settings of the FEM × DEM commands, chosen by the trade study from measurements, and
each as a partial run specification: the fields it sets (flat names), merged under what a
user gives.

``presets.json`` beside this module is the ``presets.json`` of the committed CPU trade study
(``docs/trade-study/``, whose ``report.md`` gives each preset's measured error and cost); a
test keeps the two the same. ``quick``, ``engineering`` and ``publication`` differ in the
discs per RVE, the strain per DEM step, the Newton stress floor, the tangent and its update,
predictor and relaxation and the reuse of undisturbed RVEs: the knobs the study found to
trade speed for accuracy (see :func:`granular_material.studies.scoring.recommend` for the
rule).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

__all__ = ["PRESETS_FILE", "PRESET_NAMES", "Preset", "load_presets", "preset_fields"]

PRESETS_FILE = Path(__file__).with_name("presets.json")


@dataclass(frozen=True)
class Preset:
    """One named setting.

    Attributes:
        name: quick, engineering or publication.
        discs: discs per prepared RVE.
        strain_per_step: largest strain of one DEM step [-].
        rtol: Newton's relative residual tolerance.
        stress_floor: Newton's absolute stress tolerance as a fraction of the confining
            pressure [-].
        tangent: the material tangent (objective, kruyt-rothenburg, perturbation,
            condensed, condensed-sticking).
        tangent_update: Newton's update of it between evaluations: none (the material's
            tangent at every iterate), secant (Broyden updates) or hold (held over each
            increment).
        acceleration: "predictor/relaxation", e.g. "extrapolate/aitken".
        reuse_tol: reuse tolerance of undisturbed RVEs [-].
    """

    name: str
    discs: int
    strain_per_step: float
    rtol: float
    stress_floor: float
    tangent: str
    tangent_update: str
    acceleration: str
    reuse_tol: float


@cache
def load_presets() -> dict[str, Preset]:
    """The presets of :data:`PRESETS_FILE`, by name."""
    saved = json.loads(PRESETS_FILE.read_text())
    return {name: Preset(name=name, **values) for name, values in saved.items()}


#: the presets' names
PRESET_NAMES = tuple(load_presets())
#: what the presets were measured with beyond their own values: the force test and 25
#: iterations an increment
_MEASURED_WITH = {"convergence": "force", "max_iterations": 25}


def preset_fields(name: str, confining: float, with_discs: bool = True) -> dict[str, Any]:
    """The flat spec fields of preset ``name`` for a run at ``confining`` [Pa] (its stress
    floor is a fraction of it); ``with_discs``: the discs per prepared RVE too (not for a
    run of an RVE file, whose discs are the file's)."""
    preset = load_presets()[name]
    predictor, relaxation = preset.acceleration.split("/")
    values: dict[str, Any] = {
        **_MEASURED_WITH, "rtol": preset.rtol, "stress_tol": preset.stress_floor * confining,
        "tangent": preset.tangent, "tangent_update": preset.tangent_update,
        "predictor": predictor, "relaxation": relaxation, "reuse_tol": preset.reuse_tol,
        "max_strain_per_step": preset.strain_per_step,
    }
    if with_discs:
        values["particles"] = preset.discs
    return values
