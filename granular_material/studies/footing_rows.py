"""The trade study's footing rows: Guo & Zhao's reduced strip footing
(``examples/scenes/footing-gz2016-cpu.toml``) under the settings that matter there, scored by
what a designer reads off it: the bearing pressure at s/B = 0.05 and 0.1, the peak and where
it comes, and the extent of the mechanism; the Mohr–Coulomb twin (the RVE material's
calibration at the surcharge, ``docs/validation/mohr-coulomb``) as the cheapest row.

A row is a variant of the scene: changes to its ``[material.parameters]`` and ``[newton]``
tables, or another material. Each runs once into ``footing/<name>/`` (done once its run
has ended there; an interrupted one continues).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.results import read_points
from granular_material.runs.boundary_value.runner import run_boundary_value
from granular_material.runs.boundary_value.spec import bvp_from_dict
from granular_material.runs.presets import settings_fields
from granular_material.runs.run_folder import ended_summary, resumable
from granular_material.studies.band import command_settings, row_key

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

__all__ = ["FOOTING_BUDGETS", "FOOTING_SCALES", "FOOTING_SCENE", "MECHANISM_FRACTION",
           "MOHR_COULOMB_TWIN", "FootingRow", "FootingScale", "footing_measures",
           "footing_rows", "footing_table", "half_width", "keeps_footing", "preset_footing_row",
           "run_footing_rows"]

#: the reduced footing scene, as the package installs it (``examples/scenes`` of a checkout)
FOOTING_SCENE = Path(str(files("granular_material_examples") / "scenes"
                         / "footing-gz2016-cpu.toml"))
#: the mechanism: the Gauss points whose shear strain is at least this fraction of the
#: largest at s/B = 0.1
MECHANISM_FRACTION = 0.25
#: each preset's footing budget: the largest error of the bearing pressure at s/B = 0.05 and
#: at 0.1 [%] against the scene's own settings (the same packing; another packing moves them
#: by 12 and 20 %: the ``seed`` row)
FOOTING_BUDGETS: dict[str, dict[str, float]] = {
    "quick": {"q_0.05_pct": 20.0, "q_0.1_pct": 30.0},
    "engineering": {"q_0.05_pct": 10.0, "q_0.1_pct": 15.0},
}

#: the Mohr–Coulomb twin of the footing's RVE material: the calibration of 4 RVEs of 64
#: discs at 20 kPa (docs/validation/mohr-coulomb, "gz20k": E, ν, and the critical-state
#: angle φcs the DEM footing's load follows), perfectly plastic, small strain
MOHR_COULOMB_TWIN = {"young": 19.04e6, "poisson": 0.254, "friction_angle": 22.35,
                     "dilation_angle": 0.0}


@dataclass(frozen=True)
class FootingScale:
    """The footing rows' size (``--scale``): the scene's load steps (its footing moved the
    same 0.25 mm a step, so fewer steps reach less settlement), discs per RVE and mesh
    (elements across and down); None: the scene's."""

    name: str
    steps: int | None = None
    discs: int | None = None
    elements: tuple[int, int] | None = None


FOOTING_SCALES = {"smoke": FootingScale("smoke", steps=3, discs=16, elements=(4, 3)),
                  "cpu": FootingScale("cpu")}


@dataclass(frozen=True)
class FootingRow:
    """One variant of the footing scene: its knob and value, the changes to the scene's
    ``[material.parameters]`` and ``[newton]`` tables, another material (name and
    parameters) where it has one, and an ``[adaptivity]`` table where it has one (the
    twin where the soil has not yielded, DEM where it has)."""

    knob: str
    value: str
    parameters: dict[str, Any] = field(default_factory=dict)
    newton: dict[str, Any] = field(default_factory=dict)
    material: tuple[str, dict[str, Any]] | None = None
    adaptivity: dict[str, Any] | None = None

    @property
    def key(self) -> str:
        """The row's folder name (:func:`~granular_material.studies.band.row_key` of its
        changes)."""
        return row_key(self.knob, self.value, [self.parameters, self.newton])


def footing_rows() -> list[FootingRow]:
    """The knobs' rows: the scene as written (the reference), another packing (the scatter
    between RVEs), the force test and the force test with reuse (what issue 44 measured),
    the band rows' knobs (the RVEs' drive continued, a coarser strain per DEM step, no
    relaxation, a looser displacement test), the Mohr–Coulomb twin, and adaptivity with its
    defaults (the twin calibrated from the scene's RVE, DEM where it is no longer trusted)."""
    return [FootingRow("reference", "scene"),
            FootingRow("seed", "2", {"seed": 2}),
            FootingRow("convergence", "force", newton={"convergence": "force"}),
            FootingRow("reuse_tol", "1e-5 with force test", {"reuse_tol": 1e-5},
                       {"convergence": "force"}),
            FootingRow("drive", "continue", {"drive": "continue"}),
            FootingRow("strain_per_step", "3e-5", {"max_strain_per_step": 3e-5}),
            FootingRow("relaxation", "none", newton={"relaxation": "none"}),
            FootingRow("convergence", "residual-displacement 3e-2", newton={"rtol": 3e-2}),
            FootingRow("material", "mohr-coulomb twin",
                       material=("mohr-coulomb", dict(MOHR_COULOMB_TWIN)),
                       newton={"formulation": "small-strain"}),
            FootingRow("adaptivity", "defaults", adaptivity={})]


def preset_footing_row(name: str, settings: dict[str, Any]) -> FootingRow | None:
    """A preset's footing row: its settings (the study's terms) as changes of the scene
    (:func:`_preset_tables`); None where it changes nothing (its footing is the
    reference's)."""
    parameters, newton = _preset_tables(settings)
    return FootingRow("preset", name, parameters, newton) if parameters or newton else None


#: the footing scene's ``[material.parameters]`` among a preset's run-spec fields (the others
#: are its ``[newton]`` table's)
_MATERIAL_FIELDS = ("max_strain_per_step", "drive", "reuse_tol")


def _preset_tables(values: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """A preset's settings as the footing scene's material and Newton tables, only where
    they change the scene (its tangent, the Kruyt–Rothenburg one, stays: the footing's own
    choice; the discs stay the scene's); the force test with all its settings (its
    tolerance, its floor of the surcharge, its iterations: ``settings_fields``)."""
    defaults = command_settings()
    changed = {key: value for key, value in values.items()
               if key not in ("discs", "tangent", "tangent_update")
               and (value != defaults[key] or (values["convergence"] == "force"
                                               and key in ("convergence", "rtol",
                                                           "stress_floor")))}
    fields = settings_fields(changed, _surcharge())
    return ({k: v for k, v in fields.items() if k in _MATERIAL_FIELDS},
            {k: v for k, v in fields.items() if k not in _MATERIAL_FIELDS})


def half_width(scene: dict[str, Any] | None = None) -> float:
    """The footing's half-width b [m] from its boundary predicate (``x <= b``)."""
    predicate = (scene or _scene())["boundaries"]["footing"]
    return float(predicate.split("<=")[-1])


def _surcharge() -> float:
    """The footing scene's initial pressure [Pa] (the presets' stress floor is a fraction
    of it)."""
    return float(_scene()["initial"]["pressure"])


def _scene() -> dict[str, Any]:
    return tomllib.loads(FOOTING_SCENE.read_text(encoding="utf-8"))


def _scene_of(row: FootingRow, scale: FootingScale) -> dict[str, Any]:
    """The footing scene at ``scale`` with ``row``'s changes, its progress bars and fields
    off."""
    data = _scene()
    if scale.steps is not None:
        for condition in data.get("conditions", []):
            if "displacement" in condition:
                condition["displacement"] = [scale.steps / data["steps"] * v
                                             for v in condition["displacement"]]
        data["steps"] = scale.steps
    if scale.elements is not None:
        data["mesh"]["elements"] = list(scale.elements)
    if scale.discs is not None:
        data["material"]["parameters"]["particles"] = scale.discs
    if row.material is not None:
        name, parameters = row.material
        data["material"] = {"name": name, "parameters": dict(parameters)}
    else:
        data["material"].setdefault("parameters", {}).update(row.parameters)
    data.setdefault("newton", {}).update(row.newton)
    if row.adaptivity is not None:
        data["adaptivity"] = dict(row.adaptivity)
    data.setdefault("output", {}).update(progress=False, fields=False)
    return data


def run_footing_rows(rows: list[FootingRow], scale: FootingScale, out: Path,
                     log: Any = lambda _: None) -> None:
    """Run every row not yet done, at ``scale``, into ``out / "footing" / row.key``."""
    for row in rows:
        folder = out / "footing" / row.key
        if ended_summary(folder) is not None:
            continue
        run_boundary_value(bvp_from_dict(_scene_of(row, scale), FOOTING_SCENE.parent), out=folder,
                           resume=resumable(folder))
        log(f"footing/{row.key}: done")


def footing_measures(steps: pd.DataFrame, points: pd.DataFrame,
                     half_width: float) -> dict[str, float]:
    """The bearing pressure q = −F_y / b [kPa] at s/B = 0.05 and 0.1 (B = 2b), its peak and
    the settlement there [mm], and the mechanism at s/B = 0.1: the farthest reach from the
    footing's centre line and the depth below the surface of the points whose shear strain
    is at least :data:`MECHANISM_FRACTION` of the largest, in B (NaN where the run ended
    before)."""
    width = 2 * half_width
    q = -steps["footing_force_y"].to_numpy(float) / half_width / 1e3
    s = steps["footing_settlement"].to_numpy(float)
    measures: dict[str, float] = {}
    for ratio in (0.05, 0.1):
        measures[f"q_{ratio:g}"] = (float(np.interp(ratio * width, s, q))
                                    if s.max() >= ratio * width * (1 - 1e-9) else math.nan)
    peak = int(np.argmax(q))
    measures.update({"q_peak": float(q[peak]), "s_peak_mm": 1e3 * float(s[peak])})
    target = int(np.argmin(np.abs(s - 0.1 * width)))
    at = points[points["step"] == int(steps["step"].iloc[target])]
    gamma = at["shear_strain"].to_numpy(float)
    if gamma.size and s.max() >= 0.1 * width * (1 - 1e-9) and gamma.max() > 0:
        inside = at[gamma >= MECHANISM_FRACTION * gamma.max()]
        surface = float(points["y"].max())
        measures["mechanism_reach_B"] = float(inside["x"].max()) / width
        measures["mechanism_depth_B"] = (surface - float(inside["y"].min())) / width
    else:
        measures["mechanism_reach_B"] = measures["mechanism_depth_B"] = math.nan
    return measures


def keeps_footing(line: pd.Series, budget: dict[str, float]) -> bool:
    """Whether a row of :func:`footing_table` keeps a preset's footing ``budget``: it ran to
    its end and its bearing pressures are within the budget's per cent."""
    return line["error"] == "" and all(abs(line[column]) <= limit
                                       for column, limit in budget.items())


def footing_table(rows: list[FootingRow], out: Path, b: float) -> pd.DataFrame:
    """One line per done row: its measures, their errors against the reference [%], its
    cost (DEM particle-steps over the reference's; Newton iterations a step; wall time)."""
    lines = []
    for row in rows:
        folder = out / "footing" / row.key
        summary = ended_summary(folder)
        if summary is None:
            continue
        steps = pd.read_csv(folder / "steps.csv")
        points = read_points(folder)
        done = steps[steps["step"] > 0]
        lines.append({"knob": row.knob, "value": row.value,
                      **footing_measures(steps, points, b),
                      "steps": len(done), "iterations_per_step": float(done["iterations"].mean()),
                      "particle_steps": float(done["particle_steps"].sum())
                      if "particle_steps" in done else 0.0,
                      "wall_s": float(summary.get("wall_s", math.nan)),
                      "error": summary.get("error") or ""})
    table = pd.DataFrame(lines)
    if table.empty or "reference" not in set(table["knob"]):
        return table
    ref = table[table["knob"] == "reference"].iloc[0]
    for column in ("q_0.05", "q_0.1", "q_peak"):
        table[f"{column}_pct"] = 100 * (table[column] / ref[column] - 1)
    return table.assign(cost_ratio=table["particle_steps"] / ref["particle_steps"])
