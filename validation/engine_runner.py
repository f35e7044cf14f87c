"""Our engine's side of the cross-runs, through its command line (and its API for tangents).

The command line (``prepare``, ``biaxial-dem``, ``dem-drive``, ``single-element``) runs as a
subprocess of this interpreter (``python -m granular_material.cli``), so its wall time is
measured the same way as YADE's: the whole process, start-up included.
:func:`biaxial_option_names` reads which options the ``biaxial`` command has from its
parser, built in this process.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

__all__ = [
    "EngineError",
    "biaxial_option_names",
    "biaxial_options",
    "engine_available",
    "ours_biaxial",
    "ours_drive",
    "ours_femxdem_biaxial",
    "ours_prepare",
    "ours_single_element",
    "ours_tangents",
    "voigt_tangent",
]

DEFAULT_TIMEOUT = 900.0


class EngineError(RuntimeError):
    """Our engine's command failed or timed out; the message holds the tail of its stderr."""


def engine_available() -> bool:
    """True when the engine's DEM commands are importable (``granular_material.cli.dem``)."""
    try:
        import granular_material.cli.dem  # noqa: F401
    except ImportError:
        return False
    return True


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _run(args: list[str], timeout: float) -> tuple[dict[str, Any], float]:
    """Run our command line; its JSON (with ``cpu_s``: the process's CPU time) and wall [s]."""
    cmd = [sys.executable, "-m", "granular_material.cli", *args, "--json"]
    cpu0 = _children_cpu_s()
    start = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False,
                              stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        raise EngineError(f"granular-material {args[0]} timed out after {timeout:g} s") from None
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        tail = "\n".join(proc.stderr.splitlines()[-20:])
        raise EngineError(f"granular-material {' '.join(args)} failed (exit "
                          f"{proc.returncode}):\n{tail}")
    try:
        result = json.loads(proc.stdout)
    except json.JSONDecodeError as exc:
        raise EngineError(f"granular-material {args[0]} printed no JSON: {exc}\n"
                          f"{proc.stdout[-2000:]}") from None
    if isinstance(result, dict):
        result["cpu_s"] = _children_cpu_s() - cpu0
    return result, wall


def _device(device: str | None) -> list[str]:
    return [] if device is None else ["--device", device]


def ours_prepare(out: str | Path, particles: int = 400, seed: int = 1, pressure: float = 1e5,
                 device: str | None = None,
                 timeout: float = DEFAULT_TIMEOUT) -> dict[str, Any]:
    """``granular-material prepare``: its JSON summary plus ``wall_s`` [s]."""
    result, wall = _run(["prepare", "--particles", str(particles), "--seed", str(seed),
                         "--pressure", repr(float(pressure)), "--out", str(out),
                         *_device(device)], timeout)
    result["wall_s"] = wall
    return result


def ours_biaxial(rve: str | Path, out_csv: str | Path, axial_strain: float = 0.1,
                 confining: float = 1e5, strain_per_step: float = 1e-5,
                 record_every: int = 10, device: str | None = None,
                 timeout: float = DEFAULT_TIMEOUT) -> tuple[pd.DataFrame, dict[str, Any]]:
    """``granular-material biaxial-dem`` on RVE 0: the curve and its JSON plus ``wall_s``."""
    result, wall = _run(["biaxial-dem", str(rve), "--axial-strain", repr(float(axial_strain)),
                         "--confining", repr(float(confining)),
                         "--strain-per-step", repr(float(strain_per_step)),
                         "--record-every", str(int(record_every)), "--out", str(out_csv),
                         *_device(device)], timeout)
    result["wall_s"] = wall
    curve = pd.read_csv(out_csv)
    if "rve" in curve.columns:
        curve = curve[curve["rve"] == 0].reset_index(drop=True)
    return curve, result


def ours_drive(rve: str | Path, out_csv: str | Path, grad_u: list[float], increments: int,
               device: str | None = None,
               timeout: float = DEFAULT_TIMEOUT) -> tuple[pd.DataFrame, dict[str, Any]]:
    """``granular-material dem-drive`` on the file: rows of RVE 0, JSON plus ``wall_s``."""
    if len(grad_u) != 4 or increments < 1:
        raise ValueError(f"grad_u needs 4 numbers and increments >= 1, got {grad_u}, "
                         f"{increments}")
    text = ",".join(repr(float(g)) for g in grad_u)
    result, wall = _run(["dem-drive", str(rve), f"--grad-u={text}", "--increments",
                         str(int(increments)), "--out", str(out_csv), *_device(device)],
                        timeout)
    result["wall_s"] = wall
    path = pd.read_csv(out_csv)
    if "rve" in path.columns:
        path = path[path["rve"] == 0].reset_index(drop=True)
    return path, result


def ours_single_element(rve: str | Path, out_dir: str | Path, axial_strain: float = 0.1,
                        confining: float = 1e5, steps: int = 100, device: str | None = None,
                        timeout: float = DEFAULT_TIMEOUT) -> tuple[pd.DataFrame, dict[str, Any]]:
    """``granular-material single-element --material dem`` on the RVE file (FEM × DEM).

    One Q4 element, its four Gauss points each holding a copy of the RVE, loaded like the
    drained biaxial test: sides under ``confining`` [Pa] (compression positive), the top
    compressed to ``axial_strain`` (compression positive) in ``steps`` Newton load steps.
    Returns ``DIR/steps.csv`` (step 0 included: ``axial_strain``, ``sxx``, ``syy``, ``sxy``
    [Pa] tension positive, volume averages over the Gauss points, ``volumetric_strain`` =
    tr ε, ``void_ratio``, Newton ``iterations`` ...) and the command's JSON summary plus
    ``wall_s`` [s] (the whole process). A Newton failure (exit 1) raises :class:`EngineError`.
    """
    if steps < 1 or not axial_strain > 0:
        raise ValueError(f"steps must be >= 1 and axial_strain > 0, got {steps}, "
                         f"{axial_strain}")
    out_dir = Path(out_dir)
    result, wall = _run(["single-element", "--material", "dem", "--rve", str(rve),
                         "--axial-strain", repr(float(axial_strain)),
                         "--confining", repr(float(confining)), "--steps", str(int(steps)),
                         "--out", str(out_dir), "--no-progress", *_device(device)], timeout)
    result["wall_s"] = wall
    curve = pd.read_csv(out_dir / "steps.csv")
    return curve.drop(columns=["residual_history"], errors="ignore"), result


def _biaxial_parser() -> argparse.ArgumentParser:
    """The parser of ``granular-material biaxial``, built in this process (nothing run)."""
    from granular_material.cli import fem

    parser = argparse.ArgumentParser(prog="granular-material")
    subparsers = parser.add_subparsers(dest="command")
    fem.register(subparsers)
    return subparsers.choices["biaxial"]


def biaxial_option_names() -> frozenset[str]:
    """The option strings (``--element``, ``--convergence`` …) of ``granular-material
    biaxial``, read from its parser in this process."""
    return frozenset(s for action in _biaxial_parser()._actions
                     for s in action.option_strings)


def biaxial_options() -> str:
    """The help text of ``granular-material biaxial`` (which options this engine has), from
    its parser in this process."""
    return _biaxial_parser().format_help()


def ours_femxdem_biaxial(rve: str | Path, out_dir: str | Path,
                         elements: tuple[int, int] = (2, 4), axial_strain: float = 0.03,
                         steps: int = 30, confining: float = 1e5, width: float = 0.05,
                         height: float = 0.1, extra: list[str] | None = None,
                         device: str | None = None, timeout: float = 3600.0
                         ) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """``granular-material biaxial`` with RVE 0 of ``rve`` copied to every Gauss point.

    Smooth platens, ``elements`` (nx, ny) on a ``width`` × ``height`` [m] specimen, ``steps``
    equal load steps to ``axial_strain`` (compression positive) at ``confining`` [Pa];
    ``extra``: further options (element, Newton). Returns ``DIR/steps.csv`` (step 0
    included; ``platen_stress``, ``stress_ratio``, volume-average ``sxx``, ``syy``, ``sxy``
    [Pa] tension positive, ``volumetric_strain``, ``void_ratio``, ``iterations``,
    ``particle_steps``, ``wall_time`` [s] ...), ``DIR/points.csv`` (Gauss-point states of
    every step) and the JSON summary plus ``wall_s`` [s] (the whole process) and ``cpu_s``.
    A finished run in ``DIR`` with the same arguments (``DIR/run.json``) is read back.
    """
    if steps < 1 or not axial_strain > 0:
        raise ValueError(f"steps must be >= 1 and axial_strain > 0, got {steps}, "
                         f"{axial_strain}")
    out_dir = Path(out_dir)
    args = ["biaxial", "--rve", str(rve), "--elements", str(int(elements[0])),
            str(int(elements[1])), "--width", repr(float(width)), "--height",
            repr(float(height)), "--platens", "smooth", "--axial-strain",
            repr(float(axial_strain)), "--steps", str(int(steps)), "--confining",
            repr(float(confining)), "--out", str(out_dir), "--no-progress", *(extra or []),
            *_device(device)]
    done = out_dir / "run.json"
    cached = json.loads(done.read_text()) if done.is_file() else {}
    if cached.get("args") == args:
        result = cached["result"]
    else:
        result, wall = _run(args, timeout)
        result["wall_s"] = wall
        done.write_text(json.dumps({"args": args, "result": result}, indent=1))
    curve = pd.read_csv(out_dir / "steps.csv").drop(columns=["residual_history"],
                                                    errors="ignore")
    return curve, pd.read_csv(out_dir / "points.csv"), result


def voigt_tangent(tangent: np.ndarray) -> np.ndarray:
    """Symmetrised Voigt (xx, yy, xy) matrix (3, 3) [Pa] of a 4th-order tangent (2, 2, 2, 2)."""
    tangent = np.asarray(tangent, dtype=np.float64)
    if tangent.shape != (2, 2, 2, 2):
        raise ValueError(f"tangent must have shape (2, 2, 2, 2), got {tangent.shape}")
    sym = 0.25 * (tangent + tangent.transpose(1, 0, 2, 3) + tangent.transpose(0, 1, 3, 2)
                  + tangent.transpose(1, 0, 3, 2))
    idx = ((0, 0), (1, 1), (0, 1))
    return np.array([[sym[i, j, k, m] for (k, m) in idx] for (i, j) in idx])


def ours_tangents(rve: str | Path, grad_u: list[float], increments: int, at: list[int],
                  device: str | None = "cpu") -> dict[int, np.ndarray]:
    """Voigt tangents (3, 3) [Pa] of our engine after the increments ``at`` of a ∇u path.

    Runs in this process through the engine's API (``DEMBatch`` and ``drive_grad_u``), the
    way ``dem-drive`` applies the increments; the homogenised tangent is Kruyt–Rothenburg's.
    """
    from granular_material.dem.batch import DEMBatch
    from granular_material.dem.rve_file import load_rve
    from granular_material.procedures import drive_grad_u, path_increment

    data = load_rve(rve).select(0)
    batch = DEMBatch(data, device=device)
    grad = np.asarray(grad_u, dtype=np.float64).reshape(2, 2)
    wanted = sorted(set(int(k) for k in at))
    if any(k < 0 or k > increments for k in wanted):
        raise ValueError(f"tangent increments must lie in [0, {increments}], got {wanted}")
    out: dict[int, np.ndarray] = {}
    if 0 in wanted:
        out[0] = voigt_tangent(batch.homogenize().tangent[0])
    for k in range(1, (wanted[-1] if wanted else 0) + 1):
        drive_grad_u(batch, path_increment(grad, k, increments))
        if k in wanted:
            out[k] = voigt_tangent(batch.homogenize().tangent[0])
    return out
