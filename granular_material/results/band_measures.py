"""What a biaxial specimen does past its peak, as numbers a run can be scored by: when its
shear band forms, how sharp it is, where it lies, how much the specimen softens and dilates.

The peak σ1/σ3 is the least sensitive thing a multiscale run gives; two runs with the same
peak can differ in whether a band forms at all. These measures read a run's ``steps`` table
(axial_strain, stress_ratio, volumetric_strain) and its Gauss-point ``points`` table (step,
axial_strain, x, y, shear_strain) at every load step:

- the localisation ratio γmax/γmean of the points' shear strain at each step, and at the
  :data:`MEASURE_STRAINS`;
- the band's onset: the axial strain at which that ratio first reaches
  :data:`ONSET_RATIO` (linear between steps; NaN when it never does);
- the band's inclination [°] and where its axis crosses the specimen's mid-height, at the
  last step (from :func:`~granular_material.results.localization.shear_band`);
- the straight bands at the last step, each with its own inclination (from
  :func:`~granular_material.results.bands.find_bands`): how many, the two strongest ones'
  inclinations, and the strongest one's width in metres;
- the bands active over the last fifth of the run's axial strain (from
  :func:`~granular_material.results.active_bands.active_bands`: Gaussian ridges fitted to
  the shear strain of that increment): how many, and their mean width in metres;
- σ1/σ3 and the volumetric strain at :data:`SOFTENING_STRAINS`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from granular_material.results.active_bands import active_bands
from granular_material.results.bands import find_bands
from granular_material.results.localization import shear_band

__all__ = ["MEASURE_STRAINS", "ONSET_RATIO", "SOFTENING_STRAINS", "band_measures",
           "band_onset", "localisation_history", "value_at"]

#: γmax/γmean at which a band is said to have formed [-]: a uniform specimen stays near 1.1–1.3
#: (the RVEs' own scatter); Guo & Zhao's band and Wu et al.'s specimen pass 2 within a few
#: tenths of a per cent of axial strain once the band runs across the specimen
ONSET_RATIO = 2.0
#: the axial strains at which γmax/γmean is reported [-]
MEASURE_STRAINS = (0.02, 0.03, 0.05, 0.10)
#: the axial strains at which σ1/σ3 and εv are reported [-]
SOFTENING_STRAINS = (0.05, 0.10)


def localisation_history(points: pd.DataFrame) -> pd.DataFrame:
    """γmax/γmean of the Gauss points' shear strain at every step of ``points``: columns
    step, axial_strain, ratio (1 where every γ is zero, as at step 0)."""
    missing = {"step", "axial_strain", "shear_strain"} - set(points.columns)
    if missing:
        raise ValueError(f"points table lacks columns {sorted(missing)}")
    grouped = points.groupby("step", sort=True)
    gamma = grouped["shear_strain"]
    mean, largest = gamma.mean(), gamma.max()
    ratio = np.where(mean.to_numpy() > 0, largest.to_numpy() / np.where(
        mean.to_numpy() > 0, mean.to_numpy(), 1.0), 1.0)
    return pd.DataFrame({"step": mean.index.to_numpy(),
                         "axial_strain": grouped["axial_strain"].first().to_numpy(),
                         "ratio": ratio})


def band_onset(history: pd.DataFrame, threshold: float = ONSET_RATIO) -> float:
    """The axial strain [-] at which ``history``'s ratio (:func:`localisation_history`)
    first reaches ``threshold``, linear between the two steps around it; NaN when it
    never does."""
    strain = history["axial_strain"].to_numpy(dtype=float)
    ratio = history["ratio"].to_numpy(dtype=float)
    above = np.flatnonzero(ratio >= threshold)
    if above.size == 0:
        return math.nan
    i = int(above[0])
    if i == 0:
        return float(strain[0])
    r0, r1 = ratio[i - 1], ratio[i]
    return float(strain[i - 1] + (threshold - r0) / (r1 - r0) * (strain[i] - strain[i - 1]))


def value_at(strain: np.ndarray, values: np.ndarray, target: float) -> float:
    """``values`` at axial strain ``target`` [-] of a run's ``strain`` [-] (linear between
    steps; NaN beyond the run's last strain)."""
    if strain.size == 0 or target > strain.max() * (1 + 1e-9):
        return math.nan
    return float(np.interp(target, strain, values))


def band_measures(steps: pd.DataFrame, points: pd.DataFrame, height: float,
                  width: float | None = None, threshold: float = ONSET_RATIO,
                  strains: Sequence[float] = MEASURE_STRAINS,
                  softening: Sequence[float] = SOFTENING_STRAINS) -> dict[str, Any]:
    """The measures of one biaxial run (see the module docstring) as a flat dict.

    Args:
        steps: the run's steps table (axial_strain, stress_ratio, volumetric_strain).
        points: its Gauss-point table at every step.
        height: the specimen's height [m] (its bottom at y = 0): the band's crossing is
            taken at ``height / 2``.
        width: its width [m] (its left side at x = 0): a crossing outside is NaN; None: not
            checked.
        threshold: γmax/γmean of the onset.
        strains: where γmax/γmean is reported [-]; softening: where σ1/σ3 and εv are.

    Keys: ``onset`` [-], ``ratio_<e>`` (e in per cent), ``inclination_deg`` (the band's
    angle to the x axis at the last step, 0–90°, its sign dropped), ``crossing_x`` [m]
    (where its axis crosses mid-height; NaN where that is outside the specimen),
    ``elongation`` (1 for one straight band, near 0 for a cross of two: then the
    inclination means little), ``localization`` (its mean γ inside over outside),
    ``stress_ratio_<e>``, ``volumetric_strain_<e>``; ``band_width`` [m] (the full width at
    half maximum of the shear-strain profile across the strongest straight band at the last
    step, the band of the largest line integral of γ above the background; NaN where there
    is no band), ``band_count`` (the straight bands found there, each with its own
    inclination: 1 for one band, 2 for a cross, 0 for none), ``band_1_inclination_deg`` and
    ``band_2_inclination_deg`` (the two strongest bands' angles to the x axis, signed, in
    (−90, 90], positive rising to the right; NaN where there are fewer);
    ``active_band_width`` [m] (the mean full width at half maximum of the bands active over
    the last :data:`~granular_material.results.active_bands.INCREMENT_SHARE` of the run's
    axial strain, Gaussian ridges fitted to the shear strain of that increment; NaN where
    there is none or the points carry no strain) and ``active_band_count``.
    """
    history = localisation_history(points)
    strain = history["axial_strain"].to_numpy(dtype=float)
    measures: dict[str, Any] = {"onset": band_onset(history, threshold)}
    for e in strains:
        measures[f"ratio_{100 * e:g}"] = value_at(strain, history["ratio"].to_numpy(), e)
    band = shear_band(points)
    angle = math.radians(band.inclination_deg)
    crossing = (band.centre_x + (height / 2 - band.centre_y) / math.tan(angle)
                if abs(math.tan(angle)) > 1e-9 else math.nan)
    if width is not None and not 0.0 <= crossing <= width:
        crossing = math.nan  # the band's axis leaves the specimen before mid-height
    measures.update({"inclination_deg": abs(band.inclination_deg), "crossing_x": crossing,
                     "elongation": band.elongation, "localization": band.localization})
    bands = find_bands(points)
    inclinations = [b.inclination_deg for b in bands[:2]] + [math.nan] * 2
    measures.update({"band_width": bands[0].width if bands else math.nan,
                     "band_count": len(bands), "band_1_inclination_deg": inclinations[0],
                     "band_2_inclination_deg": inclinations[1]})
    active = active_bands(points)
    measures.update({"active_band_width": (float(np.mean([b.width for b in active]))
                                           if active else math.nan),
                     "active_band_count": len(active)})
    run_strain = steps["axial_strain"].to_numpy(dtype=float)
    for e in softening:
        measures[f"stress_ratio_{100 * e:g}"] = value_at(
            run_strain, steps["stress_ratio"].to_numpy(dtype=float), e)
        measures[f"volumetric_strain_{100 * e:g}"] = value_at(
            run_strain, steps["volumetric_strain"].to_numpy(dtype=float), e)
    return measures
