"""The tangents an RVE batch answers with, each a small strategy resolved once from its name.

A :class:`TangentMethod` says what a tangent costs and how it is finished: whether it needs
four extra DEM runs (forward differences of the RVE's own response), whether it condenses
the contact network (:func:`~granular_material.dem.condensed.dispatch.condense`), whether it may
be held over a Newton increment, and what the stress's spin adds to it.

- ``objective``: Kruyt–Rothenburg applied to sym ∇u plus the stress's spin
  (:func:`~granular_material.dem.homogenization.objective_tangent`);
- ``kruyt-rothenburg``: the contact network's estimate as Wu et al. (2025, eq. 6) publish it;
- ``perturbation``: forward differences of the RVE's response, four more DEM runs;
- ``condensed``: the discs' fluctuations condensed out of the contact network, plus the
  stress's spin; contacts at their Coulomb cap slide freely;
- ``condensed-sticking``: the same with every touching contact keeping kt, an upper bound of
  the RVE's incremental stiffness.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from granular_material.errors import ParameterError

__all__ = ["TANGENTS", "TangentMethod", "tangent_method"]


@dataclass(frozen=True)
class TangentMethod:
    """One way of measuring an RVE's tangent.

    Attributes:
        name: the tangent's name (a key of :data:`TANGENTS`).
        perturbed: measured by forward differences: four more DEM runs an evaluation, each
            from the committed state.
        sliding: condensed with contacts at their cap treated so ("free" or "stick");
            None: not condensed.
        spin: how the stress's rotation by the spin is added: "objective" (the
            Kruyt–Rothenburg tangent's symmetric part plus the spin), "added" (the spin on
            top: the condensed tangent is objective already, C:W = 0) or "none".
    """

    name: str
    perturbed: bool = False
    sliding: str | None = None
    spin: str = "none"

    @property
    def condensed(self) -> bool:
        """Whether the contact network is condensed (a sparse solve per RVE)."""
        return self.sliding is not None

    @property
    def holdable(self) -> bool:
        """Whether holding it over a Newton increment saves work: the condensed and the
        perturbation tangents cost a condensation or four DEM drives; the others nothing."""
        return self.perturbed or self.condensed

    def finish(self, tangent: np.ndarray, stress: np.ndarray) -> np.ndarray:
        """The tangent [Pa] (B, 2, 2, 2, 2) answered for the measured ``tangent`` and the
        Love ``stress`` [Pa] (B, 2, 2): the stress's spin added as :attr:`spin` says."""
        if self.spin == "none":
            return tangent
        stress = np.asarray(stress, dtype=np.float64)
        symmetric = 0.5 * (stress + np.swapaxes(stress, 1, 2))
        # imported here: naming a tangent (a run's options) loads no warp
        from granular_material.dem.homogenization import objective_tangent, spin_tangent

        if self.spin == "objective":
            return objective_tangent(tangent, symmetric)
        return tangent + spin_tangent(symmetric)


#: the tangents, by name
TANGENTS: dict[str, TangentMethod] = {
    m.name: m for m in (
        TangentMethod("objective", spin="objective"),
        TangentMethod("kruyt-rothenburg"),
        TangentMethod("perturbation", perturbed=True),
        TangentMethod("condensed", sliding="free", spin="added"),
        TangentMethod("condensed-sticking", sliding="stick", spin="added"),
    )}


def tangent_method(name: str) -> TangentMethod:
    """The tangent called ``name``; a :class:`~granular_material.errors.ParameterError`
    naming the field ``tangent`` otherwise."""
    try:
        return TANGENTS[name]
    except (KeyError, TypeError):
        raise ParameterError("tangent", f"must be one of {', '.join(TANGENTS)}, "
                                        f"got {name!r}") from None
