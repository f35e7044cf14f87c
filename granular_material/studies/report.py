"""What the trade study reports: ``report.md`` (the reference, a table per knob, the presets
measured) and ``presets.json`` (the presets as the commands read them)."""

from __future__ import annotations

import json
import math
from typing import Any

import pandas as pd

from granular_material.results.compare import markdown_table
from granular_material.runs.presets import SETTING_NAMES
from granular_material.studies.plan import (
    NOISE,
    SPECIMEN_NEWTON,
    Knob,
    StudyScale,
    _reference,
    knobs,
)
from granular_material.studies.scoring import PRESETS, accuracy

__all__ = ["presets_file", "report"]


def presets_file(presets: dict[str, dict[str, Any]]) -> str:
    """``presets.json``: each preset's settings in the order of
    :data:`~granular_material.runs.presets.SETTING_NAMES`, the fields of
    :class:`~granular_material.runs.presets.Preset`."""
    entries = {name: {field: values[field] for field in SETTING_NAMES}
               for name, values in presets.items()}
    return json.dumps(entries, indent=2) + "\n"


def report(table: pd.DataFrame, presets: dict[str, dict[str, Any]], scale: StudyScale,
           device: str, commit: str) -> str:
    """``report.md``: the reference, a table per knob, the presets measured."""
    ref = _reference(scale)
    lines = [
        f"# Speed against accuracy: trade study ({scale.name})", "",
        f"Device {device}; report written at commit {commit} (the commit each row was "
        "measured at is its `commit` in trade.csv). Drained biaxial tests to axial strain "
        f"{scale.axial_strain:g} at p0 = {scale.confining:g} Pa; seeds "
        f"{', '.join(map(str, scale.seeds))}.", "",
        "Reference settings: " + ", ".join(f"{k} = {v}" for k, v in ref.items())
        + f"; pure DEM: {scale.base_discs} discs (discs knob: {max(scale.discs)} discs, "
        f"mean of the seeds); single element: {scale.element_discs} discs, "
        f"{scale.element_steps} load steps; specimens: {scale.mesh_discs} discs, "
        f"{scale.mesh_steps} load steps, Newton's force test looser than the reference's "
        f"({', '.join(f'{k} = {v:g}' for k, v in SPECIMEN_NEWTON.items())}), reference mesh "
        "the finest. Every run's wall time was measured on a machine shared with other work: "
        "the DEM particle-steps are the cost that does not depend on its load. `cost` adds "
        "the tangent's own work in the same unit: a FEM run's particle-steps times its "
        "material's seconds (DEM, homogenisation, tangent) over its DEM seconds, both timed "
        "in that run.", "",
        "Errors (%, relative to the reference's peak σ1/σ3): `peak` = |peak σ1/σ3 − "
        "reference|, `rms` = RMS of the σ1/σ3 difference, `εv rms` relative to the "
        "reference's largest |εv|; pure-DEM errors are means over the seeds of each seed "
        "against the same seed at the reference (discs: against the seeds' mean curve at "
        "the largest size). `accuracy` = |peak|, the measure the presets use; the `noise` rows "
        f"(disc positions moved by {NOISE:g} of a radius, nothing else changed) show how far "
        "round-off alone carries a run: RMS differences at that level are chaos, not the "
        "knob.", "",
        "![Pareto](pareto.png)", "",
    ]
    columns = {"value": "value", "peak_error_pct": "peak %", "stress_ratio_rms_pct": "rms %",
               "volumetric_strain_rms_pct": "εv rms %", "peak_strain_error_pct": "Δε peak %",
               "seed_scatter_pct": "seed scatter %", "inertial_number": "I",
               "band_inclination_deg": "band °", "wall_s": "wall s",
               "particle_steps": "particle-steps",
               "cost_particle_steps": "cost (particle-steps)", "newton_iterations": "iterations",
               "error": "error"}
    shown_knobs = {k.name: k for k in knobs(scale)}  # one section per name
    for knob in [*shown_knobs.values(), Knob("preset", "", tuple(PRESETS), "publication")]:
        rows = table[table["knob"] == knob.name]
        if rows.empty:
            continue
        shown = rows.assign(accuracy=accuracy(rows))
        keep = ["test", *[c for c in columns if c in shown and shown[c].notna().any()
                          and (c != "error" or (shown[c].fillna("") != "").any())],
                "accuracy"]
        lines += [f"## {knob.name}" + (f" (reference {knob.reference})"
                                       if knob.name != "preset" else ""), "",
                  markdown_table(shown[keep].rename(columns=columns))]
        if knob.name != "preset":
            lines += [f"![{knob.name}](knob_{knob.name}.png)", ""]
    lines += ["## Recommended settings", "",
              "Rule (`granular_material.studies.scoring.recommend`): the discs, the strain per "
              "DEM step and the reuse tolerance take the value of the least `cost` (DEM "
              "particle-steps, the tangent's work included) whose peak accuracy is within the "
              "preset's budget (the reference on a tie) "
              f"({', '.join(f'{k}: {v:g} %' for k, v in PRESETS.items() if v is not None)}); "
              "Newton's test, tangent, relaxation and drive are the commands' defaults, each "
              "changed only where a band row (below) of that knob keeps the preset's band "
              "budget for clearly less work and the footing row of the same setting, where "
              "there is one, its footing budget; a strain per DEM step that breaks a budget "
              "is replaced by the largest that keeps it. A preset whose combination breaks a "
              "budget takes the Newton settings of a stricter preset that kept its own, else "
              "the commands'. Publication is the commands' defaults with the most discs and "
              "the finest strain per DEM step. Each preset then ran itself (rows `preset` "
              "above: pure DEM and single element; below: the band specimen and the "
              "footing).", ""]
    preset_rows = []
    for name, values in presets.items():
        measured = table[(table["knob"] == "preset") & (table["value"] == name)]
        cost = {t: measured[measured["test"] == t] for t in ("dem", "element")}
        preset_rows.append({"preset": name, **{k: str(v) for k, v in values.items()},
                            **{f"{t} accuracy %": float(accuracy(c).iloc[0]) if len(c)
                               else math.nan for t, c in cost.items()},
                            **{f"{t} wall s": float(c["wall_s"].iloc[0]) if len(c)
                               else math.nan for t, c in cost.items()}})
    lines.append(markdown_table(pd.DataFrame(preset_rows)))
    return "\n".join(lines)
