"""The loading of a boundary-value problem: boundary conditions against the load factor."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["Loading"]


@dataclass(frozen=True)
class Loading:
    """Boundary conditions as a linear function of the load factor λ ∈ [0, 1].

    Attributes:
        dirichlet_dofs: constrained degrees of freedom, shape (m,), int.
        dirichlet_end: prescribed displacement at λ = 1 [m], shape (m,); u_D(λ) = λ · end,
            or, with ``dirichlet_start``, u_D(λ) = start + λ · end (``end`` the increment).
        force_start: external nodal forces at λ = 0 [N/m], shape (ndofs,) (e.g. confinement).
        force_end: external nodal forces at λ = 1 [N/m], shape (ndofs,).
        follower: None, or the nodal forces [N/m] (ndofs,) of the load at λ = 0 acting on
            the configuration displaced by u [m] (ndofs,) — a pressure on the current sides,
            for the finite-strain formulation; it replaces ``force_start`` where a
            displacement is given.
        follower_end: None (the follower load is constant in λ: ``force_start`` equal to
            ``force_end``), or the follower of the load at λ = 1, which replaces
            ``force_end``; between them f_ext = (1 − λ)·follower(u) + λ·follower_end(u).
        dirichlet_start: None (u_D(λ) = λ · end, from 0), or the prescribed displacement
            [m] (m,) at λ = 0, to which λ · end is added (a later phase of a staged run,
            whose prescribed displacements are increments from where the phase starts).
    """

    dirichlet_dofs: np.ndarray
    dirichlet_end: np.ndarray
    force_start: np.ndarray
    force_end: np.ndarray
    follower: Callable[[np.ndarray], np.ndarray] | None = None
    follower_end: Callable[[np.ndarray], np.ndarray] | None = None
    dirichlet_start: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.dirichlet_dofs.shape != self.dirichlet_end.shape:
            raise ValueError(
                f"dirichlet_end shape {self.dirichlet_end.shape} does not match "
                f"dirichlet_dofs shape {self.dirichlet_dofs.shape}"
            )
        if (self.dirichlet_start is not None
                and self.dirichlet_start.shape != self.dirichlet_end.shape):
            raise ValueError(
                f"dirichlet_start shape {self.dirichlet_start.shape} does not match "
                f"dirichlet_end shape {self.dirichlet_end.shape}"
            )
        if self.force_start.shape != self.force_end.shape:
            raise ValueError(
                f"force_end shape {self.force_end.shape} differs from force_start "
                f"shape {self.force_start.shape}"
            )
        if self.follower_end is not None and self.follower is None:
            raise ValueError("a follower_end needs the follower of the load at λ = 0")
        if (self.follower is not None and self.follower_end is None
                and not np.array_equal(self.force_start, self.force_end)):
            raise ValueError("a follower load that changes with the load factor "
                             "(force_start differs from force_end) needs its follower_end")

    def at(self, load_factor: float, u: np.ndarray | None = None,
           ) -> tuple[np.ndarray, np.ndarray]:
        """(u_D [m] shape (m,), f_ext [N/m] shape (ndofs,)) at load factor λ; with a
        follower load and a displacement ``u`` [m], f_ext acts on the displaced
        configuration."""
        if u is not None and self.follower is not None:
            f = self.follower(u)
            if self.follower_end is not None:
                f = (1.0 - load_factor) * f + load_factor * self.follower_end(u)
            return self.prescribed(load_factor), f
        f = (1.0 - load_factor) * self.force_start + load_factor * self.force_end
        return self.prescribed(load_factor), f

    def prescribed(self, load_factor: float) -> np.ndarray:
        """u_D [m], shape (m,), at load factor λ: λ · end, plus the start where one is
        given."""
        if self.dirichlet_start is None:
            return load_factor * self.dirichlet_end
        return self.dirichlet_start + load_factor * self.dirichlet_end
