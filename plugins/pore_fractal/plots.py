"""Figures: the pore image, q–D_q and α–f(α) spectra (as Wu et al. 2025, Fig. 3).

Built on :class:`matplotlib.figure.Figure` directly, so no GUI backend is needed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from .image import PoreImage
from .spectrum import MultifractalSpectrum

__all__ = ["plot_dq", "plot_f_alpha", "plot_pore_image", "save_figure", "spectrum_figure"]


def plot_pore_image(ax: Axes, image: PoreImage) -> None:
    """Draw the pore image (pores white, discs dark) with axes in mm."""
    extent_mm = 1e3 * np.array([
        image.origin[0], image.origin[0] + image.side,
        image.origin[1], image.origin[1] + image.side,
    ])
    ax.imshow(image.pore, origin="lower", cmap="gray", extent=extent_mm, interpolation="nearest")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_title(
        f"pores: {image.n_pixels}² px of {1e3 * image.pixel_size:.3f} mm, "
        f"n = {image.porosity:.3f} (RVE {image.rve_porosity:.3f})",
        fontsize="small",
    )


def plot_dq(ax: Axes, spectrum: MultifractalSpectrum, label: str | None = None) -> None:
    """Draw D_q against q for one image; fits flagged as poor are ringed in red."""
    ax.plot(spectrum.q, spectrum.Dq, "o-", ms=3, label=label)
    poor = spectrum.poor_fit
    if poor.any():
        ax.plot(spectrum.q[poor], spectrum.Dq[poor], "o", mfc="none", mec="red", ms=7,
                label=f"R² < {spectrum.min_r2:g}")
        ax.legend(fontsize="small")
    ax.set_xlabel("q")
    ax.set_ylabel("$D_q$")
    ax.set_title(f"$D_0$ = {float(spectrum.D0):.4f}", fontsize="small")
    ax.grid(alpha=0.3)


def plot_f_alpha(ax: Axes, spectrum: MultifractalSpectrum, label: str | None = None) -> None:
    """Draw f(α) against α for one image and mark the peak (α0, D0)."""
    ax.plot(spectrum.alpha, spectrum.f, "o-", ms=3, label=label)
    ax.plot([float(spectrum.alpha0)], [float(spectrum.D0)], "k^", ms=7,
            label=r"$(\alpha_0, D_0)$")
    ax.set_xlabel(r"$\alpha$")
    ax.set_ylabel(r"$f(\alpha)$")
    ax.set_title(
        rf"$\alpha_0$ = {float(spectrum.alpha0):.4f}, "
        rf"$\alpha_0/D_0$ = {float(spectrum.alpha0_over_D0):.4f}",
        fontsize="small",
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")


def spectrum_figure(image: PoreImage, spectrum: MultifractalSpectrum) -> Figure:
    """A three-panel figure: the pore image, q–D_q and α–f(α), for one RVE."""
    if np.ndim(spectrum.D0) != 0:
        raise ValueError("spectrum_figure draws one image; select one spectrum of the batch")
    fig = Figure(figsize=(13.5, 4.2), layout="constrained")
    axes = fig.subplots(1, 3)
    plot_pore_image(axes[0], image)
    plot_dq(axes[1], spectrum)
    plot_f_alpha(axes[2], spectrum)
    return fig


def save_figure(fig: Figure, path: str | Path, dpi: int = 150) -> Path:
    """Save ``fig`` to ``path`` (format from the suffix), whole or not at all, and return
    the path."""
    from granular_material.results.plots import save_figure as save_whole

    return save_whole(fig, path, dpi=dpi)
