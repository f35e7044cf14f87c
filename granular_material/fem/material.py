"""The material protocol that the Newton driver and scikit-fem scripts talk to.

A material holds one constitutive state per Gauss point. The driver evaluates it with the
displacement gradient accumulated since the last commit and, once the load step has
converged, commits it. Arrays are batch-first: point ``p`` of a mesh is ``element * nqp + q``
(see :mod:`granular_material.fem.layout`).

Semantics every implementation keeps:

- ``evaluate(grad_u)`` starts from the *committed* state, so calling it twice with the same
  ``grad_u`` gives the same answer (idempotent) and a failed Newton iteration costs no state
  (a DEM material with ``drive="continue"`` drives its RVEs on from their last trial state
  instead: still idempotent, but its answer depends on the iterates that came before);
- ``commit()`` makes the state of the last ``evaluate`` the committed one;
- ``revert()`` drops the trial state (the next ``evaluate`` starts from the committed one
  anyway, but a material that keeps its trial state in place restores it here);
- ``checkpoint(path)`` / ``restore(path)`` write and read the committed state.

Materials are found by name through the ``granular_material.materials`` entry-point group.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = [
    "ENTRY_POINT_GROUP",
    "Material",
    "MaterialResponse",
    "PointStatus",
    "available_materials",
    "create_material",
    "load_material",
]

ENTRY_POINT_GROUP = "granular_material.materials"


class PointStatus(enum.IntEnum):
    """Outcome of a material evaluation at one Gauss point."""

    OK = 0
    FAILED = 1  # no admissible state for this increment (instability, non-finite values)


@dataclass(frozen=True)
class MaterialResponse:
    """Stress, tangent and status at every Gauss point after one evaluation.

    Attributes:
        stress: Cauchy stress σ [Pa], tension positive, shape (n, 2, 2), float64.
        tangent: D_ijkl = ∂σ_ij/∂(∂u_k/∂x_l) [Pa], shape (n, 2, 2, 2, 2), float64.
        status: :class:`PointStatus` per point, shape (n,), int8.
        costs: what the evaluation cost, by name: numbers (int or float) whose names and
            units are the material's (e.g. the DEM material reports ``dem_steps``,
            ``rve_evaluations`` and ``particle_steps``); empty for a material that counts
            nothing (e.g. a closed-form law). The Newton driver sums each name over the
            evaluations of a load step (:attr:`~granular_material.fem.newton.StepRecord.costs`)
            and knows none of them; NumPy scalars are stored as Python numbers.
        fields: further per-point scalars for output (e.g. ``void_ratio``), each shape (n,).
    """

    stress: np.ndarray
    tangent: np.ndarray
    status: np.ndarray
    costs: Mapping[str, int | float] = field(default_factory=dict)
    fields: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "costs", _costs(self.costs))
        n = self.stress.shape[0]
        if self.stress.shape != (n, 2, 2):
            raise ValueError(f"stress must have shape (n, 2, 2), got {self.stress.shape}")
        if self.tangent.shape != (n, 2, 2, 2, 2):
            raise ValueError(
                f"tangent must have shape ({n}, 2, 2, 2, 2), got {self.tangent.shape}"
            )
        if self.status.shape != (n,):
            raise ValueError(f"status must have shape ({n},), got {self.status.shape}")

    @property
    def ok(self) -> bool:
        """True when every point succeeded and stress and tangent are finite."""
        return bool(
            np.all(self.status == PointStatus.OK)
            and np.isfinite(self.stress).all()
            and np.isfinite(self.tangent).all()
        )

    def failed_points(self) -> np.ndarray:
        """Indices of the points that failed or returned non-finite values, shape (k,)."""
        bad = (self.status != PointStatus.OK)
        bad |= ~np.isfinite(self.stress).all(axis=(1, 2))
        bad |= ~np.isfinite(self.tangent).all(axis=(1, 2, 3, 4))
        return np.flatnonzero(bad)


def _costs(costs: Mapping[str, Any]) -> dict[str, int | float]:
    """``costs`` as a dict of names to Python ints and floats; ValueError for a name that is
    not a string or a value that is not a real number (booleans included)."""
    out: dict[str, int | float] = {}
    for name, value in costs.items():
        if not isinstance(name, str):
            raise ValueError(f"a cost's name must be a string, got {name!r}")
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"cost {name!r} must be an int or a float, got {value!r}")
        out[name] = value
    return out


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
    return sorted({ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)})


def load_material(name: str) -> type:
    """The material class registered under ``name``; ``ValueError`` naming the choices."""
    matches = [ep for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name == name]
    if not matches:
        raise ValueError(
            f"material {name!r} is not registered; available: {', '.join(available_materials())}"
        )
    return matches[0].load()


def create_material(name: str, **parameters: Any) -> Material:
    """Instantiate the material ``name`` with keyword ``parameters`` (not yet allocated)."""
    material = load_material(name)(**parameters)
    if not isinstance(material, Material):
        raise TypeError(f"material {name!r} does not implement the Material protocol")
    return material
