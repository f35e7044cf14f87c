"""The loading of a boundary-value problem: boundary conditions against the load factor."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Loading"]


@dataclass(frozen=True)
class Loading:
    """Boundary conditions as a linear function of the load factor λ ∈ [0, 1].

    Attributes:
        dirichlet_dofs: constrained degrees of freedom, shape (m,), int.
        dirichlet_end: prescribed displacement at λ = 1 [m], shape (m,); u_D(λ) = λ · end.
        force_start: external nodal forces at λ = 0 [N/m], shape (ndofs,) (e.g. confinement).
        force_end: external nodal forces at λ = 1 [N/m], shape (ndofs,).
    """

    dirichlet_dofs: np.ndarray
    dirichlet_end: np.ndarray
    force_start: np.ndarray
    force_end: np.ndarray

    def __post_init__(self) -> None:
        if self.dirichlet_dofs.shape != self.dirichlet_end.shape:
            raise ValueError(
                f"dirichlet_end shape {self.dirichlet_end.shape} does not match "
                f"dirichlet_dofs shape {self.dirichlet_dofs.shape}"
            )
        if self.force_start.shape != self.force_end.shape:
            raise ValueError(
                f"force_end shape {self.force_end.shape} differs from force_start "
                f"shape {self.force_start.shape}"
            )

    def at(self, load_factor: float) -> tuple[np.ndarray, np.ndarray]:
        """(u_D [m] shape (m,), f_ext [N/m] shape (ndofs,)) at load factor λ."""
        f = (1.0 - load_factor) * self.force_start + load_factor * self.force_end
        return load_factor * self.dirichlet_end, f
