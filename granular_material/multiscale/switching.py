"""When a point of an adaptive material leaves its continuum twin for a DEM RVE: the
criterion (:class:`SwitchCriterion`: mobilised friction, accumulated shear strain, the
points that switch with a point) and the words of its settings. Light on purpose: the
command line and the run specification check these settings without loading the DEM
(:mod:`granular_material.multiscale.adaptive` holds the material itself)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.continuum_start import mobilised_friction as friction_of

__all__ = ["NEIGHBOURS", "STARTS", "SwitchCriterion", "check_start", "mobilised_friction"]

#: which points switch with a point that meets the criterion: itself, or its element's
NEIGHBOURS = ("point", "element")
#: how a switching point's RVE starts: driven from the source RVE through the point's
#: accumulated deformation ("strain"), or brought by the stress servo to the point's twin
#: stress ("stress")
STARTS = ("strain", "stress")


def check_start(start: str) -> None:
    """ParameterError naming ``adaptivity.start`` unless ``start`` is one of
    :data:`STARTS`."""
    if start not in STARTS:
        raise ParameterError("adaptivity.start", f"must be one of {', '.join(STARTS)}, got "
                                                 f"{start!r}")


@dataclass(frozen=True)
class SwitchCriterion:
    """When a point leaves its twin for a DEM RVE (either threshold met; None: not used).

    Attributes:
        mobilised_fraction: switch once φ_mob ≥ this fraction of the twin's peak friction
            angle (0 < f ≤ 1).
        shear_strain: switch once the accumulated shear strain γ [-] reaches this (> 0).
        neighbours: "point" (the point alone) or "element" (every point of its element).
        in_step: a point that meets a threshold during a load step is DEM in that whole
            step (its RVE made from its state at the step's start, and the step's
            iterations from there on answered by it); False: from the next step on (the
            test made on the committed state, a step behind).
    """

    mobilised_fraction: float | None = 0.7
    shear_strain: float | None = None
    neighbours: str = "element"
    in_step: bool = True

    def __post_init__(self) -> None:
        f, g = self.mobilised_fraction, self.shear_strain
        if f is None and g is None:
            raise ParameterError("adaptivity", "needs a threshold: mobilised_fraction, "
                                               "shear_strain or both")
        if f is not None and not (isinstance(f, int | float) and 0 < f <= 1):
            raise ParameterError("adaptivity.mobilised_fraction",
                                 f"must be a fraction in (0, 1] of the twin's peak friction "
                                 f"angle, got {f!r}")
        if g is not None and not (isinstance(g, int | float) and math.isfinite(g) and g > 0):
            raise ParameterError("adaptivity.shear_strain",
                                 f"must be a shear strain > 0 [-], got {g!r}")
        if self.neighbours not in NEIGHBOURS:
            raise ParameterError("adaptivity.neighbours", f"must be one of "
                                                          f"{', '.join(NEIGHBOURS)}, got "
                                                          f"{self.neighbours!r}")

    def met(self, stress: np.ndarray, grad_u: np.ndarray, peak_friction: float
            ) -> np.ndarray:
        """Whether each point meets it: ``stress`` [Pa] (n, 2, 2), tension positive, the
        total ``grad_u`` [-] (n, 2, 2), the twin's peak friction angle [deg]; (n,) bool."""
        met = np.zeros(len(stress), dtype=bool)
        if self.mobilised_fraction is not None:
            met |= mobilised_friction(stress) >= self.mobilised_fraction * peak_friction
        if self.shear_strain is not None:
            e = 0.5 * (grad_u + np.swapaxes(grad_u, 1, 2))
            met |= np.hypot(e[:, 0, 0] - e[:, 1, 1], 2 * e[:, 0, 1]) >= self.shear_strain
        return met


def mobilised_friction(stress: np.ndarray) -> np.ndarray:
    """φ_mob [deg] of each in-plane stress [Pa] (n, 2, 2), tension positive, as the
    continuum start reads it (``fem.boundary_value.continuum_start``: asin((σ1 − σ3)/(σ1 +
    σ3)) of the principal compressions, 90° past a cohesionless material's apex), but 0
    where neither principal stress is compressive: a point that carries nothing has nothing
    mobilised, and its RVE would be a gas."""
    s = np.asarray(stress, dtype=np.float64)
    s = 0.5 * (s + np.swapaxes(s, 1, 2))
    uncompressed = (np.trace(s, axis1=1, axis2=2) >= 0) & (np.linalg.det(s) >= 0)
    return np.where(uncompressed, 0.0, friction_of(s))
