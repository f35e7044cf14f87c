"""Bad input gives clear errors naming the value; a blow-up names the RVEs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from dem_helpers import calm_and_violent

from granular_material.dem import (
    DEMBatch,
    DEMInstabilityError,
    RVEFileError,
    critical_timestep,
    load_rve,
    save_rve,
)
from granular_material.procedures import drive_grad_u


def test_non_positive_radius_is_named(two_discs, tmp_path):
    data = two_discs((0.05, 0.1), (0.08, 0.1))
    bad = replace(data, radius=np.array([[5e-3, -1e-3]]))
    with pytest.raises(RVEFileError, match=r"radius must be positive.*-0\.001"):
        DEMBatch(bad, device="cpu")
    with pytest.raises(RVEFileError, match="radius"):
        save_rve(tmp_path / "bad.npz", bad)
    assert not (tmp_path / "bad.npz").exists()


def test_cell_too_small_for_its_discs(two_discs):
    data = two_discs((0.005, 0.005), (0.012, 0.005), cell=np.eye(2) * 0.01)
    with pytest.raises(RVEFileError, match="too small for its discs"):
        DEMBatch(data, device="cpu")


def test_timestep_above_stable_is_refused(two_discs):
    data = two_discs((0.05, 0.1), (0.08, 0.1))
    crit = critical_timestep(data.radius, data.meta)
    with pytest.raises(ValueError, match="above the stable step"):
        DEMBatch(replace(data, meta=replace(data.meta, timestep=2 * crit)), device="cpu")


def test_nan_and_inverting_grad_u_are_refused(two_discs):
    batch = DEMBatch(two_discs((0.05, 0.1), (0.08, 0.1)), device="cpu")
    with pytest.raises(ValueError, match="not finite"):
        drive_grad_u(batch, np.array([[np.nan, 0.0], [0.0, 0.0]]))
    with pytest.raises(ValueError, match="inverts the cell"):
        drive_grad_u(batch, np.array([[-1.5, 0.0], [0.0, 0.0]]))


def test_unreadable_file(tmp_path):
    path = tmp_path / "junk.npz"
    path.write_bytes(b"not an npz at all")
    with pytest.raises(RVEFileError, match="not a readable RVE file"):
        load_rve(path)
    np.savez(tmp_path / "partial.npz", radius=np.ones((1, 3)))
    with pytest.raises(RVEFileError, match="missing array"):
        load_rve(tmp_path / "partial.npz")


def test_blow_up_names_the_rve(two_discs):
    """RVE 1 starts with two discs almost on top of each other: it, and only it, is named."""
    data = calm_and_violent(two_discs)
    batch = DEMBatch(data, device="cpu")
    batch.set_affine(np.zeros((2, 2, 2)))
    with pytest.raises(DEMInstabilityError, match=r"RVE\(s\) 1 ") as info:
        batch.run(50, check_every=10)
    assert info.value.rve == [1]
    assert all(np.isfinite(s.state.fractional_position.numpy()).all() for s in batch.shards)
