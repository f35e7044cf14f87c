"""The ``pore-fractal`` post-processor: pore image and multifractal indices of one RVE.

Registered under the ``granular_material.postprocessors`` entry-point group, so a simulation
can ask for it per RVE and per step.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from granular_material.dem.rve_file import RVEData

from .image import DEFAULT_PIXEL, PoreImage, pore_image
from .spectrum import (
    DEFAULT_K,
    DEFAULT_Q,
    MultifractalSpectrum,
    multifractal_spectrum,
)

__all__ = ["analyse_rve", "pore_fractal", "summary"]


def analyse_rve(
    data: RVEData,
    rve_index: int = 0,
    pixel_size: float = DEFAULT_PIXEL,
    *,
    q: ArrayLike = DEFAULT_Q,
    k: Sequence[int] = DEFAULT_K,
    min_r2: float = 0.99,
) -> tuple[PoreImage, MultifractalSpectrum]:
    """Pore image of RVE ``rve_index`` and the spectrum of its pore pixels (the measure).

    Args:
        data: an RVE batch.
        rve_index: which RVE of the batch (negative counts from the end).
        pixel_size: requested pixel size [m]; the window side is m·2^max(k) pixels.
        q: moment orders, shape (nq,).
        k: box levels, ε = 2⁻ᵏL.
        min_r2: fits with R² below this are flagged in the spectrum's ``poor_fit``.

    Raises:
        ValueError: for an index outside the batch, a bad pixel size, or an image without
            pore pixels.
    """
    if not -data.n_rve <= rve_index < data.n_rve:
        raise ValueError(
            f"rve index {rve_index} is out of range for a batch of {data.n_rve} RVE(s)"
        )
    levels = [int(level) for level in k]
    if not levels:
        raise ValueError("k must list at least two box levels")
    multiple = 1 << max(levels)
    image = pore_image(
        data.radius[rve_index], data.position[rve_index], data.cell[rve_index], pixel_size,
        multiple_of=multiple,
    )
    if not image.pore.any():
        raise ValueError(f"RVE {rve_index} has no pore pixel at {image.pixel_size:.4g} m")
    return image, multifractal_spectrum(image.pore, q=q, k=levels, min_r2=min_r2)


def summary(image: PoreImage, spectrum: MultifractalSpectrum) -> dict[str, float]:
    """The scalar results: D0, alpha0, alpha0_over_D0, porosity (of the image),
    rve_porosity, pixel_size [m], image_size [px per side], window_side [m] and min_r2
    (the smallest R² of all the fits)."""
    return {
        "D0": float(spectrum.D0),
        "alpha0": float(spectrum.alpha0),
        "alpha0_over_D0": float(spectrum.alpha0_over_D0),
        "porosity": image.porosity,
        "rve_porosity": float(image.rve_porosity),
        "pixel_size": float(image.pixel_size),
        "image_size": image.n_pixels,
        "window_side": float(image.side),
        "min_r2": float(np.min(spectrum.r2)),
    }


def pore_fractal(
    data: RVEData, rve_index: int = 0, pixel_size: float = DEFAULT_PIXEL
) -> dict[str, float]:
    """Multifractal indices of the pore space of one RVE (Wu et al. 2025, section 2.1).

    Args:
        data: an RVE batch.
        rve_index: which RVE of the batch.
        pixel_size: requested pixel size [m]; the pixel used is returned as ``pixel_size``.

    Returns:
        see :func:`summary`; spectrum with q ∈ [−10, 10] step 0.5, ε = 2⁻ᵏL, k = 1…8.
    """
    return summary(*analyse_rve(data, rve_index, pixel_size))
