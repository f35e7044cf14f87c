"""Unconfined DEM points: found against their own initial pressure, and their tangent (not
their stress) floored by their initial tangent."""

from __future__ import annotations

import numpy as np

from granular_material.multiscale.confinement import (
    UNCONFINED_FRACTION,
    UNCONFINED_TANGENT,
    floored_tangent,
    unconfined,
)


def test_a_point_is_unconfined_against_its_own_initial_pressure():
    stress = -np.array([1e3, 50.0, 5.0])[:, None, None] * np.eye(2)
    initial = np.array([1e3, 10e3, 1e3])
    mask = unconfined(stress, np.ones(3, bool), initial)
    assert mask.tolist() == [False, True, True]
    assert not unconfined(stress, np.array([True, False, False]), initial).any()
    assert unconfined(-0.99 * UNCONFINED_FRACTION * 1e3 * np.eye(2)[None], np.ones(1, bool),
                      1e3).all()


def test_only_unconfined_points_get_the_floor():
    rng = np.random.default_rng(1)
    tangent = np.zeros((3, 2, 2, 2, 2))
    initial = rng.normal(size=(3, 2, 2, 2, 2))
    mask = np.array([False, True, False])
    out = floored_tangent(tangent, initial, mask)
    assert np.array_equal(out[[0, 2]], tangent[[0, 2]])
    assert np.allclose(out[1], UNCONFINED_TANGENT * initial[1])
    assert np.array_equal(tangent, np.zeros_like(tangent))  # the input is not changed
    assert floored_tangent(tangent, initial, np.zeros(3, bool)) is tangent
