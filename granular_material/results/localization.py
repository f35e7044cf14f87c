"""Where strain localises: position, inclination and sharpness of a shear band.

A Gauss-point field of shear strain γ (the ``points`` table of a biaxial run) is reduced to
a few numbers, so that "a shear band emerged" is measured rather than read off a map: the
points carrying the largest γ (the top ``fraction``) are taken as the band, the principal
axis of their γ-weighted spread gives its inclination, how line-like that spread is gives
its elongation, and the mean γ inside over the mean γ outside gives the localisation ratio.
A homogeneous specimen gives a ratio near 1 and no preferred axis.

This reads one band: a cross of two, or several reflected bands, have no single axis, and
their principal axis means little (its elongation says so). Each band on its own, with its
width in metres, is :func:`granular_material.results.bands.find_bands`'s.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

__all__ = ["ShearBand", "mohr_coulomb_inclination", "shear_band"]


@dataclass(frozen=True)
class ShearBand:
    """Shape of the zone of largest shear strain at one load step.

    Attributes:
        step: load step of the points.
        axial_strain: axial strain of that step [-], compression +.
        inclination_deg: angle of the band's axis to the x axis [°], in (−90, 90]; positive
            when the band rises to the right (``/``).
        elongation: 1 − λ_min/λ_max of the band points' γ-weighted spread [-]; 1 for points
            on a line, 0 for a round patch (or a cross of two conjugate bands).
        localization: mean γ of the band points / mean γ of the others [-].
        band_fraction: share of the points taken as the band [-].
        centre_x, centre_y: γ-weighted centre of the band points [m].
    """

    step: int
    axial_strain: float
    inclination_deg: float
    elongation: float
    localization: float
    band_fraction: float
    centre_x: float
    centre_y: float

    def as_dict(self) -> dict[str, float]:
        """The measures as a plain dict (for JSON)."""
        return asdict(self)


def mohr_coulomb_inclination(stress_ratio: float) -> float:
    """Band inclination to the minor principal stress direction, 45° + φ/2 [°], from the
    peak σ1/σ3 through sin φ = (R − 1)/(R + 1) (Mohr–Coulomb)."""
    if not stress_ratio >= 1:
        raise ValueError(f"stress_ratio must be >= 1, got {stress_ratio!r}")
    phi = math.asin((stress_ratio - 1) / (stress_ratio + 1))
    return 45.0 + math.degrees(phi) / 2


def shear_band(points: pd.DataFrame, step: int | None = None,
               fraction: float = 0.15) -> ShearBand:
    """Measure the band of largest ``shear_strain`` in the ``points`` table at ``step``.

    Args:
        points: Gauss-point table with columns step, axial_strain, x, y [m], shear_strain.
        step: load step to measure; None: the last one.
        fraction: share of the points, those with the largest γ, taken as the band, in
            (0, 0.5].
    """
    if not 0 < fraction <= 0.5:
        raise ValueError(f"fraction must lie in (0, 0.5], got {fraction!r}")
    missing = {"step", "axial_strain", "x", "y", "shear_strain"} - set(points.columns)
    if missing:
        raise ValueError(f"points table lacks columns {sorted(missing)}")
    step = int(points["step"].max()) if step is None else int(step)
    at = points[points["step"] == step]
    if len(at) < 4:
        raise ValueError(f"step {step} has {len(at)} points; at least 4 are needed")
    gamma = at["shear_strain"].to_numpy(dtype=float)
    if not np.isfinite(gamma).all():
        raise ValueError(f"shear strain at step {step} is not finite")
    count = max(3, round(fraction * gamma.size))
    order = np.argsort(gamma)[::-1]
    band, rest = order[:count], order[count:]
    xy = at[["x", "y"]].to_numpy(dtype=float)[band]
    weight = gamma[band] / gamma[band].sum() if gamma[band].sum() > 0 else np.full(count, 1 / count)
    centre = weight @ xy
    spread = (xy - centre).T @ ((xy - centre) * weight[:, None])
    eigenvalues, eigenvectors = np.linalg.eigh(spread)
    axis = eigenvectors[:, 1]
    angle = math.degrees(math.atan2(axis[1], axis[0]))
    angle = angle - 180.0 if angle > 90 else angle + 180.0 if angle <= -90 else angle
    outside = gamma[rest].mean() if rest.size else np.nan
    return ShearBand(
        step=step, axial_strain=float(at["axial_strain"].iloc[0]), inclination_deg=angle,
        elongation=float(1 - eigenvalues[0] / eigenvalues[1]) if eigenvalues[1] > 0 else 0.0,
        localization=float(gamma[band].mean() / outside) if outside > 0 else math.inf,
        band_fraction=count / gamma.size, centre_x=float(centre[0]), centre_y=float(centre[1]),
    )
