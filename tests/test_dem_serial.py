"""The CPU's step, one serial pass per RVE (``kernels_step.step_serial``), against the step
of a thread per disc (``contact_forces`` → ``integrate``, CUDA's), both run on the CPU.

Where the lists are sorted by partner (every build leaves them so) the serial pass adds
each disc's forces in the gather's order, so the two agree bit for bit."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from dem_helpers import load_shear_or_servo

from granular_material.dem import DEMBatch, load_rve
from granular_material.dem.kernels.sets import GENERIC_STEP

SHEAR = 2e-5  #: strain a step, enough for list rebuilds within the run


def _batch(path, serial: bool, dtype: str = "float64", damping: float | None = None,
           friction: float | None = None) -> DEMBatch:
    data = load_rve(path).replicate(2)
    if damping is not None:
        data = replace(data, meta=replace(data.meta, damping=damping))
    batch = DEMBatch(data, device="cpu", dtype=dtype, shards=1)
    for shard in batch.shards:
        assert shard.solver.serial  # the engine's choice on the CPU
        shard.solver.serial = serial
    if friction is not None:
        batch.set_friction(friction)
    return batch


def _load(batch: DEMBatch, servo: bool) -> None:
    load_shear_or_servo(batch, servo, SHEAR)


def _assert_same(batch: DEMBatch, reference: DEMBatch) -> None:
    got, want = batch.to_data(), reference.to_data()
    for name in ("position", "velocity", "angular_velocity", "cell"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
    assert np.array_equal(got.extra["contact_shear_force"],
                          want.extra["contact_shear_force"])
    assert np.array_equal(batch.homogenize().stress, reference.homogenize().stress)


@pytest.mark.parametrize(("dtype", "damping", "friction", "servo"), [
    ("float64", None, None, True),  # generic kernels: friction, damping, servo
    ("float64", 0.0, None, False),  # undamped shear (the benchmark's scene)
    ("float64", None, 0.0, True),  # frictionless under the servo
    ("float32", None, None, True),
])
def test_serial_step_matches_the_parallel_step(small_rve_path, dtype, damping, friction,
                                               servo):
    batch = _batch(small_rve_path, True, dtype, damping, friction)
    reference = _batch(small_rve_path, False, dtype, damping, friction)
    for b in (batch, reference):
        _load(b, servo)
        b.run(150)
        b.set_cell(b.cell())  # lists rebuilt (history kept) halfway
        b.run(150)
    _assert_same(batch, reference)


def test_generic_serial_step_on_a_frictionless_scene(small_rve_path):
    """The generic serial kernel (forced) and the picked frictionless variant agree."""
    batch = _batch(small_rve_path, True, friction=0.0)
    reference = _batch(small_rve_path, False, friction=0.0)
    for shard in batch.shards:
        shard.solver.features = GENERIC_STEP
    for b in (batch, reference):
        _load(b, False)
        b.run(200)
    _assert_same(batch, reference)
