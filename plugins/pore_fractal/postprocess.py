"""The ``pore-fractal`` post-processor: pore image and multifractal indices of one RVE.

Registered under the ``granular_material.postprocessors`` entry-point group, so a simulation
can ask for it per RVE and per step.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from granular_material.dem.rve.file import RVEData

from .boxes import (
    BOX_RULES,
    DEFAULT_BOX_MAX,
    DEFAULT_BOX_MIN,
    DEFAULT_MIN_FILL,
    DEFAULT_PER_OCTAVE,
    physical_boxes,
)
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
    box_rule: str = "cell",
    box_min: float = DEFAULT_BOX_MIN,
    box_max: float = DEFAULT_BOX_MAX,
    per_octave: int = DEFAULT_PER_OCTAVE,
    min_fill: float = DEFAULT_MIN_FILL,
) -> tuple[PoreImage, MultifractalSpectrum]:
    """Pore image of RVE ``rve_index`` and the spectrum of its pore pixels (the measure).

    Args:
        data: an RVE batch.
        rve_index: which RVE of the batch (negative counts from the end).
        pixel_size: requested pixel size [m]; under ``cell`` the window side is m·2^max(k)
            pixels, under ``physical`` any number, the pixel nearest the request.
        q: moment orders, shape (nq,).
        k: box levels, ε = 2⁻ᵏL (``cell`` only).
        min_r2: fits with R² below this are flagged in the spectrum's ``poor_fit``.
        box_rule: ``cell`` (ε = 2⁻ᵏL, the paper's) or ``physical`` (see :mod:`.boxes`).
        box_min, box_max: smallest and largest box [m] (``physical`` only).
        per_octave: box sides per doubling (``physical`` only).
        min_fill: pore fraction below which a box counts as empty (``physical`` only).

    Raises:
        ValueError: for an index outside the batch, a bad pixel size, or an image without
            pore pixels.
    """
    if not -data.n_rve <= rve_index < data.n_rve:
        raise ValueError(
            f"rve index {rve_index} is out of range for a batch of {data.n_rve} RVE(s)"
        )
    if box_rule not in BOX_RULES:
        raise ValueError(f"box_rule must be one of {BOX_RULES}, got {box_rule!r}")
    levels = [int(level) for level in k]
    if not levels:
        raise ValueError("k must list at least two box levels")
    multiple = 1 << max(levels) if box_rule == "cell" else 1
    image = pore_image(
        data.radius[rve_index], data.position[rve_index], data.cell[rve_index], pixel_size,
        multiple_of=multiple,
    )
    if not image.pore.any():
        raise ValueError(f"RVE {rve_index} has no pore pixel at {image.pixel_size:.4g} m")
    if box_rule == "cell":
        return image, multifractal_spectrum(image.pore, q=q, k=levels, min_r2=min_r2)
    sides = physical_boxes(image.pixel_size, image.n_pixels, box_min, box_max, per_octave)
    return image, multifractal_spectrum(image.pore, q=q, min_r2=min_r2, box_px=sides,
                                        min_fill=min_fill)


def summary(image: PoreImage, spectrum: MultifractalSpectrum) -> dict[str, float]:
    """The scalar results: D0, alpha0, alpha0_over_D0, porosity (of the image),
    rve_porosity, pixel_size [m], image_size [px per side], window_side [m], min_r2
    (the smallest R² of all the fits); the fit range box_min_m, box_max_m [m] and
    box_min_px, box_max_px [px], box_sizes (how many), r2_q0 (the smallest R² of the fits
    that give D0 and α0), and the standard errors D0_se, alpha0_se, alpha0_over_D0_se."""
    sides = spectrum.box_px
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
        "box_min_m": float(sides.min() * image.pixel_size),
        "box_max_m": float(sides.max() * image.pixel_size),
        "box_min_px": int(sides.min()),
        "box_max_px": int(sides.max()),
        "box_sizes": int(sides.size),
        "r2_q0": float(spectrum.r2_q0),
        "D0_se": float(spectrum.D0_se),
        "alpha0_se": float(spectrum.alpha0_se),
        "alpha0_over_D0_se": float(spectrum.alpha0_over_D0_se),
    }


def pore_fractal(
    data: RVEData, rve_index: int = 0, pixel_size: float = DEFAULT_PIXEL,
    box_rule: str = "cell",
) -> dict[str, float]:
    """Multifractal indices of the pore space of one RVE (Wu et al. 2025, section 2.1).

    Args:
        data: an RVE batch.
        rve_index: which RVE of the batch.
        pixel_size: requested pixel size [m]; the pixel used is returned as ``pixel_size``.
        box_rule: ``cell`` (ε = 2⁻ᵏL, k = 1…8) or ``physical`` (the defaults of
            :mod:`.boxes`).

    Returns:
        see :func:`summary`; spectrum with q ∈ [−10, 10] step 0.5.
    """
    return summary(*analyse_rve(data, rve_index, pixel_size, box_rule=box_rule))
