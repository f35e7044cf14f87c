"""The material protocol that the Newton driver and scikit-fem scripts talk to.

A material holds one constitutive state per Gauss point. The driver evaluates it with the
displacement gradient accumulated since the last commit and, once the load step has
converged, commits it. Arrays are batch-first: point ``p`` of a mesh is ``element * nqp + q``
(see :mod:`granular_material.fem.layout`).

Two ways in, one state:

- ``evaluate(grad_u)`` is the protocol's: batch-first ``(n, 2, 2)`` and the *increment*
  ∇u since the last commit. The project's :class:`~granular_material.fem.solver.newton.NewtonSolver`
  calls it, and nothing about it changes.
- ``response(grad_u, measure="total")`` (:class:`ScikitFemInterface`, offered by both
  shipped materials) is what a scikit-fem, felupe or MGIS user expects: the *total* ∇u by
  default (``measure="increment"`` for the protocol's), in any layout of
  :func:`~granular_material.fem.layout.grad_points` (batch-first, scikit-fem's quadrature-last
  ``(2, 2, nelems, nqp)``, or a ``DiscreteField``), answered in that same layout
  (:class:`QuadratureResponse` for quadrature-last input).

How the material knows the committed state: it keeps the total ∇u of its committed state,
:attr:`ScikitFemInterface.committed_grad_u` (zero at ``allocate``; every ``commit`` makes
the last evaluation's total the committed one, whichever way it was evaluated). A total is
turned into the increment ``∇u − committed_grad_u`` and evaluated as such. This is the
small-strain composition of the project's default formulation (the mesh does not move, so
the reference configuration is also the configuration of the last commit); a finite-strain
(updated-Lagrangian) user passes increments measured on the committed configuration,
``∇_X Δu · F_n⁻¹``, with ``measure="increment"``.

Kinematics and measures, for every material here: ∇u is ∂u_k/∂x_l on the configuration of
the last commit; the stress is the Cauchy stress σ [Pa], tension positive; the tangent is
D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) [Pa], a full fourth-order array. D has the major and the first
minor symmetry of σ (D_ijkl = D_jikl) but in general *not* the second minor symmetry
(D_ijkl ≠ D_ijlk): its spin part, the rotation of the stress by W = skw ∇u, makes it respond
to the skew part of ∇u. A Voigt/Mandel user (3 × 3 matrices on sym ∇u) must therefore either
keep the full (2, 2, 2, 2) tangent (recommended: scikit-fem's forms contract it with ∇v and
∇u directly) or, knowing that the spin term is then dropped, use the part that acts on the
strain, ½ (D_ijkl + D_ijlk), which is exact for the linear-elastic material and loses the
stress's rotation for the DEM one.

A failed point carries a reason (:class:`FailureReason`, the response's ``reasons``) and the
stress of its committed state, never NaN, in every shipped material: a ∇u that is NaN or
infinite at a point is that point's failure (``non_finite_input``); ∇u that is None, text,
complex or of another shape is a ``ValueError`` before any work. What ``commit()`` does after
an evaluation in which points failed is each material's (said in its class): the
linear-elastic and DEM materials commit the failed points' committed state unchanged (their
``committed_grad_u`` too), the Mohr–Coulomb material refuses the commit (RuntimeError);
none commits a non-finite state. ``allocate(n)`` refuses (ParameterError naming
``n_points``, with the estimate) a count that is not an integer >= 1 or whose state would
not fit in the memory available, before it takes any; ``restore(path)`` refuses another
material's checkpoint by that material's name (ValueError).

Semantics every implementation keeps:

- ``evaluate(grad_u)`` starts from the *committed* state, so calling it twice with the same
  ``grad_u`` gives the same answer (idempotent) and a failed Newton iteration costs no state
  (a DEM material with ``drive="continue"`` drives its RVEs on from their last trial state
  instead: still idempotent, but its answer depends on the iterates that came before);
- ``commit()`` makes the state of the last ``evaluate`` the committed one;
- ``revert()`` drops the trial state (the next ``evaluate`` starts from the committed one
  anyway, but a material that keeps its trial state in place restores it here);
- ``checkpoint(path)`` / ``restore(path)`` write and read the committed state;
- optionally, ``hold_tangent(hold)``: the Newton driver's ``tangent_update="hold"`` calls
  ``hold_tangent(True)`` before an increment's first evaluation and then uses that
  evaluation's tangent alone, so a material whose tangent is costly (the DEM material's
  condensed or perturbation tangent) may return it unchanged from the later evaluations,
  until the next ``commit`` or ``revert``. A material without it is evaluated as always.

Materials are found by name through the ``granular_material.materials`` entry-point group.
"""

from __future__ import annotations

import inspect
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from granular_material.entry_points import entry_point_names, load_entry_point
from granular_material.errors import ParameterError
from granular_material.fem.materials.response import (
    FailureReason,
    MaterialResponse,
    PointStatus,
    QuadratureResponse,
)
from granular_material.fem.materials.run_context import RunContext
from granular_material.fem.materials.scikit_fem_interface import MEASURES, ScikitFemInterface

__all__ = [
    "ENTRY_POINT_GROUP",
    "MEASURES",
    "FailureReason",
    "Material",
    "MaterialResponse",
    "PointStatus",
    "QuadratureResponse",
    "RunContext",
    "ScikitFemInterface",
    "available_materials",
    "create_material",
    "load_material",
]

#: the entry-point group where materials are found by name
ENTRY_POINT_GROUP = "granular_material.materials"


@runtime_checkable
class Material(Protocol):
    """What the Newton driver needs from a constitutive model (batch of Gauss points)."""

    @property
    def n_points(self) -> int:
        """Number of Gauss points allocated (0 before :meth:`allocate`)."""
        ...

    def allocate(self, n_points: int) -> None:
        """Create the initial committed state for ``n_points`` Gauss points."""
        ...

    def evaluate(self, grad_u: np.ndarray) -> MaterialResponse:
        """Response to ∇u [-], shape (n, 2, 2), measured from the committed state."""
        ...

    def commit(self) -> None:
        """Accept the state of the last :meth:`evaluate` as the committed state."""
        ...

    def revert(self) -> None:
        """Discard any trial state; the committed state is unchanged."""
        ...

    def checkpoint(self, path: str | Path) -> None:
        """Write the committed state to ``path``."""
        ...

    def restore(self, path: str | Path) -> None:
        """Read a committed state written by :meth:`checkpoint` (allocates as needed)."""
        ...


def available_materials() -> list[str]:
    """Names registered in the ``granular_material.materials`` entry-point group."""
    return entry_point_names(ENTRY_POINT_GROUP)


def load_material(name: str) -> type:
    """The material class registered under ``name``; ``ValueError`` naming the choices."""
    return load_entry_point(ENTRY_POINT_GROUP, name, "material")


def create_material(name: str, **parameters: Any) -> Material:
    """Instantiate the material ``name`` with keyword ``parameters`` (not yet allocated); a
    keyword the material does not take is a :class:`ParameterError` naming it."""
    cls = load_material(name)
    try:
        signature = inspect.signature(cls)
    except (TypeError, ValueError):  # no signature to read: the class checks its keywords
        signature = None
    if signature is not None and not any(
            p.kind is p.VAR_KEYWORD for p in signature.parameters.values()):
        unknown = sorted(set(parameters) - set(signature.parameters))
        if unknown:
            raise ParameterError(unknown[0], f"is no parameter of material {name!r} (it takes "
                                             f"{', '.join(signature.parameters)})")
    material = cls(**parameters)
    if not isinstance(material, Material):
        raise TypeError(f"material {name!r} does not implement the Material protocol")
    return material
