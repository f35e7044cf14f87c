"""The CPU-runnable pieces of ``benchmarks/gpu_check.sh``: it stops at once and says why
without a GPU, and its agreement check runs (a CPU against itself: every difference zero)."""

from __future__ import annotations

import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import warp as wp

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
#: the script's steps, in order
STEPS = ("tests", "throughput", "agreement", "condensed", "specimen", "paths",
         "block_specimen")


def _module():
    spec = importlib.util.spec_from_file_location("gpu_check", BENCH / "gpu_check.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.skipif(wp.is_cuda_available(), reason="a CUDA device is here")
def test_script_stops_with_a_message_without_a_gpu(tmp_path):
    out = tmp_path / "check"
    done = subprocess.run(["bash", str(BENCH / "gpu_check.sh"), str(out)],
                          capture_output=True, text=True, timeout=120,
                          env={"PYTHON": sys.executable, "PATH": "/usr/bin:/bin"})
    assert done.returncode == 2
    assert "no CUDA device" in done.stderr
    assert not out.exists()  # nothing started


@pytest.mark.skipif(wp.is_cuda_available(), reason="a CUDA device is here")
def test_require_cuda_prints_nothing_but_the_device_to_stdout():
    """Its stdout becomes summary.json's "device": warp's start-up banner must not reach it
    (on an H200 it did, and the file was not JSON)."""
    done = subprocess.run([sys.executable, str(BENCH / "gpu_check.py"), "require-cuda"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and done.stdout == ""


def test_script_is_valid_bash_and_names_every_step():
    text = (BENCH / "gpu_check.sh").read_text()
    assert subprocess.run(["bash", "-n", str(BENCH / "gpu_check.sh")]).returncode == 0
    for step in STEPS:
        assert f"run_step {step} " in text
    limits = [int(v) for v in re.findall(r"T_\w+=\$\{T_\w+:-(\d+)\}", text)]
    # the limits are caps (an H200 took 244 s for the first five, 2026-12-04): together they
    # fit, with the install and start-up, in one 10-minute command on a lent GPU machine
    assert len(limits) == len(STEPS) and sum(limits) <= 480


def test_gradients_cover_the_batch():
    grad = _module().gradients(7, 2e-3)
    assert grad.shape == (7, 2, 2)
    assert np.abs(grad).max() == pytest.approx(2e-3)
    assert len({tuple(g.ravel()) for g in grad}) == 7


def test_agreement_of_a_device_with_itself(tmp_path):
    summary = _module().agreement(tmp_path, device="cpu", reference="cpu", n_rve=3,
                                  particles=30, strain=5e-4, dtypes=("float64",))
    f64 = summary["dtypes"]["float64"]
    assert f64["max_stress_rel_diff"] == 0 and f64["max_tangent_rel_diff"] == 0
    assert summary["within_tolerance"]
    assert json.loads((tmp_path / "agreement.json").read_text())["n_rve"] == 3
    assert (tmp_path / "agreement.csv").read_text().count("\n") == 4


@pytest.mark.slow
def test_whole_script_at_smoke_size_on_the_cpu(tmp_path):
    """GPU_CHECK_SMOKE=1: every step of the script on the CPU at toy sizes (about 80 s on
    2 busy cores before the two steps of the block path), its results and summary.json
    where the script says."""
    out = tmp_path / "check"
    done = subprocess.run(["bash", str(BENCH / "gpu_check.sh"), str(out)],
                          capture_output=True, text=True, timeout=600,
                          env={"PYTHON": sys.executable, "PATH": "/usr/bin:/bin",
                               "GPU_CHECK_SMOKE": "1"})
    assert done.returncode == 0, done.stdout[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert {name: step["exit"] for name, step in summary["steps"].items()} == dict.fromkeys(
        STEPS, 0)
    for name in ("tests.xml", "throughput.csv", "throughput.json", "agreement.csv",
                 "agreement.json", "condensed.json", "specimen/steps.csv",
                 "specimen/summary.json", "paths.csv", "paths.json",
                 "block_specimen/steps.csv", "block_specimen/summary.json"):
        assert (out / name).exists(), name


@pytest.mark.parametrize("sliding", ["free", "stick"])
def test_condensed_cg_against_the_lu_on_the_cpu(tmp_path, sliding):
    summary = _module().condensed(tmp_path, device="cpu", n_rve=2, particles=30,
                                  strain=2e-4, sliding=sliding)
    assert summary["within_tolerance"] and summary["max_rel_diff"] <= 1e-8
    assert summary["device_assembly_max_rel_diff"] <= 1e-8
    written = json.loads((tmp_path / "condensed.json").read_text())
    assert written["n_rve"] == 2 and written["sliding"] == sliding
    seconds = summary["seconds"]
    assert 0 < seconds["cg_assembly_host"] and 0 < seconds["cg_solve"]
    assert seconds["cg_assembly_host"] + seconds["cg_solve"] == pytest.approx(seconds["cg"],
                                                                              rel=0.2)
    assert seconds["dem_200_steps"] > 0 and seconds["device_assembly"] > 0
    assert summary["device_assembly_max_rel_diff"] <= 1e-8


def test_paths_times_both_step_paths_on_the_cpu(tmp_path):
    """The two-kernel step and the block path from one snapshot: on the CPU (one thread a
    block) they give the same stress bit for bit; the block path ran in rounds."""
    summary = _module().paths(tmp_path, device="cpu", batches=(2,), particles=30,
                              dtypes=("float64",), seconds=0.05)
    (case,) = summary["cases"]
    assert case["stress_rel_diff"] == 0 and summary["within_tolerance"]
    assert case["two_kernel_particle_steps_per_s"] > 0 and case["block_rounds"] >= 1
    assert case["block_over_two_kernel"] == pytest.approx(
        case["block_particle_steps_per_s"] / case["two_kernel_particle_steps_per_s"])
    assert json.loads((tmp_path / "paths.json").read_text())["cases"][0]["n_rve"] == 2
