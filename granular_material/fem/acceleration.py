"""Relaxation of the Newton corrections when the tangent is stiffer than the material.

The Kruyt–Rothenburg tangent of a DEM RVE is the stiffness of its contact network deformed
affinely: it leaves out the particles' rearrangement, so even before the peak it is about
1.7–2 times the stiffness the RVE shows under a deviatoric increment (measured on 64-disc
RVEs), and past the peak, inside a shear band, more still. Plain Newton corrections are
then too short and converge linearly, at a rate close to one. Irons–Tuck (Aitken)
relaxation scales every correction by one factor ω learned from the last two corrections
(Küttler & Wall 2008, eq. 44), which recovers most of the lost rate and needs nothing from
the material.
"""

from __future__ import annotations

import numpy as np

__all__ = ["AitkenRelaxation"]


class AitkenRelaxation:
    """x ← x + ω c, with ω from the last two corrections c, clipped to [lower, upper]."""

    def __init__(self, lower: float = 0.1, upper: float = 50.0) -> None:
        if not 0 < lower <= 1 <= upper:
            raise ValueError(f"need 0 < lower <= 1 <= upper, got {lower!r}, {upper!r}")
        self.lower, self.upper = lower, upper
        self.omega = 1.0
        self._previous: np.ndarray | None = None

    def update(self, x: np.ndarray, correction: np.ndarray) -> np.ndarray:
        """The next iterate from the iterate ``x`` and its Newton correction ``correction``."""
        if self._previous is not None:
            change = correction - self._previous
            denominator = float(change @ change)
            if denominator > 0:
                self.omega = float(np.clip(-self.omega * (self._previous @ change)
                                           / denominator, self.lower, self.upper))
        self._previous = correction
        return x + self.omega * correction
