"""Pore fractal analysis of periodic RVEs: pore images and multifractal spectra.

Rasterises the pore space of a periodic disc packing (:mod:`.image`) and computes its
multifractal spectrum by box counting with Chhabra & Jensen's (1989) direct method
(:mod:`.spectrum`), after Wu, Fu & Zhou (2025), section 2.1. Registered as the
``pore-fractal`` post-processor and the ``granular-material fractal`` command.
"""

from .boxes import (
    BOX_RULES,
    DEFAULT_BOX_MAX,
    DEFAULT_BOX_MIN,
    DEFAULT_MIN_FILL,
    DEFAULT_PER_OCTAVE,
    physical_boxes,
)
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
    box_masses_px,
    multifractal_spectrum,
)

__all__ = [
    "BOX_RULES",
    "DEFAULT_BOX_MAX",
    "DEFAULT_BOX_MIN",
    "DEFAULT_K",
    "DEFAULT_MIN_FILL",
    "DEFAULT_PER_OCTAVE",
    "DEFAULT_PIXEL",
    "DEFAULT_Q",
    "MultifractalSpectrum",
    "PoreImage",
    "analyse_rve",
    "box_masses",
    "box_masses_px",
    "choose_window",
    "multifractal_spectrum",
    "physical_boxes",
    "pore_fractal",
    "pore_image",
    "pore_images",
    "rasterize_pores",
    "rve_porosity",
    "summary",
]
