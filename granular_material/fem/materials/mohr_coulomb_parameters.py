"""The constants of the Mohr–Coulomb material (:class:`MohrCoulombParameters`, angles in
degrees, stresses in Pa) and the material of a run specification
(:class:`MohrCoulombRunParameters`, the same names), each checked once where it is built."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from granular_material.errors import ParameterError
from granular_material.fem.materials.mohr_coulomb_return import Strength
from granular_material.vocabulary import accept_old_keywords

__all__ = ["MohrCoulombParameters", "MohrCoulombRunParameters", "number"]


def number(field: str, value: Any) -> float:
    """``value`` (a real number, not text or a bool) as a finite float;
    :class:`ParameterError` naming ``field`` otherwise."""
    if isinstance(value, (str, bytes, bool)):
        raise ParameterError(field, f"must be a number, got {value!r}")
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ParameterError(field, f"must be a number, got {value!r}") from None
    if not math.isfinite(value):
        raise ParameterError(field, f"must be finite, got {value!r}")
    return value


@dataclass(frozen=True)
class MohrCoulombParameters:
    """The constants of :class:`MohrCoulomb` (angles in degrees, stresses in Pa).

    Attributes:
        young: Young's modulus E [Pa], > 0.
        poisson: Poisson's ratio ν [-], in (−1, 0.5).
        friction_angle: peak friction angle φ [°], in [0, 90); 0 is Tresca (undrained
            clay: strength c whatever the pressure), which needs c > 0.
        dilation_angle: peak dilation angle ψ [°], 0 ≤ ψ ≤ φ.
        cohesion: c [Pa], ≥ 0; > 0 when φ = 0.
        critical_friction_angle: φcs [°], 0 < φcs ≤ φ, or None (no softening; always None
            when φ = 0).
        softening_strain: plastic shear strain γp [-] over which φ falls linearly to φcs and
            ψ to 0 (constant after); > 0 when φcs is given.
    """

    young: float = 60.0e6
    poisson: float = 0.3
    friction_angle: float = 30.0
    dilation_angle: float = 0.0
    cohesion: float = 0.0
    critical_friction_angle: float | None = None
    softening_strain: float = 0.0

    def __post_init__(self) -> None:
        for name in ("young", "poisson", "friction_angle", "dilation_angle", "cohesion",
                     "softening_strain"):
            object.__setattr__(self, name, number(name, getattr(self, name)))
        if self.young <= 0:
            raise ParameterError("young", f"must be a positive number of Pa, got {self.young!r}")
        if not -1.0 < self.poisson < 0.5:
            raise ParameterError("poisson", f"must lie in (-1, 0.5), got {self.poisson!r}")
        if not 0 <= self.friction_angle < 90:
            raise ParameterError("friction_angle", "must lie in [0, 90) degrees, got "
                                                   f"{self.friction_angle!r}")
        if not 0 <= self.dilation_angle <= self.friction_angle:
            raise ParameterError("dilation_angle", "must lie in [0, friction_angle] degrees, "
                                                   f"got {self.dilation_angle!r}")
        if self.cohesion < 0:
            raise ParameterError("cohesion", f"must be >= 0 Pa, got {self.cohesion!r}")
        if self.friction_angle == 0 and self.cohesion <= 0:
            raise ParameterError("cohesion", "must be > 0 Pa when friction_angle is 0 "
                                             "(Tresca: the cohesion is all the strength, so "
                                             "the material would carry no shear stress), got "
                                             f"{self.cohesion!r}")
        if self.softening_strain < 0:
            raise ParameterError("softening_strain", "must be >= 0, got "
                                                     f"{self.softening_strain!r}")
        if self.critical_friction_angle is not None:
            phi_cs = number("critical_friction_angle", self.critical_friction_angle)
            object.__setattr__(self, "critical_friction_angle", phi_cs)
            if self.friction_angle == 0:
                raise ParameterError("critical_friction_angle", "must be left out when "
                                     "friction_angle is 0 (Tresca: there is no friction to "
                                     f"soften), got {phi_cs!r}")
            if not 0 < phi_cs <= self.friction_angle:
                raise ParameterError("critical_friction_angle", "must lie in (0, "
                                     f"friction_angle] degrees, got {phi_cs!r}")
            if self.softening_strain <= 0:
                raise ParameterError("softening_strain", "must be > 0 when "
                                     "critical_friction_angle is given, got "
                                     f"{self.softening_strain!r}")

    @property
    def lame(self) -> tuple[float, float]:
        """Lamé constants (λ, μ) [Pa]."""
        e, nu = self.young, self.poisson
        return e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))

    def reduced(self, factor: float) -> MohrCoulombParameters:
        """These parameters with the strength divided by ``factor`` F (> 0, finite; the
        strength reduction of a factor of safety): c/F, and each angle a (φ, φcs, ψ) turned
        into atan(tan a / F), so that ψ_F ≤ φ_F; E, ν and the softening strain unchanged.
        F = 1 gives these parameters themselves. ParameterError naming ``factor``
        otherwise."""
        factor = number("factor", factor)
        if not factor > 0:
            raise ParameterError("factor", "must be a strength reduction factor > 0, got "
                                           f"{factor!r}")
        if factor == 1.0:
            return self

        def angle(degrees: float) -> float:
            return math.degrees(math.atan(math.tan(math.radians(degrees)) / factor))

        phi = angle(self.friction_angle)
        phi_cs = (None if self.critical_friction_angle is None
                  else min(angle(self.critical_friction_angle), phi))
        return replace(self, friction_angle=phi,
                       dilation_angle=min(angle(self.dilation_angle), phi),
                       cohesion=self.cohesion / factor, critical_friction_angle=phi_cs)

    def strength(self) -> Strength:
        """The constants of the return mapping (radians)."""
        lam, mu = self.lame
        phi_cs = (self.friction_angle if self.critical_friction_angle is None
                  else self.critical_friction_angle)
        return Strength(mu, lam, math.radians(self.friction_angle),
                        math.radians(self.dilation_angle), self.cohesion,
                        math.radians(phi_cs),
                        self.softening_strain if self.critical_friction_angle is not None
                        else 0.0)


@accept_old_keywords("mohr-coulomb")
@dataclass(frozen=True, kw_only=True)
class MohrCoulombRunParameters:
    """The material of a run specification (its initial stress is the run's confining
    pressure), under the names of :class:`MohrCoulombParameters`: ``young`` [Pa],
    ``poisson`` [-], ``friction_angle``, ``dilation_angle``, ``critical_friction_angle``
    [°], ``cohesion`` [Pa], ``softening_strain`` [-]. The old names ``E``, ``nu``, ``phi``,
    ``psi``, ``phi_cs`` are still read, with a
    :class:`~granular_material.vocabulary.RenamedWarning`."""

    young: float = MohrCoulombParameters.young
    poisson: float = MohrCoulombParameters.poisson
    friction_angle: float = MohrCoulombParameters.friction_angle
    dilation_angle: float = MohrCoulombParameters.dilation_angle
    cohesion: float = MohrCoulombParameters.cohesion
    critical_friction_angle: float | None = MohrCoulombParameters.critical_friction_angle
    softening_strain: float = MohrCoulombParameters.softening_strain

    def __post_init__(self) -> None:
        try:  # the material's own checks
            MohrCoulombParameters(young=self.young, poisson=self.poisson,
                                  friction_angle=self.friction_angle,
                                  dilation_angle=self.dilation_angle, cohesion=self.cohesion,
                                  critical_friction_angle=self.critical_friction_angle,
                                  softening_strain=self.softening_strain)
        except ParameterError as exc:
            if exc.field == "softening_strain" and self.softening_strain == 0.0:
                raise ParameterError("critical_friction_angle", "needs softening_strain > 0 "
                                     "(the plastic shear strain over which friction_angle "
                                     "softens to critical_friction_angle), which is 0") from None
            raise
