"""The basis of a periodic cell's lattice: a sheared cell re-described by its least skewed
basis (YADE's ``Cell.flipCell``), the same packing with larger perpendicular heights.

A periodic RVE is the lattice of its cell vectors (the columns of H); any basis H' = H·M with
M an integer matrix of determinant 1 spans the same lattice, so the same infinite packing. A
cell sheared far (beside a footing's edge, in a shear band) has one short perpendicular
height, and the engine's minimum images need the contact cut-off below half of it
(:func:`~granular_material.dem.model.cell_heights`); its Lagrange–Gauss reduced basis has
the largest heights the lattice allows. Discs keep their places (fractional coordinates
s' = M⁻¹·s, wrapped into [0, 1)), their velocities and their contacts (partners are indices;
branch vectors are minimum images): the state is the same packing, re-described.
"""

from __future__ import annotations

import numpy as np

__all__ = ["rebase_state", "reduced_basis"]

#: Lagrange–Gauss reduction of a 2D basis ends in a few rounds; a cap against NaN input
_MAX_ROUNDS = 64
#: |h1·h2|/|h1|² up to 1/2 + this counts as reduced, so that a basis on a tie is its own
_TIE = 1e-9


def reduced_basis(cell: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H', M) for a cell H [m] (2, 2) (columns = cell vectors): H' = H·M the Lagrange–Gauss
    reduced basis of the same lattice (its first column the shorter, and the projection of
    the second on the first at most half the first's length), M an integer matrix of
    determinant +1 (the orientation kept); M = I where H is reduced already."""
    h = np.asarray(cell, dtype=np.float64).copy()
    change = np.eye(2, dtype=np.int64)
    for _ in range(_MAX_ROUNDS):
        if h[:, 0] @ h[:, 0] > h[:, 1] @ h[:, 1]:  # the shorter first: (h1, h2) -> (h2, -h1)
            h = np.stack([h[:, 1], -h[:, 0]], axis=1)
            change = np.stack([change[:, 1], -change[:, 0]], axis=1)
        ratio = (h[:, 0] @ h[:, 1]) / (h[:, 0] @ h[:, 0])
        if not abs(ratio) > 0.5 + _TIE:  # reduced (a tie stays as it is: M = I again)
            break
        mu = int(np.rint(ratio))
        h[:, 1] -= mu * h[:, 0]
        change[:, 1] -= mu * change[:, 0]
    return np.asarray(cell, dtype=np.float64) @ change, change


def rebase_state(cell: np.ndarray, fractional: np.ndarray,
                 ) -> tuple[np.ndarray, np.ndarray, bool]:
    """One RVE's cell H [m] (2, 2) and fractional positions (N, 2) in its reduced basis:
    (H', s' = M⁻¹·s wrapped into [0, 1), whether the basis changed)."""
    reduced, change = reduced_basis(cell)
    if np.array_equal(change, np.eye(2, dtype=np.int64)):
        return np.asarray(cell), np.asarray(fractional), False
    inverse = np.array([[change[1, 1], -change[0, 1]], [-change[1, 0], change[0, 0]]])
    s = np.asarray(fractional, dtype=np.float64) @ inverse.T.astype(np.float64)
    s -= np.floor(s)
    s[s >= 1.0] = 0.0  # a coordinate a rounding below 0 wraps to 1.0 - floor: keep [0, 1)
    return reduced, s, True
