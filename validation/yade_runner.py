"""Run our YADE scripts with Debian's ``yade`` in a subprocess and read their results.

YADE does not import into our virtualenv: each run writes a job file (JSON) into a work
folder, calls ``yade -n -x <script> <job.json>`` with a timeout, keeps its log next to the
results, and parses the result files (CSV, JSON) here.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
from granular_material_validation.yade_io import export_rve, import_scene

from granular_material.dem.rve.file import RVEData
from granular_material.procedures.element_tests import DEFAULT_AXIAL_STRAIN
from granular_material.procedures.packing import DEFAULT_PRESSURE
from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP

__all__ = [
    "SCRIPTS",
    "YadeError",
    "YadeNotFoundError",
    "YadeRun",
    "find_yade",
    "yade_biaxial",
    "yade_drive",
    "yade_prepare_guo_zhao",
    "yade_round_trip",
    "yade_throughput",
    "yade_version",
]

SCRIPTS = Path(__file__).with_name("yade_scripts")
DEFAULT_TIMEOUT = 600.0


class YadeNotFoundError(RuntimeError):
    """The ``yade`` executable is not on PATH (Debian: ``apt-get install yade``)."""


class YadeError(RuntimeError):
    """A YADE run failed or timed out; the message ends with the tail of its log."""


@dataclass(frozen=True)
class YadeRun:
    """One finished YADE run.

    Attributes:
        workdir: folder holding the job, the log and the results.
        log: path of the combined stdout/stderr log.
        wall_s: wall time of the whole subprocess [s], YADE's start-up included.
    """

    workdir: Path
    log: Path
    wall_s: float


def find_yade(executable: str | None = None) -> str:
    """Path of the yade executable (``$GM_YADE`` or ``yade`` on PATH); raises if absent."""
    name = executable or os.environ.get("GM_YADE", "yade")
    path = shutil.which(name)
    if path is None:
        raise YadeNotFoundError(
            f"yade executable {name!r} not found on PATH; install Debian's package with "
            "'apt-get install yade' (2023.02a) or set GM_YADE"
        )
    return path


def yade_version(executable: str | None = None) -> str:
    """The version string YADE prints, e.g. ``'2023.02a'``."""
    out = subprocess.run([find_yade(executable), "--version"], capture_output=True, text=True,
                         timeout=60, check=False)
    for line in (out.stdout + out.stderr).splitlines():
        if "version" in line.lower():
            return line.split(":", 1)[-1].strip()
    return (out.stdout + out.stderr).strip()


def _tail(path: Path, lines: int = 25) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return "(no log)"


def run_script(script: str, job: dict[str, Any], workdir: str | Path,
               timeout: float = DEFAULT_TIMEOUT, executable: str | None = None,
               threads: int = 1) -> YadeRun:
    """Run ``yade_scripts/<script>`` on ``job`` (written to ``workdir/<stem>.job.json``).

    Raises ``YadeNotFoundError`` without yade, ``YadeError`` on a non-zero exit, a timeout or
    a script error (YADE may exit 0 after a Python exception; the log is checked too).
    """
    exe = find_yade(executable)
    script_path = SCRIPTS / script
    if not script_path.is_file():
        raise ValueError(f"script must name a file of {SCRIPTS}, got {script!r}")
    if timeout <= 0:
        raise ValueError(f"timeout must be positive, got {timeout!r}")
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    stem = script_path.stem
    job_path = workdir / f"{stem}.job.json"
    job_path.write_text(json.dumps(job, indent=1))
    log = workdir / f"{stem}.log"
    env = {**os.environ, "OMP_NUM_THREADS": str(threads), "DISPLAY": ""}
    cmd = [exe, "-j", str(threads), "-n", "-x", str(script_path), str(job_path)]
    start = time.perf_counter()
    with open(log, "w") as fh:
        try:
            proc = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=workdir,
                                  env=env, timeout=timeout, check=False,
                                  stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            raise YadeError(f"yade {script} timed out after {timeout:g} s; log {log}:\n"
                            f"{_tail(log)}") from None
    wall = time.perf_counter() - start
    text = log.read_text(errors="replace")
    if proc.returncode != 0 or "Traceback (most recent call last)" in text:
        raise YadeError(f"yade {script} failed (exit {proc.returncode}); log {log}:\n"
                        f"{_tail(log)}")
    return YadeRun(workdir=workdir, log=log, wall_s=wall)


def _workdir(workdir: str | Path | None, prefix: str) -> Path:
    if workdir is not None:
        path = Path(workdir)
        path.mkdir(parents=True, exist_ok=True)
        return path
    return Path(tempfile.mkdtemp(prefix=f"gm-yade-{prefix}-"))


def yade_prepare_guo_zhao(out_rve: str | Path, seed: int = 1, particles: int = 400,
                          pressure: float = DEFAULT_PRESSURE, friction_angle: float = 0.5,
                          workdir: str | Path | None = None,
                          timeout: float = DEFAULT_TIMEOUT) -> tuple[RVEData, dict[str, Any]]:
    """Guo & Zhao's RVE built by YADE (docs/design.md#guo-zhao-rve), written to ``out_rve`` in
    our format.

    Returns the RVE data and YADE's preparation summary: ``stress`` (sxx, syy, sxy) [Pa],
    ``void_ratio``, ``coordination``, ``steps``, ``wall_s`` (consolidation only) and
    ``run_wall_s`` (the whole subprocess).
    """
    if particles < 2 or pressure <= 0:
        raise ValueError(f"particles must be >= 2 and pressure > 0, got {particles}, {pressure}")
    work = _workdir(workdir, "prepare")
    scene_out = work / f"guo_zhao_seed{seed}.scene.json"
    run = run_script("prepare_guo_zhao.py", {
        "out": str(scene_out), "particles": particles, "seed": seed, "pressure": pressure,
        "friction_angle": friction_angle}, work, timeout)
    data = import_scene(scene_out, out_rve)
    summary = dict(json.loads(scene_out.read_text())["prepare"])
    summary["run_wall_s"] = run.wall_s
    return data, summary


def yade_round_trip(rve: str | Path | RVEData, workdir: str | Path | None = None,
                    steps: int = 0,
                    timeout: float = 120.0) -> tuple[RVEData, tuple[float, float, float]]:
    """Export RVE 0 to YADE, build the scene there, run ``steps`` steps and import it back.

    Returns the imported RVE and YADE's stress (sxx, syy, sxy) [Pa] of that state.
    """
    work = _workdir(workdir, "echo")
    scene = export_rve(rve, work / "in.scene.json")
    out = work / "out.scene.json"
    run_script("echo_scene.py", {"scene": str(scene), "out": str(out), "steps": steps},
               work, timeout)
    stress = json.loads(out.read_text())["stress"]
    return import_scene(out), (float(stress[0]), float(stress[1]), float(stress[2]))


def yade_biaxial(rve: str | Path | RVEData, axial_strain: float = DEFAULT_AXIAL_STRAIN,
                 confining: float = DEFAULT_PRESSURE,
                 strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
                 record_strain: float = 1e-4, workdir: str | Path | None = None,
                 timeout: float = DEFAULT_TIMEOUT) -> tuple[pd.DataFrame, dict[str, Any]]:
    """YADE's drained biaxial test of RVE 0: the curve (see ``biaxial.py``) and its timings.

    The summary holds ``build_s``, ``run_s`` (stepping only), ``steps``, ``timestep`` and
    ``wall_s`` (the whole subprocess).
    """
    work = _workdir(workdir, "biaxial")
    scene = export_rve(rve, work / "rve.scene.json")
    run = run_script("biaxial.py", {
        "scene": str(scene), "out": str(work / "yade_biaxial.csv"),
        "summary": str(work / "yade_biaxial.json"), "confining": confining,
        "axial_strain": axial_strain, "strain_per_step": strain_per_step,
        "record_strain": record_strain}, work, timeout)
    summary = json.loads((work / "yade_biaxial.json").read_text())
    summary["wall_s"] = run.wall_s
    return pd.read_csv(work / "yade_biaxial.csv"), summary


def yade_drive(rve: str | Path | RVEData, grad_u: list[float], increments: int,
               tangent_at: list[int] | None = None, kinematics: str = "shear2d",
               workdir: str | Path | None = None,
               timeout: float = DEFAULT_TIMEOUT) -> tuple[pd.DataFrame, dict[str, Any]]:
    """YADE's shear2D-style ∇u path of RVE 0 (``grad_u`` = [Gxx, Gxy, Gyx, Gyy], total).

    ``kinematics``: ``"shear2d"`` (Guo & Zhao: L = ΔG/(n·dt)) or ``"exact"`` (the cell is
    (I + G·k/K)·H0 after increment k, as in our ``dem-drive``). Returns one row per increment
    (see ``drive.py``; tangent columns ``D_xx_xx`` … in Pa where asked) and the timings.
    """
    if kinematics not in ("shear2d", "exact"):
        raise ValueError(f"kinematics must be 'shear2d' or 'exact', got {kinematics!r}")
    if len(grad_u) != 4 or increments < 1:
        raise ValueError(f"grad_u needs 4 numbers and increments >= 1, got {grad_u}, "
                         f"{increments}")
    work = _workdir(workdir, "drive")
    scene = export_rve(rve, work / "rve.scene.json")
    run = run_script("drive.py", {
        "scene": str(scene), "out": str(work / "yade_drive.csv"),
        "summary": str(work / "yade_drive.json"), "grad_u": [float(g) for g in grad_u],
        "increments": int(increments), "tangent_at": list(tangent_at or []),
        "kinematics": kinematics}, work, timeout)
    summary = json.loads((work / "yade_drive.json").read_text())
    summary["wall_s"] = run.wall_s
    return pd.read_csv(work / "yade_drive.csv"), summary


def yade_throughput(rve_path: str | Path, steps: int = 2000, warmup: int = 100,
                    timeout: float = DEFAULT_TIMEOUT) -> float | None:
    """Particle-steps per second of YADE stepping RVE 0 of ``rve_path`` on one core.

    The scene build and ``warmup`` steps are excluded from the timing. Returns None when
    yade is not installed; raises ``YadeError`` if the run fails.
    """
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    try:
        find_yade()
    except YadeNotFoundError:
        return None
    with tempfile.TemporaryDirectory(prefix="gm-yade-throughput-") as tmp:
        work = Path(tmp)
        scene = export_rve(rve_path, work / "rve.scene.json")
        out = work / "throughput.json"
        run_script("throughput.py", {"scene": str(scene), "steps": int(steps),
                                     "warmup": int(warmup), "out": str(out)}, work, timeout)
        return float(json.loads(out.read_text())["particle_steps_per_s"])
