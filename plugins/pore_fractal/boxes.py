"""Box rules: which box sides the multifractal fits use.

``cell`` (Wu et al. 2025, eq. 8): ε = 2⁻ᵏL, k = 1…8, fractions of the window side L, so the
boxes of RVEs of different sizes cover different physical scales and the finest box of a
small image is one pixel. ``physical``: box sides fixed in metres, from ``box_min`` (a few
pixels) to ``box_max`` (a fraction of the cell), ``per_octave`` sides per doubling, the same
for every RVE size and resolution; a box counts as occupied only when at least
``min_fill`` of it is pore, so slivers of pore one pixel wide (the tips of the wedges at the
contacts, which a finer pixel resolves further) do not set the count.
"""

from __future__ import annotations

import math

import numpy as np

from granular_material.memory import available_memory, memory_refusal, size_in_words

__all__ = [
    "BOX_RULES",
    "DEFAULT_BOX_MAX",
    "DEFAULT_BOX_MIN",
    "DEFAULT_MIN_FILL",
    "DEFAULT_PER_OCTAVE",
    "MAX_PER_OCTAVE",
    "physical_boxes",
]

BOX_RULES = ("cell", "physical")
"""The box rules: ``cell`` (ε = 2⁻ᵏL, the paper's) and ``physical`` (ε fixed in metres)."""

DEFAULT_BOX_MIN = 2.4e-3
"""Smallest box [m] of the physical rule: 4 pixels of 0.6 mm, 8 of 0.3 mm."""

DEFAULT_BOX_MAX = 38.4e-3
"""Largest box [m] of the physical rule (16 × the smallest; ≈ 0.4 of a 100-disc cell)."""

DEFAULT_PER_OCTAVE = 2
"""Box sides per doubling of the physical rule (ratio √2)."""

DEFAULT_MIN_FILL = 0.01
"""Pore fraction below which a box of the physical rule counts as empty."""

_MIN_BOX_PX = 2  # the smallest box must hold at least this many pixels per side

MAX_PER_OCTAVE = 1024
"""Most box sides per doubling of the physical rule. Consecutive sides differ by the ratio
2^(1/n) − 1 ≈ 0.69/n, less than a pixel for every side under n/0.69 pixels: at 1024 sides per
doubling only sides above 1477 pixels could still be told apart, and a side is at most half
the image. More only lengthens the list of candidates (10⁸ took 33 s to fail for memory)."""

#: memory per candidate side while the sides are made [bytes]: ε (float64), its rounding
#: and the sorted copy of ``np.unique`` (int64), with a temporary
_CANDIDATE_BYTES = 32


def physical_boxes(
    pixel_size: float,
    n_pixels: int,
    box_min: float = DEFAULT_BOX_MIN,
    box_max: float = DEFAULT_BOX_MAX,
    per_octave: int = DEFAULT_PER_OCTAVE,
) -> np.ndarray:
    """Box sides in pixels of the physical rule, coarse to fine, shape (nk,), int64.

    Args:
        pixel_size: side of one pixel [m].
        n_pixels: pixels per side of the image.
        box_min: smallest box side [m]; must be at least 2 pixels.
        box_max: largest box side [m]; capped at half the image side (then reported as used).
        per_octave: box sides per doubling (ε_j = box_min·2^(j/per_octave)), at most
            :data:`MAX_PER_OCTAVE`.

    Returns:
        the distinct sides round(ε_j / pixel) for ε_j ≤ min(box_max, image side / 2); at
        least two.

    Raises:
        ValueError: for a pixel too coarse for ``box_min``, a range without two sides, more
            than :data:`MAX_PER_OCTAVE` sides per doubling (refused before any allocation,
            with the count and memory they would take), or bad arguments.
    """
    if not (np.isfinite(pixel_size) and pixel_size > 0):
        raise ValueError(f"pixel_size must be a positive length in m, got {pixel_size!r}")
    if not (np.isfinite(box_min) and np.isfinite(box_max) and 0 < box_min < box_max):
        raise ValueError(f"need 0 < box_min < box_max [m], got {box_min!r}, {box_max!r}")
    if isinstance(per_octave, bool) or int(per_octave) != per_octave or per_octave < 1:
        raise ValueError(f"per_octave must be a positive integer, got {per_octave!r}")
    if isinstance(n_pixels, bool) or int(n_pixels) != n_pixels or n_pixels < 1:
        raise ValueError(f"n_pixels must be a positive integer, got {n_pixels!r}")
    if round(box_min / pixel_size) < _MIN_BOX_PX:
        raise ValueError(
            f"the smallest box ({1e3 * box_min:g} mm) must span at least {_MIN_BOX_PX} pixels "
            f"of {1e3 * pixel_size:.4g} mm: use a finer --pixel or a larger --box-min"
        )
    top = min(box_max, 0.5 * n_pixels * pixel_size)
    octaves = math.log2(top / box_min) if top > box_min else 0.0
    try:
        per = float(per_octave)
    except OverflowError:  # an integer beyond any float
        per = math.inf
    candidates = per * octaves + 1.0
    needed = candidates * _CANDIDATE_BYTES
    asked = (f"per_octave {per_octave if per < 1e9 else f'{per:.3g}'} "
             f"({candidates:.3g} candidate box sides over {octaves:.3g} doublings)")
    refusal = memory_refusal(needed, asked, available_memory())
    if per_octave > MAX_PER_OCTAVE or refusal is not None:
        raise ValueError(
            refusal or f"{asked} needs about {size_in_words(needed)} while they are made; "
                       f"sides closer than a pixel are the same box, so at most "
                       f"{MAX_PER_OCTAVE} per doubling are taken")
    count = math.floor(per_octave * octaves + 1e-9) + 1
    eps = box_min * 2.0 ** (np.arange(max(count, 0)) / per_octave)
    sides = np.unique(np.round(eps / pixel_size).astype(np.int64))
    if sides.size < 2:
        raise ValueError(
            f"boxes from {1e3 * box_min:g} to {1e3 * top:.4g} mm give fewer than two sides at "
            f"{1e3 * pixel_size:.4g} mm pixels (image {n_pixels} px): widen the range"
        )
    return sides[::-1].copy()
