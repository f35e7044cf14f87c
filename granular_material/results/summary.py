"""Key figures of the runs, as the commands report them (the JSON summary)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import pandas as pd

from granular_material.results.active_bands import active_bands
from granular_material.results.bands import find_bands
from granular_material.results.biaxial import COST_COLUMNS
from granular_material.results.localization import mohr_coulomb_inclination, shear_band
from granular_material.results.peaks import find_peak

if TYPE_CHECKING:
    from granular_material.results.biaxial import BiaxialResult

__all__ = ["BiaxialSummary", "band_summary", "run_summary", "summarize_biaxial"]


@dataclass(frozen=True)
class BiaxialSummary:
    """Key figures of one RVE's biaxial curve (volumetric strain tension positive)."""

    peak_stress_ratio: float
    axial_strain_at_peak: float
    max_contraction: float
    final_void_ratio: float


def summarize_biaxial(curve: pd.DataFrame) -> BiaxialSummary:
    """Peak σ1/σ3 and its axial strain, the most negative εv, the last void ratio of one
    RVE's curve of :func:`~granular_material.procedures.biaxial_test`."""
    peak, ratio = find_peak(curve["axial_strain"].to_numpy(), curve["stress_ratio"].to_numpy())
    return BiaxialSummary(
        peak_stress_ratio=ratio,
        axial_strain_at_peak=float(curve["axial_strain"].iloc[peak]),
        max_contraction=float(curve["volumetric_strain"].min()),
        final_void_ratio=float(curve["void_ratio"].iloc[-1]),
    )


def run_summary(result: BiaxialResult, wall: float) -> dict[str, Any]:
    """The summary of a FEM biaxial run: peak, Newton cost, the material's costs (each cost
    column of :data:`~granular_material.results.biaxial.COST_COLUMNS` summed over the steps), the
    failed point-evaluations by reason (``failed_points``, e.g. ``{"max_dem_steps": 4}``:
    points whose evaluation failed and cut an increment back, the step that stopped the run
    included; empty when none failed), wall time [s], error."""
    steps = result.steps
    peak, ratio = find_peak(steps["axial_strain"].to_numpy(), steps["stress_ratio"].to_numpy())
    done = steps[steps["step"] > 0]
    return {
        "peak_stress_ratio": ratio,
        "axial_strain_at_peak": float(steps["axial_strain"].iloc[peak]),
        "newton_iterations_mean": float(done["iterations"].mean()) if len(done) else math.nan,
        "sxx": float(steps["sxx"].iloc[-1]),
        "syy": float(steps["syy"].iloc[-1]),
        "final_axial_strain": float(steps["axial_strain"].iloc[-1]),
        "steps_completed": len(done),
        "cutbacks": int(done["cutbacks"].sum()),
        "stalled_increments": int(done["stalled"].sum()),
        "failed_points": dict(getattr(result, "failures", {})),
        **{name: int(done[name].sum()) for name in COST_COLUMNS},
        "wall_time_s": wall,
        "error": result.error,
    }


def band_summary(result: BiaxialResult, map_strains: Sequence[float],
                 peak_ratio: float) -> dict[str, Any]:
    """Shear-band measures at the map strains and at the last step (see
    :mod:`granular_material.results.localization`), and the straight bands of the last step
    (:func:`~granular_material.results.bands.find_bands`): ``bands_final`` (each band's
    measures, strongest first; empty where there is none) and ``band_width`` (the strongest
    band's full width at half maximum of γ across it [m]; NaN where there is no band); and
    the bands active over the last fifth of the axial strain
    (:func:`~granular_material.results.active_bands.active_bands`, Gaussian ridges fitted to
    the shear strain of that increment, which also measures a band as wide as a third of
    the specimen): ``active_bands`` (each one's measures, highest first) and
    ``active_band_width`` (their mean full width at half maximum [m]; NaN where there is
    none)."""
    steps = result.steps
    if len(steps) < 2:
        return {}
    rows = sorted({result.row_nearest(e) for e in map_strains})
    bands = find_bands(result.points)
    active = active_bands(result.points)
    return {
        "shear_bands": [shear_band(result.points, int(steps["step"].iloc[r])).as_dict()
                        for r in rows],
        "shear_band_final": shear_band(result.points).as_dict(),
        "mohr_coulomb_inclination_deg": mohr_coulomb_inclination(max(peak_ratio, 1.0)),
        "band_width": bands[0].width if bands else math.nan,
        "bands_final": [band.as_dict() for band in bands],
        "active_band_width": (sum(band.width for band in active) / len(active) if active
                              else math.nan),
        "active_bands": [band.as_dict() for band in active],
    }
