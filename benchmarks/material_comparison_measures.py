"""The measures of ``benchmarks/material_comparison.py``: Prandtl's N_q, the band angles of
Coulomb, Roscoe and Arthur, the localisation series of a Gauss-point table, a footing's
bearing curve and a calibrated material file. Pure functions, shared by the study and its
report (``material_comparison_report.py``), neither of which the other imports for them."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

#: γmax/γmean [-] above which a specimen counts as localised
LOCALISED = 2.0


def prandtl_nq(phi_deg: float) -> float:
    """Prandtl's bearing capacity factor N_q = e^(π tan φ) tan²(45° + φ/2) of φ [deg]."""
    phi = math.radians(phi_deg)
    return math.exp(math.pi * math.tan(phi)) * math.tan(math.pi / 4 + phi / 2) ** 2


def band_angles(phi_deg: float, psi_deg: float) -> dict[str, float]:
    """Shear-band inclinations [deg] to the minor principal stress direction: Coulomb
    45° + φ/2, Roscoe 45° + ψ/2, Arthur 45° + (φ + ψ)/4."""
    return {"coulomb": 45 + phi_deg / 2, "roscoe": 45 + psi_deg / 2,
            "arthur": 45 + (phi_deg + psi_deg) / 4}


def localisation_series(points: pd.DataFrame) -> pd.DataFrame:
    """Per step of a Gauss-point table (``step``, ``axial_strain``, ``shear_strain``):
    γmax/γmean and the first step at which it passes :data:`LOCALISED` (``onset``)."""
    g = points.groupby("step")
    out = pd.DataFrame({"axial_strain": g["axial_strain"].first(),
                        "gamma_max": g["shear_strain"].max(),
                        "gamma_mean": g["shear_strain"].mean()}).reset_index()
    with np.errstate(invalid="ignore", divide="ignore"):
        out["ratio"] = np.where(out["gamma_mean"] > 0, out["gamma_max"] / out["gamma_mean"],
                                1.0)
    return out


def onset_strain(series: pd.DataFrame, threshold: float = LOCALISED) -> float | None:
    """Axial strain [-] at which ``ratio`` first reaches ``threshold`` (None: never)."""
    hit = series[series["ratio"] >= threshold]
    return float(hit["axial_strain"].iloc[0]) if len(hit) else None


def quadrant_angles(points: pd.DataFrame, step: int, fraction: float = 0.3) -> list[float]:
    """|Inclination| [deg] of the band in each quadrant about the specimen's centre at
    ``step`` (the top ``fraction`` of each quadrant's γ; see
    :func:`~granular_material.results.localization.shear_band`): each arm of an X of
    conjugate bands, where one axis for the whole specimen is none of them."""
    from granular_material.results.localization import shear_band

    at = points[points["step"] == step]
    cx, cy = (at["x"].min() + at["x"].max()) / 2, (at["y"].min() + at["y"].max()) / 2
    out = []
    for right in (False, True):
        for top in (False, True):
            q = at[((at["x"] > cx) == right) & ((at["y"] > cy) == top)]
            if len(q) >= 4:
                out.append(abs(shear_band(q, step, fraction).inclination_deg))
    return out


def bearing_curve(steps: pd.DataFrame, half_width: float) -> pd.DataFrame:
    """Settlement [m] and bearing pressure [Pa] (−footing_force_y / B) of a footing run's
    ``steps.csv`` on a half domain of footing half-width ``half_width`` [m]."""
    return pd.DataFrame({"settlement": steps["footing_settlement"].to_numpy(float),
                         "pressure": -steps["footing_force_y"].to_numpy(float) / half_width})


def material_file(path: Path) -> dict[str, float]:
    """The parameters of a material file ``calibrate`` writes (one of an older version, with
    the old names, read under the new ones)."""
    from granular_material.vocabulary import renamed

    return renamed(tomllib.loads(path.read_text(encoding="utf-8")), "mohr-coulomb", warn=False)
