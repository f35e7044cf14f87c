"""Named settings of the FEM × DEM commands, chosen by the trade study from measurements, and
each as a partial run specification: the fields it sets (flat names), merged under what a
user gives. A preset is written in the study's own terms (:data:`SETTING_NAMES`, see
:func:`settings_fields` for the run-spec fields each names), as the study's band rows are.

``presets.json`` beside this module is the ``presets.json`` of the committed CPU trade study
(``docs/trade-study/``, whose ``report.md`` gives each preset's measured error and cost); a
test keeps the two the same. ``quick``, ``engineering`` and ``publication`` differ in the
discs per RVE, the strain per DEM step, and Newton's convergence test, tangent, predictor and
relaxation and drive: the knobs the study found to trade speed for accuracy (see
:func:`granular_material.studies.scoring.recommend` for the rule: the peak of the pure-DEM
and single-element rows, the shear band of the specimen's rows).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

__all__ = ["PRESETS_FILE", "PRESET_NAMES", "SETTING_NAMES", "Preset", "load_presets",
           "preset_fields", "settings_fields"]

PRESETS_FILE = Path(__file__).with_name("presets.json")


@dataclass(frozen=True)
class Preset:
    """One named setting.

    Attributes:
        name: quick, engineering or publication.
        discs: discs per prepared RVE.
        strain_per_step: largest strain of one DEM step [-].
        convergence: Newton's test: force, displacement or residual-displacement.
        rtol: its relative tolerance (of ‖R‖/‖R₀‖ for the force test, of the correction
            for the displacement tests).
        stress_floor: the force test's absolute stress tolerance as a fraction of the
            confining pressure [-]; None: the commands' default.
        tangent: the material tangent (objective, kruyt-rothenburg, perturbation,
            condensed, condensed-sticking).
        tangent_update: Newton's update of it between evaluations: none (the material's
            tangent at every iterate), secant (Broyden updates) or hold (held over each
            increment).
        acceleration: "predictor/relaxation", e.g. "extrapolate/aitken".
        drive: the RVEs' trial states: restart (from the committed state) or continue.
        reuse_tol: reuse tolerance of undisturbed RVEs [-] (with the force test only).
    """

    name: str
    discs: int
    strain_per_step: float
    convergence: str
    rtol: float
    stress_floor: float | None
    tangent: str
    tangent_update: str
    acceleration: str
    drive: str
    reuse_tol: float

    def settings(self) -> dict[str, Any]:
        """The preset's values in the study's terms (:data:`SETTING_NAMES`)."""
        return {name: getattr(self, name) for name in SETTING_NAMES}


#: the settings a preset holds and a band row changes, in the study's terms
SETTING_NAMES = ("discs", "strain_per_step", "convergence", "rtol", "stress_floor", "tangent",
                 "tangent_update", "acceleration", "drive", "reuse_tol")

#: iterations an increment of the force test as the study measured it (the commands allow
#: 100, which DEM noise can spend without gain)
FORCE_TEST_ITERATIONS = 25


@cache
def load_presets() -> dict[str, Preset]:
    """The presets of :data:`PRESETS_FILE`, by name."""
    saved = json.loads(PRESETS_FILE.read_text())
    return {name: Preset(name=name, **values) for name, values in saved.items()}


#: the presets' names
PRESET_NAMES = tuple(load_presets())


def settings_fields(settings: dict[str, Any], confining: float) -> dict[str, Any]:
    """The flat run-spec fields of ``settings`` in the study's terms, for a run at
    ``confining`` [Pa]: ``strain_per_step`` is ``max_strain_per_step``, ``discs`` is
    ``particles``, ``stress_floor`` (a fraction of ``confining``) is ``stress_tol``,
    ``acceleration`` is ``predictor`` and ``relaxation``; the force test gets
    :data:`FORCE_TEST_ITERATIONS` iterations unless ``max_iterations`` is given. Any other
    key is a run-spec field already (``steps``, ``elements``, ``accept_correction``, …)."""
    renamed = {"strain_per_step": "max_strain_per_step", "discs": "particles"}
    values: dict[str, Any] = {}
    for key, value in settings.items():
        if key == "stress_floor":
            if value is not None:
                values["stress_tol"] = value * confining
        elif key == "acceleration":
            values["predictor"], values["relaxation"] = value.split("/")
        else:
            values[renamed.get(key, key)] = value
    if settings.get("convergence") == "force":
        values.setdefault("max_iterations", FORCE_TEST_ITERATIONS)
    return values


def preset_fields(name: str, confining: float, with_discs: bool = True) -> dict[str, Any]:
    """The flat spec fields of preset ``name`` for a run at ``confining`` [Pa] (its stress
    floor is a fraction of it); ``with_discs``: the discs per prepared RVE too (not for a
    run of an RVE file, whose discs are the file's)."""
    settings = load_presets()[name].settings()
    if not with_discs:
        settings.pop("discs")
    return settings_fields(settings, confining)
