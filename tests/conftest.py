"""Shared fixtures: quiet warp, a small consolidated RVE prepared once per session."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import warp as wp

import granular_material
from granular_material.dem import RVEData, RVEMeta

granular_material.verbose(False)  # whatever GRANULAR_MATERIAL_VERBOSE says
wp.init()


@pytest.fixture(scope="session")
def small_rve_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An RVE file of 100 discs (seed 3) consolidated to 100 kPa with friction 0.5 rad."""
    from granular_material.dem import save_rve
    from granular_material.procedures import prepare_packing

    batch = prepare_packing(n_disc=100, n_rve=1, seed=3, pressure=100e3, device="cpu")
    path = tmp_path_factory.mktemp("rve") / "small.npz"
    save_rve(path, batch.to_data())
    return path


@pytest.fixture
def two_discs() -> Callable[..., RVEData]:
    """Factory: RVEData of two equal discs at x_a, x_b [m] in a (0.2 m square) cell."""
    return _two_disc_data


def _two_disc_data(
    x_a: tuple[float, float],
    x_b: tuple[float, float],
    radius: float = 5e-3,
    cell: np.ndarray | None = None,
    **meta_fields: object,
) -> RVEData:
    cell = np.eye(2) * 0.2 if cell is None else np.asarray(cell, dtype=float)
    return RVEData(
        radius=np.full((1, 2), radius),
        position=np.array([[x_a, x_b]], dtype=float),
        cell=cell[None],
        velocity=np.zeros((1, 2, 2)),
        angular_velocity=np.zeros((1, 2)),
        meta=RVEMeta(**meta_fields),
    )
