"""Step kernels specialised to the scene (no friction, no damping, no servo) give the generic
kernels' results exactly."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from granular_material.dem import DEMBatch, load_rve
from granular_material.dem.kernels.sets import GENERIC_STEP, StepFeatures

SHEAR = 2e-5  #: strain a step, enough for list rebuilds within the run


def _batch(path, dtype: str = "float64", damping: float | None = None,
           generic: bool = False) -> DEMBatch:
    data = load_rve(path).replicate(2)
    if damping is not None:
        data = replace(data, meta=replace(data.meta, damping=damping))
    batch = DEMBatch(data, device="cpu", dtype=dtype, shards=1)
    if generic:
        for shard in batch.shards:
            shard.solver.features = GENERIC_STEP
    return batch


def _shear(batch: DEMBatch) -> None:
    grad = np.zeros((batch.n_rve, 2, 2))
    grad[:, 0, 1] = SHEAR / batch.dt
    batch.set_affine(grad)


def _servo(batch: DEMBatch) -> None:
    target = np.tile([[-100e3, -SHEAR]], (batch.n_rve, 1))  # sxx held, eyy compressed
    batch.set_servo(np.tile([[1, 0]], (batch.n_rve, 1)), target, gain=0.5, max_strain=1e-4)


def _features(batch: DEMBatch) -> StepFeatures:
    shard = batch.shards[0]
    return shard.solver.step_features(shard.model, shard.loading)


def _assert_same(batch: DEMBatch, reference: DEMBatch) -> None:
    got, want = batch.to_data(), reference.to_data()
    for name in ("position", "velocity", "angular_velocity", "cell"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
    assert np.array_equal(got.extra["contact_shear_force"],
                          want.extra["contact_shear_force"])
    assert np.array_equal(batch.homogenize().stress, reference.homogenize().stress)


@pytest.mark.parametrize(("friction", "damping", "expected"), [
    (0.0, None, StepFeatures(tangential=False, stress=False)),
    (None, 0.0, StepFeatures(damping=False, stress=False)),
    (0.0, 0.0, StepFeatures(tangential=False, damping=False, stress=False)),
])
def test_variant_is_picked_and_matches_the_generic_kernels(small_rve_path, friction, damping,
                                                           expected):
    """Frictionless and/or undamped shearing: the picked variant (the consolidated packing's
    shear history is left over from friction 0.5 and must be zeroed) matches bit for bit."""
    batch = _batch(small_rve_path, damping=damping)
    reference = _batch(small_rve_path, damping=damping, generic=True)
    for b in (batch, reference):
        if friction is not None:
            b.set_friction(friction)
        _shear(b)
        b.run(300)
    assert _features(batch) == expected
    assert _features(reference) == GENERIC_STEP
    _assert_same(batch, reference)
    if friction == 0.0:
        assert not batch.to_data().extra["contact_shear_force"].any()


def test_servo_on_and_off_and_friction_change_follow(small_rve_path):
    """A frictionless servo run, then friction 0.5 under affine shear: the variant is picked
    again at each change (recorded launches and graph included) and matches throughout."""
    batch = _batch(small_rve_path)
    reference = _batch(small_rve_path, generic=True)
    for b in (batch, reference):
        b.set_friction(0.0)
        _servo(b)
        b.run(250)
    assert _features(batch) == StepFeatures(tangential=False)
    _assert_same(batch, reference)
    for b in (batch, reference):
        _shear(b)
        b.run(120)
    assert _features(batch) == StepFeatures(tangential=False, stress=False)
    _assert_same(batch, reference)
    for b in (batch, reference):
        b.set_friction(0.5)
        b.run(230)
    assert _features(batch) == _features(reference) == GENERIC_STEP
    _assert_same(batch, reference)
    assert batch.to_data().extra["contact_shear_force"].any()


def test_float32_variant_matches_float32_generic(small_rve_path):
    batch = _batch(small_rve_path, dtype="float32", damping=0.0)
    reference = _batch(small_rve_path, dtype="float32", damping=0.0, generic=True)
    for b in (batch, reference):
        b.set_friction(0.0)
        _shear(b)
        b.run(200)
    assert _features(batch) == StepFeatures(tangential=False, damping=False, stress=False)
    _assert_same(batch, reference)


def test_the_stress_variant_matches_without_servo(small_rve_path):
    """A frictional, damped scene keeps the generic kernels (no extra module); the variant
    without the stress sums, forced on it without servo, matches them."""
    batch = _batch(small_rve_path)
    reference = _batch(small_rve_path, generic=True)
    _shear(batch)
    assert _features(batch) == GENERIC_STEP
    for shard in batch.shards:
        shard.solver.features = StepFeatures(stress=False)
    for b in (batch, reference):
        _shear(b)
        b.run(200)
    _assert_same(batch, reference)
