"""The presets measured past the peak: each preset with a budget runs on the band specimen
and the reduced footing, and one whose combination of settings breaks a budget (each
setting kept it alone; together they did not) takes the Newton settings of a stricter
preset that kept its own budgets (else the commands') and runs again. The presets in
force when the study began run beside them, where they differ, so that the report shows
what changed."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import pandas as pd

from granular_material.runs.presets import load_presets
from granular_material.studies.band import (
    BandRow,
    BandScale,
    command_settings,
    preset_band_row,
    run_band_rows,
)
from granular_material.studies.band_scoring import (
    BAND_BUDGETS,
    band_table,
    keeps_band,
    run_measures,
)
from granular_material.studies.footing_rows import (
    FOOTING_BUDGETS,
    FootingRow,
    FootingScale,
    footing_table,
    half_width,
    keeps_footing,
    preset_footing_row,
    run_footing_rows,
)

__all__ = ["check_presets"]


def check_presets(presets: dict[str, dict[str, Any]], band: list[BandRow],
                  footing: list[FootingRow], band_scale: BandScale,
                  footing_scale: FootingScale, out: Path, device: str, jobs: int,
                  progress: bool, log: Callable[[str], None]
                  ) -> tuple[dict[str, dict[str, Any]], list[BandRow], list[FootingRow]]:
    """Run the presets' band and footing rows (and those of the presets in force, where
    they differ); a preset that breaks its band or footing budget takes the Newton
    settings of :func:`_fallback` and runs again. Returns the presets and every band and
    footing row."""
    presets = {name: dict(values) for name, values in presets.items()}
    band, footing = list(band), list(footing)
    new_band, new_footing = _preset_rows(presets, band_scale, in_force=True)
    band, footing = band + new_band, footing + new_footing
    _run(new_band, new_footing, band_scale, footing_scale, out, device, jobs, progress, log)
    bands = band_table(run_measures(out, band, band_scale), band_scale)
    footings = footing_table(footing, out, half_width())
    for name in BAND_BUDGETS:
        if _keeps(name, bands, footings):
            continue
        fallback = _fallback(name, presets, bands, footings)
        if all(presets[name][k] == v for k, v in fallback.items()):
            continue
        log(f"preset {name} breaks its budget past the peak; it takes the Newton settings "
            "of a stricter preset that kept its own, else the commands'")
        band = [replace(r, value=f"{name} (first choice)")
                if r.knob == "preset" and r.value == name else r for r in band]
        footing = [replace(r, value=f"{name} (first choice)")
                   if r.knob == "preset" and r.value == name else r for r in footing]
        presets[name] = {**presets[name], **fallback}
        new_band, new_footing = _preset_rows({name: presets[name]}, band_scale,
                                             in_force=False)
        band, footing = band + new_band, footing + new_footing
        _run(new_band, new_footing, band_scale, footing_scale, out, device, jobs, progress,
             log)
    return presets, band, footing


#: the settings a fallback replaces: Newton's (the strain per DEM step and the discs stay the
#: preset's own, each kept its budgets alone)
_NEWTON = ("convergence", "rtol", "stress_floor", "tangent", "tangent_update", "acceleration",
           "drive", "reuse_tol")


def _fallback(name: str, presets: dict[str, dict[str, Any]], bands: pd.DataFrame,
              footings: pd.DataFrame) -> dict[str, Any]:
    """Newton's settings of the first preset whose budgets are all at most ``name``'s and
    which kept them (its settings then keep ``name``'s too: the band and footing rows run
    without the discs), else the commands' own."""
    for other in BAND_BUDGETS:
        stricter = other != name and all(
            budgets[other][k] <= budgets[name][k]
            for budgets in (BAND_BUDGETS, FOOTING_BUDGETS) for k in budgets[name])
        if stricter and presets[other]["strain_per_step"] == presets[name]["strain_per_step"] \
                and _keeps(other, bands, footings):
            return {k: presets[other][k] for k in _NEWTON}
    defaults = command_settings()
    return {k: defaults[k] for k in _NEWTON}


def _keeps(name: str, bands: pd.DataFrame, footings: pd.DataFrame) -> bool:
    """Whether preset ``name``'s rows keep its budgets (a preset without a footing row
    changes nothing of the footing's scene: it keeps the footing's)."""
    line = bands[(bands["knob"] == "preset") & (bands["value"] == name)]
    if line.empty or not keeps_band(line.iloc[0], BAND_BUDGETS[name]):
        return False
    row = footings[(footings["knob"] == "preset") & (footings["value"] == name)] \
        if not footings.empty else footings
    return row.empty or keeps_footing(row.iloc[0], FOOTING_BUDGETS[name])


def _preset_rows(presets: dict[str, dict[str, Any]], band_scale: BandScale, in_force: bool
                 ) -> tuple[list[BandRow], list[FootingRow]]:
    """The band and footing rows of ``presets`` with a budget (``in_force``: and of the
    presets in force, where they differ)."""
    named = {name: values for name, values in presets.items() if name in BAND_BUDGETS}
    if in_force:
        for name, preset in load_presets().items():
            if name in named and preset.settings() != presets[name]:
                named[f"{name} (in force)"] = preset.settings()
    band = [preset_band_row(name, values, band_scale) for name, values in named.items()]
    footing = [row for name, values in named.items()
               if (row := preset_footing_row(name, values)) is not None]
    return band, footing


def _run(band: list[BandRow], footing: list[FootingRow], band_scale: BandScale,
         footing_scale: FootingScale, out: Path, device: str, jobs: int, progress: bool,
         log: Callable[[str], None]) -> None:
    """Run ``band`` and ``footing`` rows not yet done."""
    run_band_rows(band, band_scale, out, device, jobs, progress, log)
    run_footing_rows(footing, footing_scale, out, log)
