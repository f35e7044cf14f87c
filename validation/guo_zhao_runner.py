"""Run Guo & Zhao's own FEM × DEM code (YADE's ``FEMxDEM`` module on esys-escript).

Debian's yade 2023.02a ships their module (``msFEM2D.py``, ``simDEM.py``, ``saveGauss.py``)
and their example ``examples/FEMxDEM/biaxialSmooth.py`` (8-node quadrilaterals, 2 × 2 Gauss
points, smooth platens, Newton with ``rtol = 1e-2`` on ‖δu‖/‖u‖, one RVE ``0.yade.gz`` copied
to every Gauss point); Debian packages esys-escript as ``python3-escript``. The example is run
as shipped except for the patches listed in :data:`EXAMPLE_PATCHES` and
:data:`MODULE_PATCHES`, applied to copies in a work folder: the problem size (mesh, load
steps, strain a step, confinement, processes), Python 3 (``file`` → ``open``) and two
instrumentation hooks (``yade_scripts/gz_probe.py``: timings, DEM steps and Gauss-point
states, counted without touching their numerics). It runs under yade's own interpreter
(``yade -n -x``, Debian's numpy; escript does not import under numpy 2) with escript's folder
and the module copy on ``PYTHONPATH`` and escript's ``lib/`` on ``LD_LIBRARY_PATH``.
"""

from __future__ import annotations

import glob
import gzip
import json
import os
import re
import resource
import shutil
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from granular_material_validation.yade_io import export_rve
from granular_material_validation.yade_runner import (
    SCRIPTS,
    YadeError,
    YadeNotFoundError,
    find_yade,
    run_script,
)

from granular_material.procedures.packing import DEFAULT_PRESSURE

__all__ = [
    "EXAMPLE_PATCHES",
    "MODULE_PATCHES",
    "EscriptNotFoundError",
    "apply_patches",
    "copy_modules",
    "find_escript",
    "find_femxdem",
    "finish_run",
    "gauss_fields",
    "group_cpu_s",
    "guo_zhao_available",
    "guo_zhao_biaxial",
    "patch_example",
]

#: (what, original text, replacement) applied to the example; {name} fields are the job's
EXAMPLE_PATCHES: tuple[tuple[str, str, str], ...] = (
    ("python 3", "fout = file('./result/biaxial_surf.dat', 'w')",
     "fout = open('./result/biaxial_surf.dat', 'w')"),
    ("size: platen displacement a load step [m]", "vel = -0.0001", "vel = {vel!r}"),
    ("size: confining stress [Pa], tension positive", "confining = -1.e5",
     "confining = {confining!r}"),
    ("size: elements across", "nx = 8", "nx = {nx}"),
    ("size: elements along", "ny = 16", "ny = {ny}"),
    ("size: processes of the multiprocessing pool", "nump = 16", "nump = {processes}"),
    ("size: load steps", "while t < 100:", "while t < {steps}:"),
    ("probe: counting subclass of MultiScale", "from msFEM2D import MultiScale",
     "from gz_probe import MultiScale\nimport gz_probe"),
    ("probe: initial state and Gauss-point coordinates",
     "disp = Vector(0., Solution(mydomain))",
     "gz_probe.start(prob, mydomain)\ndisp = Vector(0., Solution(mydomain))"),
    ("probe: state after each load step",
     "\tvolume_strain = trace(strain)", "\tgz_probe.record(t, prob, vR, forceTop[1], lengthTop)\n"
     "\tvolume_strain = trace(strain)"),
)
#: (file of their module, original text, replacement, expected count): Python 3 only
MODULE_PATCHES: tuple[tuple[str, str, str, int], ...] = (
    ("saveGauss.py", "fout = file(name, 'w')", "fout = open(name, 'w')", 2),
)

#: how often the CPU time of a running yade process group is sampled [s]
POLL_S = 1.0
_CONVERGED = re.compile(r"Convergence reached after (\d+) iteration\(s\)! Relative error: (\S+)")


class EscriptNotFoundError(RuntimeError):
    """esys-escript or YADE's FEMxDEM module is missing (``apt-get install python3-escript``)."""


def find_escript() -> Path:
    """Folder holding escript's ``esys`` package (``$GM_ESCRIPT`` or Debian's)."""
    candidates = [os.environ.get("GM_ESCRIPT", ""), "/usr/lib/python3-escript"]
    for folder in candidates:
        if folder and (Path(folder) / "esys" / "escript").is_dir():
            return Path(folder)
    raise EscriptNotFoundError(
        "esys-escript not found (looked in $GM_ESCRIPT and /usr/lib/python3-escript); on "
        "Debian: apt-get install python3-escript")


def find_femxdem() -> tuple[Path, Path]:
    """YADE's FEMxDEM module folder and its ``biaxialSmooth.py`` example (Debian's paths)."""
    modules = sorted(glob.glob("/usr/lib/*/yade*/py/yade/FEMxDEM/msFEM2D.py"),
                     key=lambda p: ("yade-double" not in p, p))
    examples = [p for p in ("/usr/share/doc/yade/examples/FEMxDEM/biaxialSmooth.py",
                            "/usr/share/doc/yade/examples/FEMxDEM/biaxialSmooth.py.gz")
                if Path(p).is_file()]
    if not modules or not examples:
        raise EscriptNotFoundError(
            "YADE's FEMxDEM module or its biaxialSmooth.py example not found (Debian's yade "
            "installs them under /usr/lib/*/yade*/py/yade/FEMxDEM and "
            "/usr/share/doc/yade/examples/FEMxDEM)")
    return Path(modules[0]).parent, Path(examples[0])


def guo_zhao_available() -> bool:
    """True when yade, esys-escript and the FEMxDEM module and example are all installed."""
    try:
        find_yade()
        find_escript()
        find_femxdem()
    except (YadeNotFoundError, EscriptNotFoundError):
        return False
    return True


def apply_patches(text: str, patches: Any, source: str, **job: Any) -> str:
    """``text`` (their script ``source``) with ``patches`` ((what, original, replacement)
    each, the replacement formatted with ``job``) applied; every original must occur
    exactly once (raises otherwise, naming it)."""
    for what, old, new in patches:
        if text.count(old) != 1:
            raise ValueError(f"patch '{what}': {old!r} occurs {text.count(old)} times in "
                             f"{source}, expected once (another yade version?)")
        text = text.replace(old, new.format(**job))
    return text


def patch_example(text: str, **job: Any) -> str:
    """``biaxialSmooth.py`` with :data:`EXAMPLE_PATCHES` applied (:func:`apply_patches`)."""
    return apply_patches(text, EXAMPLE_PATCHES, "the example", **job)


def copy_modules(work: Path) -> Path:
    """``work/FEMxDEM``: a fresh copy of their module with :data:`MODULE_PATCHES`, the
    counting probe and a ``yadeimport`` link to yade; returns the example folder's
    ``biaxialSmooth.py`` (it may be ``.gz``)."""
    module_dir, example = find_femxdem()
    modules = work / "FEMxDEM"
    if modules.exists():
        shutil.rmtree(modules)
    shutil.copytree(module_dir, modules)
    for name, old, new, count in MODULE_PATCHES:
        path = modules / name
        text = path.read_text()
        if text.count(old) != count:
            raise ValueError(f"{name}: {old!r} occurs {text.count(old)} times, expected "
                             f"{count}")
        path.write_text(text.replace(old, new))
    shutil.copy(SCRIPTS / "gz_probe.py", modules / "gz_probe.py")
    (modules / "yadeimport.py").symlink_to(find_yade())
    return example


def _prepare_folder(work: Path, job: dict[str, Any]) -> None:
    """Copies of their module and example, patched, with the probe and a yadeimport link."""
    example = copy_modules(work)
    raw = gzip.open(example, "rt").read() if example.suffix == ".gz" else example.read_text()
    (work / "biaxialSmooth.py").write_text(patch_example(raw, **job))


def _read_results(work: Path, job: dict[str, Any], log_text: str,
                  height: float = 0.1) -> pd.DataFrame:
    """One row per load step done (step 0 included) from the probe and their log."""
    rows = [json.loads(line) for line in (work / "gz_probe.jsonl").read_text().splitlines()
            if line.endswith("}")]
    iterations = [0] + [int(m.group(1)) for m in _CONVERGED.finditer(log_text)]
    n = min(len(rows), len(iterations))
    if n < 2:
        raise YadeError(f"Guo & Zhao's run in {work} finished no load step")
    area0 = rows[0]["area"]
    out = []
    for k in range(n):
        row = rows[k]
        stress = np.asarray(row["stress"], dtype=np.float64).reshape(-1, 2, 2)
        mean = np.asarray(row["mean_stress"], dtype=np.float64)
        out.append({
            "step": row["step"], "axial_strain": row["step"] * abs(job["vel"]) / height,
            "platen_stress": (-row["force_top"] / row["length_top"] if "force_top" in row
                              else float("nan")),
            "sxx": mean[0, 0], "syy": mean[1, 1], "sxy": 0.5 * (mean[0, 1] + mean[1, 0]),
            "volumetric_strain": row["area"] / area0 - 1.0,
            "void_ratio": float(np.mean(row["void_ratio"])),
            "iterations": iterations[k],
            "evaluations": row["evaluations"] - (rows[k - 1]["evaluations"] if k else 0),
            "dem_steps": row["dem_steps"] - (rows[k - 1]["dem_steps"] if k else 0),
            "wall_time": row["wall_s"] - (rows[k - 1]["wall_s"] if k else 0.0),
            "points_syy_spread": float(stress[:, 1, 1].std()),
        })
    frame = pd.DataFrame(out)
    frame["stress_ratio"] = frame["platen_stress"] / -job["confining"]
    return frame


def gauss_fields(work: str | Path) -> pd.DataFrame:
    """Gauss-point states of every recorded step of a run in ``work``: ``step``, ``point``,
    reference ``x``, ``y`` [m], ``sxx``, ``syy``, ``sxy`` [Pa] (tension positive), ``exx``,
    ``eyy``, ``exy`` (symmetric part of their accumulated ∇u) and ``void_ratio``."""
    rows = [json.loads(line) for line in (Path(work) / "gz_probe.jsonl").read_text()
            .splitlines()]
    points = np.asarray(rows[0]["points"], dtype=np.float64)
    frames = []
    for row in rows:
        s = np.asarray(row["stress"], dtype=np.float64).reshape(-1, 2, 2)
        g = np.asarray(row["grad_u"], dtype=np.float64).reshape(-1, 2, 2)
        frames.append(pd.DataFrame({
            "step": row["step"], "point": np.arange(len(points)), "x": points[:, 0],
            "y": points[:, 1], "sxx": s[:, 0, 0], "syy": s[:, 1, 1],
            "sxy": 0.5 * (s[:, 0, 1] + s[:, 1, 0]), "exx": g[:, 0, 0], "eyy": g[:, 1, 1],
            "exy": 0.5 * (g[:, 0, 1] + g[:, 1, 0]),
            "void_ratio": np.asarray(row["void_ratio"], dtype=np.float64).ravel()}))
    return pd.concat(frames, ignore_index=True)


def _children_cpu_s() -> float:
    """CPU seconds (user + system) of the finished child processes of this one, with
    theirs (a process's pool workers are counted once it has waited for them)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def guo_zhao_biaxial(rve: str | Path, workdir: str | Path, elements: tuple[int, int] = (2, 4),
                     steps: int = 30, strain_per_step: float = 1e-3,
                     confining: float = DEFAULT_PRESSURE,
                     width: float = 0.05, height: float = 0.1, processes: int = 2,
                     timeout: float = 7200.0) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Guo & Zhao's ``biaxialSmooth.py`` on RVE 0 of ``rve`` copied to every Gauss point.

    ``elements`` (nx, ny) 8-node quadrilaterals on their 50 mm × 100 mm specimen (``width``
    and ``height`` must be theirs), ``steps`` load steps of ``strain_per_step`` axial strain
    (compression positive) at ``confining`` [Pa] (a magnitude), their multiprocessing pool
    of ``processes``. A run longer than ``timeout`` [s] is stopped and keeps the load
    steps it has done (``steps_done``, ``timed_out`` in the summary). A run in ``workdir``
    with the same job is read back, not rerun. Returns one row per load step (step 0
    included: ``axial_strain``,
    ``platen_stress`` (their top force over the top width, compression positive),
    ``stress_ratio`` = platen_stress/confining, the volume-average ``sxx``, ``syy``, ``sxy``
    [Pa, tension positive], ``volumetric_strain`` = A/A0 − 1, mean ``void_ratio``, Newton
    ``iterations`` (their count), DEM ``evaluations`` and ``dem_steps`` (all points),
    ``wall_time`` [s]; ``platen_stress`` NaN for steps of a probe without the force) and a
    summary (``wall_s``: the whole yade process, ``cpu_s``: its CPU time with its pool's;
    ``patches``).
    """
    if (width, height) != (0.05, 0.1):
        raise ValueError(f"their example's specimen is 0.05 m × 0.1 m, got {width} × {height}")
    if steps < 1 or not 0 < strain_per_step <= 0.01 or processes < 1 or confining <= 0:
        raise ValueError(f"bad run: steps={steps}, strain_per_step={strain_per_step}, "
                         f"processes={processes}, confining={confining}")
    find_escript()
    work = Path(workdir).resolve()
    job = {"nx": int(elements[0]), "ny": int(elements[1]), "steps": int(steps),
           "vel": -float(strain_per_step) * height, "confining": -float(confining),
           "processes": int(processes), "rve": str(Path(rve).resolve())}
    done = work / "gz_summary.json"
    if done.is_file():
        summary = json.loads(done.read_text())
        if summary.get("job") == job:
            return pd.read_csv(work / "gz_curve.csv"), summary
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    export_rve(rve, work / "rve.scene.json")
    run_script("gz_rve_to_yade.py", {"scene": str(work / "rve.scene.json"),
                                     "out": str(work / "0.yade.gz"),
                                     "summary": str(work / "rve_state.json")}, work)
    _prepare_folder(work, job)
    escript_dir = find_escript()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "DISPLAY": "",
           "PYTHONPATH": os.pathsep.join([str(escript_dir), str(work / "FEMxDEM")]),
           "LD_LIBRARY_PATH": os.pathsep.join(
               p for p in (str(escript_dir / "lib"), os.environ.get("LD_LIBRARY_PATH", ""))
               if p)}
    log = work / "biaxialSmooth.log"
    cpu0 = _children_cpu_s()
    start = time.perf_counter()
    timed_out = False
    with open(log, "w") as fh:
        proc = subprocess.Popen([find_yade(), "-n", "-x", "biaxialSmooth.py"], cwd=work,
                                env=env, stdout=fh, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True)
        # their pool's workers end without being waited for, so the children's rusage
        # misses them: the group's CPU time is sampled from /proc while it runs
        seen = 0.0
        while proc.poll() is None:
            seen = max(seen, group_cpu_s(proc.pid))
            if time.perf_counter() - start > timeout:
                # keep the load steps done
                timed_out = True
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
                break
            time.sleep(POLL_S)
    wall = time.perf_counter() - start
    cpu = max(seen, _children_cpu_s() - cpu0)
    text = log.read_text(errors="replace")
    if not timed_out and (proc.returncode != 0 or "Traceback (most recent call last)" in text):
        tail = "\n".join(text.splitlines()[-25:])
        raise YadeError(f"Guo & Zhao's biaxialSmooth.py failed (exit {proc.returncode}); "
                        f"log {log}:\n{tail}")
    return finish_run(work, job, wall, cpu, timed_out, timeout)


def group_cpu_s(pgid: int) -> float:
    """CPU seconds (user + system, with reaped children) of the live processes of process
    group ``pgid``, from /proc (0 where /proc is absent)."""
    total = 0
    ticks = os.sysconf("SC_CLK_TCK")
    for stat in glob.glob("/proc/[0-9]*/stat"):
        try:
            fields = Path(stat).read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        # after the command: state ppid pgrp ... utime(12) stime(13) cutime(14) cstime(15)
        if int(fields[2]) == pgid:
            total += sum(int(f) for f in fields[11:15])
    return total / ticks


def finish_run(work: str | Path, job: dict[str, Any], wall_s: float, cpu_s: float,
               timed_out: bool = False,
               time_limit: float | None = None) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Read a run of theirs in ``work`` (finished, or stopped at ``time_limit`` [s] with the
    load steps it had done), write ``gz_curve.csv`` and ``gz_summary.json`` there (a later
    call with the same job reads them back) and return both."""
    work = Path(work)
    text = (work / "biaxialSmooth.log").read_text(errors="replace")
    curve = _read_results(work, job, text)
    done = len(curve) - 1
    if done < job["steps"] and not timed_out:
        raise YadeError(f"Guo & Zhao's run in {work} recorded {done} of {job['steps']} "
                        "load steps")
    summary = {"job": job, "wall_s": wall_s, "cpu_s": cpu_s, "processes": job["processes"],
               "steps_done": done, "timed_out": bool(timed_out), "time_limit_s": time_limit,
               "stepping_s": float(curve["wall_time"].sum()),
               "newton_iterations_mean": float(curve["iterations"].iloc[1:].mean()),
               "dem_steps": int(curve["dem_steps"].sum()),
               "rve_state": json.loads((work / "rve_state.json").read_text()),
               "patches": [p[0] for p in EXAMPLE_PATCHES]
               + [f"{p[0]}: {p[1]!r} -> {p[2]!r} (x{p[3]})" for p in MODULE_PATCHES]}
    curve.to_csv(work / "gz_curve.csv", index=False)
    (work / "gz_summary.json").write_text(json.dumps(summary, indent=1))
    return curve, summary
