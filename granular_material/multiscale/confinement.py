"""Points whose RVE has lost its confinement: how they are found, said and solved through.

An RVE whose mean pressure falls to (nearly) nothing is a gas of discs: its stress and its
stiffness vanish. In a boundary-value problem this happens where the soil unloads (beside a
footing's edge, behind a wall moving away); the stress answer is right (the soil there
carries nothing), but a Newton iteration matrix with zero stiffness at a point is singular
and its corrections grow without bound. So such a point's *tangent* (what Newton iterates
with, never its stress) is floored by a fraction of the tangent it had in its initial state:
the converged answer is the same, Newton only takes a well-posed matrix.
"""

from __future__ import annotations

import numpy as np

__all__ = ["UNCONFINED_FRACTION", "UNCONFINED_TANGENT", "UnconfinedWarning", "floored_tangent",
           "unconfined"]

#: a point whose mean pressure −tr σ / 2 falls below this fraction of its initial one (the
#: material's confining pressure, or the point's own initial stress) has lost its confinement
UNCONFINED_FRACTION = 0.01
#: the fraction of its initial tangent that an unconfined point's tangent is floored by
UNCONFINED_TANGENT = 0.05


class UnconfinedWarning(UserWarning):
    """A DEM RVE has (nearly) no confining stress: with none, a granular RVE relaxes into a
    stress-free gas of discs (zero stress, zero stiffness) and a Newton loop "converges" to
    nothing. Confine the specimen (a pressure on its boundary, as
    ``examples/skfem_material_swap.py`` does) or load RVEs prepared at a pressure; in a
    boundary-value problem, points that unload to nothing (beside a footing's edge) are
    physical, counted per step in its tables."""


def unconfined(stress: np.ndarray, ok: np.ndarray, initial_pressure: float | np.ndarray,
               ) -> np.ndarray:
    """Mask (n,) of the points (``ok`` among them) whose mean pressure from ``stress`` [Pa]
    (n, 2, 2), tension positive, is below :data:`UNCONFINED_FRACTION` of
    ``initial_pressure`` [Pa] (a number or (n,))."""
    pressure = -0.5 * np.trace(stress, axis1=1, axis2=2)
    return np.asarray(ok, dtype=bool) & (pressure < UNCONFINED_FRACTION * initial_pressure)


def floored_tangent(tangent: np.ndarray, initial: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``tangent`` [Pa] (n, 2, 2, 2, 2) with :data:`UNCONFINED_TANGENT` × ``initial`` added at
    the points of ``mask`` (a copy where any is; the array itself where none is)."""
    if not mask.any():
        return tangent
    out = tangent.copy()
    out[mask] += UNCONFINED_TANGENT * initial[mask]
    return out
