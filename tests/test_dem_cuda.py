"""CPU against CUDA, run whenever a GPU is available (skipped otherwise)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from granular_material.dem import DEMBatch, load_rve
from granular_material.procedures import biaxial_test, drive_grad_u

pytestmark = [
    pytest.mark.cuda,
    pytest.mark.skipif(not wp.is_cuda_available(), reason="no CUDA device"),
]


def test_strain_path_cpu_matches_cuda(small_rve_path):
    data = load_rve(small_rve_path).replicate(4)
    grad = np.array([[0.0, 2e-3], [0.0, -1e-3]])
    stresses = []
    for device in ("cpu", "cuda"):
        batch = DEMBatch(data, device=device)
        drive_grad_u(batch, grad)
        stresses.append(batch.homogenize().stress)
    # same kernels, same summation order per disc; only the compilers' FMA choices differ
    np.testing.assert_allclose(stresses[1], stresses[0], rtol=1e-6, atol=1e-3)


def test_cuda_is_deterministic_and_graph_replay_matches(small_rve_path):
    data = load_rve(small_rve_path).replicate(8)
    results = []
    for _ in range(2):
        batch = DEMBatch(data, device="cuda")
        # 475 steps: 50-step blocks replay a captured graph, the last 25 run eagerly
        batch.set_affine(np.zeros((8, 2, 2)))
        batch.run(475)
        results.append(batch.homogenize().stress)
    np.testing.assert_array_equal(results[0], results[1])
    np.testing.assert_array_equal(results[0][0], results[0][7])


def test_biaxial_on_cuda_matches_cpu_peak(small_rve_path):
    data = load_rve(small_rve_path)
    peaks = []
    for device in ("cpu", "cuda"):
        curve = biaxial_test(DEMBatch(data, device=device), axial_strain=0.02,
                             record_every=200)
        peaks.append(curve["stress_ratio"].max())
    assert peaks[1] == pytest.approx(peaks[0], rel=0.02)


@pytest.mark.parametrize(("dtype", "rtol"), [("float64", 1e-6), ("float32", 1e-3)])
def test_block_path_matches_the_two_kernel_step_on_cuda(small_rve_path, dtype, rtol):
    """The block path (one thread block an RVE, 128 threads) against the engine's CUDA
    step on a sheared batch and under the servo: the same steps, its servo sums in the
    block's order (the tolerances of CUDA against the CPU above and in gpu_check.py)."""
    data = load_rve(small_rve_path).replicate(4)
    for servo in (False, True):
        stresses = []
        for block in (False, True):
            batch = DEMBatch(data, device="cuda", dtype=dtype)
            batch.shards[0].solver.block = block
            if servo:
                batch.set_servo(np.tile([[1, 0]], (4, 1)), np.tile([[-100e3, -2e-5]], (4, 1)),
                                gain=0.5, max_strain=1e-4)
            else:
                grad = np.zeros((4, 2, 2))
                grad[:, 0, 1] = 2e-5 / batch.dt
                batch.set_affine(grad)
            batch.run(300, check_every=70)
            stresses.append(batch.homogenize().stress)
        assert batch.shards[0].solver.block_rounds > 5  # lists rebuilt between rounds
        scale = np.abs(stresses[0]).max()
        np.testing.assert_allclose(stresses[1], stresses[0], rtol=0, atol=rtol * scale)
