"""The block path (``kernels_block.step_block``: one thread block an RVE, many steps a
launch) on warp's CPU device, against the two-kernel step (``contact_forces`` →
``integrate``, CUDA's path), both run on the CPU.

With one thread a block (the CPU's default) the block path adds every sum in the two-kernel
step's order, so the two agree bit for bit; with 8 threads a block (warp's cooperative CPU
blocks) only the servo's stress and stiffness sums are added in another order, so the runs
under the servo agree to rounding, within the tolerances of CUDA against the CPU
(``benchmarks/gpu_check.py``: stress within 1e-6 in float64, 1e-3 in float32)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from dem_helpers import calm_and_violent, load_shear_or_servo

from granular_material.dem import DEMBatch, DEMInstabilityError, load_rve, solver_block
from granular_material.dem.kernels.block import BLOCK_DISCS
from granular_material.dem.solver_block import BLOCK_MIN_RVES, block_path_expected_to_pay

SHEAR = 2e-5  #: strain a step, enough for several list rebuilds within the run
#: stress tolerance of CUDA against the CPU (benchmarks/gpu_check.py, tests/test_dem_cuda.py)
TOLERANCE = {"float64": 1e-6, "float32": 1e-3}


@pytest.fixture
def cpu_blocks():
    """warp's cooperative CPU blocks (more than one thread a block) for one test."""
    before = wp.config.enable_cpu_blocks
    wp.config.enable_cpu_blocks = True
    yield
    wp.config.enable_cpu_blocks = before


def _batch(path, block: bool, dtype: str = "float64", threads: int = 1,
           n_rve: int = 3) -> DEMBatch:
    batch = DEMBatch(load_rve(path).replicate(n_rve), device="cpu", dtype=dtype, shards=1)
    for shard in batch.shards:
        assert not shard.solver.block  # the engine's choice on the CPU
        shard.solver.serial = False
        shard.solver.block = block
        shard.solver.block_threads = threads
    return batch


def _load(batch: DEMBatch, servo: bool) -> None:
    load_shear_or_servo(batch, servo, SHEAR)


def _run(batch: DEMBatch) -> None:
    batch.run(150)
    batch.set_cell(batch.cell())  # lists rebuilt (history kept) between two runs
    batch.run(150, check_every=70)  # chunks that end between rebuilds


def _differences(batch: DEMBatch, reference: DEMBatch) -> dict[str, float]:
    got, want = batch.to_data(), reference.to_data()
    out = {name: float(np.abs(getattr(got, name) - getattr(want, name)).max())
           for name in ("position", "velocity", "angular_velocity", "cell")}
    out["shear"] = float(np.abs(got.extra["contact_shear_force"]
                                - want.extra["contact_shear_force"]).max())
    stress, stress_ref = batch.homogenize().stress, reference.homogenize().stress
    out["stress"] = float(np.abs(stress - stress_ref).max() / np.abs(stress_ref).max())
    return out


@pytest.mark.parametrize(("dtype", "servo"), [
    ("float64", False), ("float64", True), ("float32", True),
])
def test_block_path_with_one_thread_matches_the_two_kernel_step(small_rve_path, dtype,
                                                                servo):
    batch = _batch(small_rve_path, True, dtype)
    reference = _batch(small_rve_path, False, dtype)
    for b in (batch, reference):
        _load(b, servo)
        _run(b)
    assert _differences(batch, reference) == dict.fromkeys(
        ("position", "velocity", "angular_velocity", "cell", "shear", "stress"), 0.0)
    # 3 chunks, and the lists were rebuilt within them: more rounds than chunks
    assert batch.shards[0].solver.block_rounds > 3


@pytest.mark.parametrize(("dtype", "servo"), [
    ("float64", False), ("float64", True), ("float32", True),
])
def test_block_path_with_eight_threads_a_block(small_rve_path, cpu_blocks, dtype, servo):
    """8 cooperative threads a block, 100 discs: the discs of a thread are strided, the
    barriers and block reductions are exercised."""
    batch = _batch(small_rve_path, True, dtype, threads=8)
    reference = _batch(small_rve_path, False, dtype)
    for b in (batch, reference):
        _load(b, servo)
        _run(b)
    diff = _differences(batch, reference)
    if not servo:  # no block sum enters the state: bit for bit
        assert max(diff.values()) == 0.0, diff
    else:
        assert diff["stress"] <= TOLERANCE[dtype], diff
        if dtype == "float64":  # tight: rounding of the servo's sums, over 300 steps
            assert diff["stress"] <= 1e-10 and diff["cell"] <= 1e-12, diff


def test_frozen_rves_stay_as_they_are(small_rve_path):
    batch = _batch(small_rve_path, True)
    reference = _batch(small_rve_path, False)
    for b in (batch, reference):
        _load(b, False)
        b.set_active(np.array([True, False, True]))
        b.run(120)
    assert max(_differences(batch, reference).values()) == 0.0
    frozen = load_rve(small_rve_path)
    assert np.array_equal(batch.to_data().position[1], frozen.position[0])


def test_blow_up_names_the_rve_on_the_block_path(two_discs):
    """RVE 1 starts with two discs almost on top of each other: it, and only it, is named
    (as on the existing path, tests/test_dem_errors.py); the calm one steps on."""
    data = calm_and_violent(two_discs)
    batch = DEMBatch(data, device="cpu", shards=1)
    batch.shards[0].solver.block = True
    batch.set_affine(np.zeros((2, 2, 2)))
    with pytest.raises(DEMInstabilityError, match=r"RVE\(s\) 1 ") as info:
        batch.run(50, check_every=10)
    assert info.value.rve == [1]
    assert np.isfinite(batch.shards[0].state.fractional_position.numpy()).all()


def test_the_engine_chooses_the_block_path_only_where_measured_to_pay(monkeypatch):
    """Unmeasured on a GPU, so never (BLOCK_MIN_RVES None); once a size is set, only on
    CUDA, from that many RVEs on, and never for RVEs beyond the shared tiles."""
    assert BLOCK_MIN_RVES is None
    assert not block_path_expected_to_pay(True, 4096, 400)
    monkeypatch.setattr(solver_block, "BLOCK_MIN_RVES", 64)
    assert block_path_expected_to_pay(True, 4096, 400)
    assert block_path_expected_to_pay(True, 64, BLOCK_DISCS)
    assert not block_path_expected_to_pay(True, 63, 400)
    assert not block_path_expected_to_pay(True, 4096, BLOCK_DISCS + 1)
    assert not block_path_expected_to_pay(False, 4096, 400)


def test_block_path_refuses_rves_beyond_its_tiles(small_rve_path, monkeypatch):
    batch = _batch(small_rve_path, False)
    solver = batch.shards[0].solver
    monkeypatch.setattr("granular_material.dem.solver.BLOCK_DISCS", 50)
    with pytest.raises(ValueError, match="at most 50 discs"):
        solver.block = True


def test_switching_paths_within_a_run_keeps_the_results(small_rve_path):
    """The two-kernel step, the block path, then the two-kernel step again on one batch
    (each switch gives fresh records and drops the launches recorded with the old ones)
    against the two-kernel step throughout, with a snapshot restored on the way."""
    batch = _batch(small_rve_path, False)
    reference = _batch(small_rve_path, False)
    solver = batch.shards[0].solver
    for b in (batch, reference):
        _load(b, False)
        b.run(100)
    start = batch.snapshot()
    solver.block = True
    batch.run(60)
    batch.restore(start)
    batch.run(100)
    solver.block = False
    batch.run(100)
    reference.run(200)
    assert max(_differences(batch, reference).values()) == 0.0
