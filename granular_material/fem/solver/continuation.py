"""Path following past a limit point: the arc-length continuation of the Newton driver.

Under load control (``NewtonSolver.step``) each step prescribes the load factor λ; past a
limit point (a peak of the load, or a snap-back, where the prescribed displacement itself
must go back) no state exists at the next λ and Newton fails, so a run stops there and a
collapse is inferred from a failure whose load factor moves with the number of cut-backs.
The arc-length continuation (Riks 1979; Crisfield 1981, Computers & Structures 13:55) makes
λ an unknown instead: each step adds an increment (Δu, Δλ) of a prescribed length in
displacement,

    ‖Δu‖_L2 = Δl   (cylindrical: the load factor does not enter the length),

with the equilibrium f_int(u) = f_ext(λ) (and the prescribed displacements u_D(λ)) at its
end. Each Newton correction solves the tangent system twice, for the residual (δu_r) and for
a unit change of the parameter (δu_t: the prescribed displacements' and loads' derivatives
in λ), and the change δλ of the parameter is the root of the quadratic constraint
‖Δu + δu_r + δλ δu_t‖ = Δl that keeps the increment closest to its direction so far (where
the arc misses the linearised path, a negative discriminant, the δλ that comes nearest to
it: Lam & Morley 1992, J. Eng. Mech. 118:1243).

The parameter need not be the load factor: :class:`Parameter` names what it changes (the
loads, or a strength factor that divides a material's tan φ and c) and how the residual
changes with it. A step's length follows the Newton iterations of the step before (longer
when they were few, shorter when many, within factors of 2), never exceeds the nominal
change of the parameter per step (so that away from a limit the steps are the load steps of
load control), and is halved when an increment fails. The path's peak is kept. A *collapse*
is a plateau: :data:`PLATEAU_STEPS` steps in a row whose change of the parameter per length
of path is at most :data:`PLATEAU_STIFFNESS` of the first step's (Bergan's current stiffness
parameter near 0: the parameter stalls while the displacement runs on): the tangent of
the load–displacement path has fallen to 1 % of the elastic one. The collapse value is the
path's peak when the plateau is found, the largest parameter at which equilibrium was
found. Measured on the embankment of examples/scenes (929 tri6, Mohr–Coulomb c = 10 kPa,
φ = 20°, ψ = 0): 1.141 by strength reduction and 1.427 by gravity increase, against
Bishop's 1.143 and 1.461 (:mod:`granular_material.limit_equilibrium`); a threshold of 0.002
moved them to 1.143 and 1.431, and on a coarse 16 × 4 quad8 slope, where the path rises
again after its first plateau, the gravity factor from 1.485 to 1.515 (Bishop 1.461). Neither the
plateau nor its value depends on the number of cut-backs, which only set how small a step
may become: a step cut back to a tenth still measures the same rate. A path that comes down
past a peak (a snap-back, or softening) is followed on; its peak is reported.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

__all__ = [
    "CONTINUATIONS",
    "PLATEAU_STEPS",
    "PLATEAU_STIFFNESS",
    "ContinuationState",
    "LoadParameter",
    "Parameter",
    "arc_roots",
    "next_length",
]

#: the ways of stepping a run (NewtonSettings.continuation)
CONTINUATIONS = ("load", "arc-length")
#: steps after the peak over which a collapse is judged
PLATEAU_STEPS = 5
#: the current stiffness parameter (the parameter's change per length of path over the first
#: step's) at or below which, :data:`PLATEAU_STEPS` steps in a row, the path has collapsed
PLATEAU_STIFFNESS = 0.01
#: the Newton iterations a step aims at: the next length is scaled by √(target / used)
TARGET_ITERATIONS = 6


class Parameter(Protocol):
    """What the continuation changes along the path, and how the problem depends on it."""

    name: str

    def apply(self, value: float) -> None:
        """Set the parameter to ``value`` before the material is evaluated."""

    def external(self, value: float, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u_D [m] (m,), f_ext [N/m] (ndofs,)) at ``value`` with the displacement ``u``."""

    def derivative(self, value: float, u: np.ndarray, stress: np.ndarray,
                   ) -> tuple[np.ndarray, np.ndarray]:
        """(∂u_D/∂value [m] (m,), ∂(f_ext − f_int)/∂value [N/m] (ndofs,)) at ``value`` and
        the displacement ``u`` [m], where the material's stress is ``stress`` [Pa]."""


@dataclass
class LoadParameter:
    """The load factor λ of a :class:`~granular_material.fem.boundary_value.loading.Loading`:
    prescribed displacements and loads linear in λ (a follower load through ``at``)."""

    at: Callable[[float, np.ndarray | None], tuple[np.ndarray, np.ndarray]]
    finite: bool = False  # loads on the displaced configuration
    name: str = "load_factor"

    def apply(self, value: float) -> None:
        """Nothing to set: the loads are read at ``value`` by :meth:`external`."""

    def external(self, value: float, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u_D, f_ext) of the loading at load factor ``value``."""
        return self.at(value, u if self.finite else None)

    def derivative(self, value: float, u: np.ndarray, stress: np.ndarray,
                   ) -> tuple[np.ndarray, np.ndarray]:
        """The loading's change per unit λ (it is linear in λ: the difference of its ends)."""
        u_d1, f1 = self.external(1.0, u)
        u_d0, f0 = self.external(0.0, u)
        return u_d1 - u_d0, f1 - f0


def arc_roots(a: float, b: float, c: float) -> tuple[float, ...]:
    """The real roots δλ of a δλ² + b δλ + c = 0 (the arc's constraint), none when the
    arc misses the linearised path (a negative discriminant) or a ≤ 0."""
    if not a > 0:
        return ()
    disc = b * b - 4.0 * a * c
    if disc < 0:
        return ()
    root = math.sqrt(disc)
    # the form that does not cancel: q = −(b + sign(b) √disc) / 2
    q = -0.5 * (b + math.copysign(root, b))
    if q == 0.0:
        return (0.0,)
    return (q / a, c / q)


def next_length(length: float, iterations: int, largest: float) -> float:
    """The next step's length [m]: ``length`` scaled by √(TARGET_ITERATIONS / iterations),
    within [½, 2], and at most ``largest``."""
    scale = math.sqrt(TARGET_ITERATIONS / max(iterations, 1))
    return min(length * min(max(scale, 0.5), 2.0), largest)


@dataclass
class ContinuationState:
    """What the continuation carries from one step to the next (kept in checkpoints).

    Attributes:
        length: the next step's arc length Δl [m]; None before the first step.
        largest: the longest a step may be [m] (ten times the first step's); None before.
        first_rate: Δλ/Δl [1/m] of the first step that moved: the path's initial stiffness.
        peak: the highest value of the parameter along the path so far.
        peak_step: the step at which it was reached (0: the start).
        values: the parameter after each committed step.
        rates: each committed step's Δλ/Δl over ``first_rate`` (Bergan's current stiffness
            parameter: 1 at the start, 0 at a limit point, negative past it).
        collapse: the collapse found (the peak's ``value`` and ``step``), None while none.
    """

    length: float | None = None
    largest: float | None = None
    first_rate: float | None = None
    peak: float = -math.inf
    peak_step: int = 0
    values: list[float] = field(default_factory=list)
    rates: list[float] = field(default_factory=list)
    collapse: dict[str, float] | None = None

    def commit(self, step: int, value: float, change: float, length: float) -> None:
        """Record the parameter ``value`` reached at ``step`` by a ``change`` over an arc of
        ``length`` [m]; a collapse once the current stiffness parameter has stayed within
        ±:data:`PLATEAU_STIFFNESS` for :data:`PLATEAU_STEPS` steps (the parameter stalls while
        the displacement runs on); its value is the path's peak then."""
        self.values.append(float(value))
        if value > self.peak:
            self.peak, self.peak_step = float(value), step
        if length > 0 and self.first_rate is None and change != 0:
            self.first_rate = abs(change) / length
        rate = (change / length / self.first_rate
                if length > 0 and self.first_rate else math.nan)
        self.rates.append(float(rate))
        window = self.rates[-PLATEAU_STEPS:]
        if (self.collapse is None and len(window) == PLATEAU_STEPS
                and all(abs(r) <= PLATEAU_STIFFNESS for r in window)):
            self.collapse = {"value": self.peak, "step": self.peak_step}

    def as_dict(self) -> dict[str, object]:
        """The state as plain values (JSON)."""
        return {"length": self.length, "largest": self.largest,
                "first_rate": self.first_rate, "peak": self.peak,
                "peak_step": self.peak_step, "values": list(self.values),
                "rates": list(self.rates), "collapse": self.collapse}

    @classmethod
    def from_dict(cls, data: dict[str, object]) -> ContinuationState:
        """The state :meth:`as_dict` gave."""
        return cls(length=data.get("length"), largest=data.get("largest"),  # type: ignore[arg-type]
                   first_rate=data.get("first_rate"),  # type: ignore[arg-type]
                   peak=float(data.get("peak", -math.inf)),  # type: ignore[arg-type]
                   peak_step=int(data.get("peak_step", 0)),  # type: ignore[arg-type]
                   values=[float(v) for v in data.get("values", [])],  # type: ignore[union-attr]
                   rates=[float(v) for v in data.get("rates", [])],  # type: ignore[union-attr]
                   collapse=data.get("collapse"))  # type: ignore[arg-type]
