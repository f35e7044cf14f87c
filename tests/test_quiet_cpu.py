"""A CPU run prints nothing of warp's own (its banner, module loads, the no-driver warning)
unless verbose is asked for."""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys

import pytest

START_WARP = "import granular_material{extra}\nimport warp as wp\nwp.init()\nprint('ok')\n"


def _start(extra: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", START_WARP.format(extra=extra)],
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, **(env or {})})


def _has_cuda_driver() -> bool:
    """Whether the CUDA driver's library loads here (what warp's native start looks for)."""
    for name in ("libcuda.so", "libcuda.so.1"):
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            continue
    return False


def test_warp_start_prints_nothing_by_default():
    quiet = _start("", {"GRANULAR_MATERIAL_VERBOSE": "0"})
    assert quiet.returncode == 0, quiet.stderr
    assert quiet.stdout == "ok\n"
    assert "Warp" not in quiet.stderr, quiet.stderr


def test_the_no_driver_warning_comes_back_when_verbose():
    if _has_cuda_driver():
        pytest.skip("a CUDA driver is loaded here: warp has no such warning to give")
    loud = _start("; granular_material.verbose(True)")
    assert loud.returncode == 0, loud.stderr
    assert "Could not find or load the NVIDIA CUDA driver" in loud.stderr
    assert "initialized" in loud.stdout


def test_the_material_on_the_cpu_is_silent():
    code = ("from granular_material.multiscale import DEMMaterial\n"
            "DEMMaterial(particles=16, seed=1, device='cpu', replicate=True).allocate(1)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, env={**os.environ, "GRANULAR_MATERIAL_VERBOSE": "0"})
    assert run.returncode == 0, run.stderr
    assert run.stdout == "" and run.stderr == "", run.stdout + run.stderr


def test_warp_starts_with_stderr_closed():
    """A process without a stderr (a daemon, ``2>&-``) still starts warp: nothing to capture."""
    run = subprocess.run([sys.executable, "-c", START_WARP.format(extra="")],
                         stdout=subprocess.PIPE, text=True, timeout=300,
                         preexec_fn=lambda: os.close(2))
    assert run.returncode == 0 and run.stdout == "ok\n"
