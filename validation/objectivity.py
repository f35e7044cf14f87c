"""Objectivity of a rigid rotation: our engine against YADE (issue 12, part 6).

A consolidated RVE is rotated rigidly by an angle θ (∇u = R(θ) − I, applied with a constant
spin as :func:`drive_grad_u` does); an objective engine gives σ' = R σ Rᵀ. The defect is
``|Rᵀ σ' R − σ| / p`` with p = −tr σ / 2 of the initial state (Frobenius norm).

Run as a script: ``python -m granular_material_validation.objectivity RVE.npz [--yade]``.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
from granular_material_validation.yade_io import export_rve
from granular_material_validation.yade_runner import DEFAULT_TIMEOUT, _workdir, run_script

from granular_material.dem import DEMBatch
from granular_material.dem.rve.file import RVEData, load_rve
from granular_material.procedures import drive_grad_u
from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP

__all__ = ["engine_rotation", "rotation", "rotation_defect", "yade_rotation"]


def rotation(theta: float) -> np.ndarray:
    """The rotation matrix R(θ) (2, 2), θ [rad] counter-clockwise."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def rotation_defect(stress0: np.ndarray, stress1: np.ndarray, theta: float,
                    p0: float | None = None) -> float:
    """``|Rᵀ σ1 R − σ0| / p0`` [-] of 2×2 stresses [Pa] (Frobenius norm); p0 [Pa] defaults to
    −tr σ0 / 2."""
    r = rotation(theta)
    back = r.T @ np.asarray(stress1) @ r
    if p0 is None:
        p0 = -0.5 * float(np.trace(stress0))
    return float(np.linalg.norm(back - np.asarray(stress0)) / p0)


def engine_rotation(rve: str | Path | RVEData, theta: float,
                    max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
                    friction_angle: float | None = None,
                    device: str | None = "cpu") -> tuple[float, int]:
    """Our engine: (defect [-], steps) of rotating RVE 0 rigidly by θ [rad].

    The reference is the same RVE run as many steps without loading (so that a packing not
    quite at rest is not counted as a defect); p0 is that of the initial state.
    ``friction_angle`` [rad] replaces the file's (0: frictionless) when given.
    """
    data = load_rve(rve) if isinstance(rve, (str, Path)) else rve
    batch = DEMBatch(data, device=device)
    if friction_angle is not None:
        batch.set_friction(friction_angle)
    start = batch.snapshot()
    p0 = -0.5 * float(np.trace(batch.homogenize().stress[0]))
    steps = drive_grad_u(batch, rotation(theta) - np.eye(2), max_strain_per_step)
    rotated = batch.homogenize().stress[0]
    batch.restore(start)
    batch.run(steps)
    still = batch.homogenize().stress[0]
    return rotation_defect(still, rotated, theta, p0), steps


def yade_rotation(rve: str | Path | RVEData, theta: float, steps: int,
                  workdir: str | Path | None = None,
                  timeout: float = DEFAULT_TIMEOUT) -> dict:
    """YADE: the rigid rotation of RVE 0 by θ [rad] over ``steps`` steps (``rotate.py``).

    As :func:`engine_rotation`, the reference is a second run of as many steps at θ = 0.
    Returns the rotated run's output (``stress0``, ``stress1`` (sxx, syy, sxy) [Pa],
    ``cell0``, ``cell1``, ``steps``, …) with ``defect`` [-] and ``area_change``
    (det H1/det H0 − 1) added.
    """
    work = _workdir(workdir, "rotate")
    scene = export_rve(rve, work / "rve.scene.json")
    runs = []
    for angle in (theta, 0.0):
        out = work / f"rotate_{angle:.6f}.json"
        run_script("rotate.py", {"scene": str(scene), "out": str(out), "theta": float(angle),
                                 "steps": int(steps)}, work, timeout)
        runs.append(json.loads(out.read_text()))

    def tensor(s: list[float]) -> np.ndarray:
        return np.array([[s[0], s[2]], [s[2], s[1]]])

    result, still = runs
    p0 = -0.5 * float(np.trace(tensor(result["stress0"])))
    result["defect"] = rotation_defect(tensor(still["stress1"]), tensor(result["stress1"]),
                                       theta, p0)
    result["area_change"] = float(np.linalg.det(result["cell1"])
                                  / np.linalg.det(result["cell0"]) - 1.0)
    return result


def main(argv: list[str] | None = None) -> None:
    """Print the defect of our engine (and YADE's) at the angles asked."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rve")
    parser.add_argument("--angles", type=float, nargs="+", default=[0.15, 1.0, 0.9 * math.pi])
    parser.add_argument("--strain-per-step", type=float, nargs="+",
                        default=[DEFAULT_STRAIN_PER_STEP])
    parser.add_argument("--frictionless", action="store_true")
    parser.add_argument("--yade", action="store_true")
    args = parser.parse_args(argv)
    for theta in args.angles:
        for rate in args.strain_per_step:
            defect, steps = engine_rotation(args.rve, theta, rate,
                                            0.0 if args.frictionless else None)
            line = f"theta={theta:.4f} rate={rate:g} steps={steps} ours={defect:.4e}"
            if args.yade:
                y = yade_rotation(args.rve, theta, steps)
                line += f" yade={y['defect']:.4e} yade_area_change={y['area_change']:.3e}"
            print(line, flush=True)


if __name__ == "__main__":
    main()
