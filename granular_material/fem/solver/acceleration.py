"""Newton with a tangent that is stiffer than the material: relaxation and secant updates.

The Kruyt–Rothenburg tangent of a DEM RVE is the stiffness of its contact network deformed
affinely: it leaves out the particles' rearrangement, so even before the peak it is about
1.7–2 times the stiffness the RVE shows under a deviatoric increment (measured on 64-disc
RVEs), and past the peak, inside a shear band, more still. Plain Newton corrections are
then too short and converge linearly, at a rate close to one. Irons–Tuck (Aitken)
relaxation scales every correction by one factor ω learned from the last two corrections
(Küttler & Wall 2008, eq. 44), which recovers most of the lost rate and needs nothing from
the material. One factor for the whole mesh cannot tell the band from the rest, though.
:class:`SecantTangent` corrects each point's tangent instead, from the stress change its own
RVE gave along the step Newton took (a Broyden update per point, as quasi-Newton methods
do for the whole system); it needs no extra DEM runs, but only changes well above the DEM
noise may update it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["AitkenRelaxation", "SecantTangent"]


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


class SecantTangent:
    """Per-point Broyden update of the tangent from the material's own secant response.

    Every Gauss point keeps a 4×4 matrix C (the tangent D_ijkl with (i, j) and (k, l)
    flattened), started from the committed tangent. After each evaluation, the change of
    stress Δσ and of displacement gradient Δg since the previous iterate correct C along Δg
    (Broyden's good update): C ← C + (Δσ − C Δg) ⊗ Δg / (Δg · Δg). Points whose Δg is below
    ``min_change`` (norm, dimensionless) keep C: there the stress change would be mostly
    the DEM noise. The material's own tangent is only used to start; what the RVE did along
    the directions Newton actually took replaces it, which is what the Kruyt–Rothenburg
    tangent misses (rearrangement, softening).
    """

    def __init__(self, grad_u: np.ndarray, stress: np.ndarray, tangent: np.ndarray,
                 min_change: float = 1e-4) -> None:
        if not min_change > 0:
            raise ValueError(f"min_change must be > 0, got {min_change!r}")
        n = grad_u.shape[0]
        self.min_change = min_change
        self._g = grad_u.reshape(n, 4).copy()
        self._s = stress.reshape(n, 4).copy()
        self._c = tangent.reshape(n, 4, 4).copy()
        self.updated = np.zeros(n, dtype=bool)

    def update(self, grad_u: np.ndarray, stress: np.ndarray) -> np.ndarray:
        """The corrected tangent (n, 2, 2, 2, 2) [Pa] after an evaluation at ``grad_u``
        (n, 2, 2) [-] that gave ``stress`` (n, 2, 2) [Pa]."""
        n = grad_u.shape[0]
        g, s = grad_u.reshape(n, 4), stress.reshape(n, 4)
        dg, ds = g - self._g, s - self._s
        norm2 = np.einsum("pk,pk->p", dg, dg)
        use = norm2 > self.min_change**2
        miss = ds[use] - np.einsum("pij,pj->pi", self._c[use], dg[use])
        self._c[use] += np.einsum("pi,pj->pij", miss, dg[use]) / norm2[use, None, None]
        self.updated |= use
        self._g, self._s = g.copy(), s.copy()
        return self._c.reshape(n, 2, 2, 2, 2).copy()
