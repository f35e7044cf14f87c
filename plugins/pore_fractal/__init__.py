"""Pore fractal analysis of periodic RVEs: pore images and multifractal spectra.

Rasterises the pore space of a periodic disc packing (:mod:`.image`) and computes its
multifractal spectrum by box counting with Chhabra & Jensen's (1989) direct method
(:mod:`.spectrum`), after Wu, Fu & Zhou (2025), section 2.1. Registered as the
``pore-fractal`` post-processor and the ``granular-material fractal`` command.
"""

from .image import (
    DEFAULT_PIXEL,
    PoreImage,
    choose_window,
    pore_image,
    pore_images,
    rasterize_pores,
    rve_porosity,
)
from .postprocess import analyse_rve, pore_fractal, summary
from .spectrum import (
    DEFAULT_K,
    DEFAULT_Q,
    MultifractalSpectrum,
    box_masses,
    multifractal_spectrum,
)

__all__ = [
    "DEFAULT_K",
    "DEFAULT_PIXEL",
    "DEFAULT_Q",
    "MultifractalSpectrum",
    "PoreImage",
    "analyse_rve",
    "box_masses",
    "choose_window",
    "multifractal_spectrum",
    "pore_fractal",
    "pore_image",
    "pore_images",
    "rasterize_pores",
    "rve_porosity",
    "summary",
]
