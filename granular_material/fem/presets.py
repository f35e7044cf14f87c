"""Named settings of the FEM × DEM commands, chosen by the trade study from measurements.

``presets.json`` beside this module is the ``presets.json`` of the committed CPU trade study
(``docs/trade-study/``, whose ``report.md`` gives each preset's measured error and cost); a
test keeps the two the same. ``quick``, ``engineering`` and ``publication`` differ in the
discs per RVE, the strain per DEM step, the Newton stress floor, the tangent, predictor and
relaxation and the reuse of undisturbed RVEs: the knobs the study found to trade speed for
accuracy (see :func:`granular_material.studies.trade.recommend` for the rule).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path

__all__ = ["PRESETS_FILE", "Preset", "load_presets", "tangent_settings"]

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
        tangent: a material tangent (objective, kruyt-rothenburg, perturbation,
            condensed), "secant" (the objective tangent with Broyden updates) or
            "<tangent>-hold" (held over each increment): :func:`tangent_settings`.
        acceleration: "predictor/relaxation", e.g. "extrapolate/aitken".
        reuse_tol: reuse tolerance of undisturbed RVEs [-].
    """

    name: str
    discs: int
    strain_per_step: float
    rtol: float
    stress_floor: float
    tangent: str
    acceleration: str
    reuse_tol: float


def tangent_settings(value: str) -> dict[str, str]:
    """The material tangent and Newton's tangent update of a tangent knob ``value`` of the
    trade study and the presets: "secant" is the objective tangent with Broyden updates,
    "<tangent>-hold" that tangent held over each increment, any other the material tangent
    of every iterate."""
    if value == "secant":
        return {"tangent": "objective", "tangent_update": "secant"}
    if value.endswith("-hold"):
        return {"tangent": value.removesuffix("-hold"), "tangent_update": "hold"}
    return {"tangent": value, "tangent_update": "none"}


@cache
def load_presets() -> dict[str, Preset]:
    """The presets of :data:`PRESETS_FILE`, by name."""
    saved = json.loads(PRESETS_FILE.read_text())
    return {name: Preset(name=name, **values) for name, values in saved.items()}
