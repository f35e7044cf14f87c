"""The figure of a Mohr–Coulomb calibration: the DEM curve(s) beside the calibrated model's.

Compression positive on the axes, as every figure here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from granular_material.procedures.calibration import Calibration, principal_ratio
from granular_material.results.plots import pyplot, save_figure

__all__ = ["plot_calibration"]


def plot_calibration(calibration: Calibration, model: pd.DataFrame | None,
                     path: str | Path) -> Path:
    """σ1/σ3 (principal) and εv against the axial strain ε1: every RVE's DEM curve (thin),
    the calibrated Mohr–Coulomb point (``model``: a table of
    :func:`~granular_material.procedures.calibration.drained_point_curve`; None: none) and
    the readings marked (the peak, the critical ratio, the elastic window). Written whole to
    ``path`` (format from its suffix)."""
    plt = pyplot()
    curve = calibration.curve
    p = calibration.parameters
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5), constrained_layout=True)
    groups = list(curve.groupby("rve")) if "rve" in curve else [(0, curve)]
    for rve, g in groups:
        label = f"DEM RVE {rve}" if len(groups) <= 8 else ("DEM RVEs" if rve == groups[0][0]
                                                            else None)
        eps = 100 * g["axial_strain"]
        ax1.plot(eps, principal_ratio(g), lw=0.9, alpha=0.7, label=label)
        ax2.plot(eps, -100 * g["volumetric_strain"], lw=0.9, alpha=0.7, label=label)
    if model is not None:
        eps = 100 * model["axial_strain"]
        ax1.plot(eps, principal_ratio(model), "k--", lw=2, label="Mohr–Coulomb (calibrated)")
        ax2.plot(eps, -100 * model["volumetric_strain"], "k--", lw=2,
                 label="Mohr–Coulomb (calibrated)")
    for angle, words, style in ((p["friction_angle"], "φ", ":"),
                                (p["critical_friction_angle"], "φcs", "-.")):
        s = np.sin(np.radians(angle))
        ax1.axhline((1 + s) / (1 - s), color="grey", ls=style, lw=1,
                    label=f"{words} = {angle:.1f}°")
    phi = calibration.readings["friction_angle"]
    sines = np.sin(np.radians(phi.per_rve))
    ax1.plot([100 * w[0] for w in phi.windows], (1 + sines) / (1 - sines), "rv", ms=6,
             label="peaks read")
    lo, hi = calibration.readings["young"].windows[0]
    ax1.axvspan(100 * lo, 100 * hi, color="tab:green", alpha=0.15, label="E, ν window")
    psi_lo = min(w[0] for w in calibration.readings["dilation_angle"].windows)
    psi_hi = max(w[1] for w in calibration.readings["dilation_angle"].windows)
    ax2.axvspan(100 * psi_lo, 100 * psi_hi, color="tab:orange", alpha=0.15,
                label="ψ window")
    ax1.set_ylabel("principal stress ratio σ1/σ3 [-]")
    ax2.set_ylabel("volumetric strain εv [%] (contraction positive)")
    for ax in (ax1, ax2):
        ax.set_xlabel("axial strain ε1 [%] (compression positive)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"Mohr–Coulomb from {calibration.source} at P = {calibration.pressure:.4g} "
                 f"Pa: E = {p['young'] / 1e6:.3g} MPa, ν = {p['poisson']:.3f}, "
                 f"φ = {p['friction_angle']:.1f}°, ψ = {p['dilation_angle']:.1f}°, "
                 f"φcs = {p['critical_friction_angle']:.1f}°, softening strain "
                 f"{p['softening_strain']:.3g}", fontsize=9)
    try:
        return save_figure(fig, path)
    finally:
        plt.close(fig)
