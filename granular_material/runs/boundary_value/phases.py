"""The phases of a staged boundary-value run (``[[phases]]``,
:class:`~granular_material.runs.boundary_value.spec.PhaseSpec`): each phase as a one-phase
problem of its own, and the state a phase hands to the next.

A phase is run as the scene without phases would run its conditions
(:func:`phase_view`), with two differences the runner makes when the phase starts from the
state the phase before committed:

- its loads start where the phase before left them: each pressure goes from the total that
  acted on its boundary at the end of the phase before to its own total (a boundary loaded
  before and not in this phase: to zero), gravity from the factor the phase before ended
  with to its own;
- its prescribed displacements are increments: u_D(λ) = u_start + λ·Δ
  (:class:`~granular_material.fem.boundary_value.loading.Loading`'s ``dirichlet_start``),
  so that a support is held where the phase finds it.

A phase with ``reset_displacements`` reports displacement and strain from its start: the
solver's displacement stays the total one (in the updated-Lagrangian formulation it is the
configuration x = X + u, which a reset must not move), and what is written is u − u_reset and
the strain of the deformation since then (:func:`reported_gradient`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from granular_material.fem.boundary_value.meshes import MeshData
from granular_material.fem.kinematics import Kinematics
from granular_material.runs.boundary_value.spec import BoundaryValueSpec, ConditionSpec

__all__ = ["PhasePlan", "inward_direction", "phase_of_step", "phase_pressures",
           "phase_start_residual", "phase_view", "pressure_totals", "reported_gradient"]


def pressure_totals(spec: BoundaryValueSpec, index: int) -> dict[str, float]:
    """The pressure [Pa] on each boundary at the end of phase ``index`` (pressures on one
    boundary add up), in the order the boundaries are first loaded."""
    totals: dict[str, float] = {}
    phase = spec.phases[index]
    for c in (*spec.conditions, *phase.conditions):
        if c.type == "pressure":
            end = c.value if index > 0 or c.end is None else c.end
            totals[c.boundary] = totals.get(c.boundary, 0.0) + float(end)
    return totals


def _gravity_factors(spec: BoundaryValueSpec, index: int) -> tuple[float, float]:
    """γ's multiples at the start and the end of phase ``index``."""
    before = None
    for k in range(index + 1):
        start, end = spec.phases[k].factors(before)
        before = end
    return start, end


def phase_view(spec: BoundaryValueSpec, index: int) -> BoundaryValueSpec:
    """Phase ``index`` of the phased ``spec`` as a problem without phases: its conditions (the
    common ones, then its own; a later phase's pressures from the totals the phase before
    ended with to its own), its gravity factors and its steps. Its prescribed displacements
    are the increments of the phase."""
    phase = spec.phases[index]
    if index == 0:
        conditions = (*spec.conditions, *phase.conditions)
    else:
        before = pressure_totals(spec, index - 1)
        now = pressure_totals(spec, index)
        held = tuple(c for c in (*spec.conditions, *phase.conditions) if c.type != "pressure")
        loads = tuple(ConditionSpec(type="pressure", boundary=name,
                                    value=before.get(name, 0.0), end=now.get(name, 0.0))
                      for name in dict.fromkeys([*before, *now]))
        conditions = held + loads
    weighted = spec.unit_weight != 0.0 or any(m.unit_weight not in (None, 0.0)
                                              for m in spec.materials or ())
    factor = _gravity_factors(spec, index) if weighted else None
    return replace(spec, conditions=conditions, gravity_factor=factor, steps=phase.steps,
                   phases=())


def phase_of_step(steps: Sequence[int], step: int) -> tuple[int, int]:
    """(phase index, steps done in it) of a run of phases of ``steps`` load steps each whose
    last committed step is ``step``: a step that ends a phase is the next phase's start,
    with 0 done (the last phase's end: its index and all its steps)."""
    first = 0
    for k, n in enumerate(steps):
        if step < first + n or k == len(steps) - 1:
            return k, step - first
        first += n
    raise ValueError("a phased run has at least one phase")


def phase_pressures(view: BoundaryValueSpec) -> dict[str, tuple[float, float]]:
    """The pressure [Pa] on each boundary of a phase (:func:`phase_view`) at its start and
    at its end (pressures on one boundary add up)."""
    out: dict[str, tuple[float, float]] = {}
    for c in view.conditions:
        if c.type == "pressure":
            start, end = out.get(c.boundary, (0.0, 0.0))
            out[c.boundary] = (start + float(c.value),
                               end + float(c.value if c.end is None else c.end))
    return out


def inward_direction(mesh: MeshData, name: str) -> np.ndarray:
    """The unit vector (2,) into the body across the boundary ``name`` (the mean of its
    facets' inward normals, weighted by their lengths): the direction a pressure on it
    pushes."""
    m = mesh.mesh
    facets = mesh.boundaries[name]
    ends = m.p[:, m.facets[:, facets]]  # (2, 2 ends, n)
    tangent = ends[:, 1] - ends[:, 0]
    normal = np.array([tangent[1], -tangent[0]])  # length-weighted, either way round
    element = m.f2t[0, facets]
    centre = m.p[:, m.t[:, element]].mean(axis=1)
    inward = np.sign(np.einsum("in,in->n", normal, centre - ends.mean(axis=1)))
    total = (normal * inward).sum(axis=1)
    return total / max(float(np.linalg.norm(total)), 1e-300)


@dataclass
class PhasePlan:
    """One phase as the runner steps it.

    Attributes:
        index: its position (0: the first).
        name: its name (None: a problem without phases).
        steps: its load steps.
        first_step: the run's step number before its first step (its steps are
            first_step + 1 …).
        problem: its problem (mesh, conditions, loading; prescribed displacements as
            increments).
        settings: Newton's settings for it (the force tolerance follows its free dofs).
        view: the phase as a problem without phases (:func:`phase_view`).
        reset: report displacement and strain from the phase's start.
        pressures: the pressure [Pa] on each loaded boundary at the phase's start and end.
    """

    index: int
    name: str | None
    steps: int
    first_step: int
    problem: Any
    settings: Any
    view: BoundaryValueSpec
    reset: bool = False
    pressures: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def last_step(self) -> int:
        """The run's step number of its last step."""
        return self.first_step + self.steps


def reported_gradient(kinematics: Kinematics, grad_u: np.ndarray,
                      grad_offset: np.ndarray | None) -> np.ndarray:
    """The displacement gradient [-] (n, 2, 2) whose strain is reported: ∇_X u, or, after a
    reset at displacement u_r (``grad_offset`` = ∇_X u_r), that of the deformation since:
    ∇_X(u − u_r) (small strain) or ∇_X(u − u_r)·F_r⁻¹, so that I + it = F·F_r⁻¹ (finite
    strain)."""
    if grad_offset is None:
        return grad_u
    return kinematics.material_gradient(grad_offset, grad_u - grad_offset)


def phase_start_residual(solver: Any) -> float:
    """‖R‖ over the free dofs at the start of the solver's phase (λ = 0), relative to the
    load there (or, without one, to ‖f_int‖): about zero where the state the phase before
    committed is in equilibrium with the phase's start; a released support leaves its
    reaction here."""
    _, f_ext = solver.loading.at(0.0, solver.u if solver.kinematics.finite else None)
    residual = solver.f_int - f_ext
    free = np.ones(residual.size, dtype=bool)
    free[solver.loading.dirichlet_dofs] = False
    norm = float(np.linalg.norm(residual[free]))
    scale = float(np.linalg.norm(f_ext[free])) or float(np.linalg.norm(solver.f_int)) or 1.0
    return norm / scale
