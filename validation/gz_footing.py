"""Guo & Zhao's strip footing in their own FEM × DEM code and in ours, on one coarse mesh.

Their script (Debian yade's ``examples/FEMxDEM/footing.py``: half domain 0.6 m × 0.4 m, tri6,
a rough rigid footing of half-width 0.05 m pushed 0.25 mm a load step, a surcharge of 20 kPa
on the rest of the top, rollers on the sides, the base fixed, every Gauss point starting from
one RVE) is run on a coarse mesh of the same geometry written here as gmsh 2.2
(:func:`footing_mesh`, :func:`write_gmsh22`), patched only in size, Python 3 and
instrumentation (:data:`FOOTING_PATCHES`). Ours runs the same mesh, RVE, conditions and
load steps as a ``boundary-value`` scene (:func:`scene_text`). Their footing force is the
traction of the Gauss stresses projected onto the corner nodes (escript's ``Projector``:
reduced order, lumped mass) integrated over the footing base; :func:`footing_traction_force`
computes the same from any code's Gauss stresses, so ours is reported both ways (and the
function is checked against their own number on their own stresses).

Run: ``python -m granular_material_validation.gz_footing --out DIR [--steps N]``.
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pandas as pd
from granular_material_validation.guo_zhao_runner import (
    apply_patches,
    copy_modules,
    find_escript,
    group_cpu_s,
)
from granular_material_validation.gz_footing_mesh import (
    HALF_WIDTH,
    SETTLEMENT_PER_STEP,
    SURCHARGE,
    X_LINES,
    Y_LINES,
    FootingMesh,
    footing_mesh,
    footing_nodal_reaction,
    footing_traction_force,
    lumped_nodal_stress,
    match_elements,
    read_gmsh22,
    write_gmsh22,
)
from granular_material_validation.yade_io import export_rve
from granular_material_validation.yade_runner import YadeError, find_yade, run_script

from granular_material.results.writers import read_points

__all__ = ["FOOTING_PATCHES", "HALF_WIDTH", "SETTLEMENT_PER_STEP", "SURCHARGE", "X_LINES",
           "Y_LINES", "FootingMesh", "finish_footing", "footing_mesh",
           "footing_nodal_reaction", "footing_traction_force", "guo_zhao_footing",
           "lumped_nodal_stress", "match_elements", "ours_footing", "patch_footing",
           "read_gmsh22", "scene_text", "write_gmsh22"]

#: (what, original text, replacement) applied to their footing.py; {name}: the job's
FOOTING_PATCHES: tuple[tuple[str, str, str], ...] = (
    ("module: their 2D MultiScale (the script names a module 'msFEM' that is not shipped), "
     "with the counting probe", "from msFEM import MultiScale",
     "from gz_probe import MultiScale\nimport gz_probe"),
    ("python 3", "fout = file('./result/bearing.dat', 'w')",
     "fout = open('./result/bearing.dat', 'w')"),
    ("size: the mesh file", "ReadGmsh('footing.msh',", "ReadGmsh({mesh!r},"),
    ("size: Gauss points (3 a tri6)", "numg = 3 * 2500", "numg = 3 * {elements}"),
    ("size: processes of the multiprocessing pool", "nump = 16", "nump = {processes}"),
    ("size: load steps", "while t < 58:", "while t < {steps}:"),
    ("log: bearing.dat flushed each load step (a run stopped at its time limit keeps them)",
     "\tfout.write(str(t * vel) + ' ' + str(forceFoot[0]) + ' ' + str(forceFoot[1]) + ' ' + "
     "str(lengthFoot) + '\\n')",
     "\tfout.write(str(t * vel) + ' ' + str(forceFoot[0]) + ' ' + str(forceFoot[1]) + ' ' + "
     "str(lengthFoot) + '\\n')\n\tfout.flush()"),
    ("log: Newton iterations printed (verbose)", "verbose=False)", "verbose=True)"),
    ("probe: initial state and Gauss-point coordinates",
     "disp = Vector(0., Solution(mydomain))",
     "gz_probe.start(prob, mydomain)\ndisp = Vector(0., Solution(mydomain))"),
    ("probe: state after each load step", "\trotation = prob.getLocalAvgRotation()",
     "\tgz_probe.record(t, prob, vR)\n\trotation = prob.getLocalAvgRotation()"),
)
_CONVERGED = re.compile(r"Convergence reached after (\d+) iteration\(s\)! Relative error: (\S+)")


def patch_footing(text: str, **job: Any) -> str:
    """``footing.py`` with :data:`FOOTING_PATCHES` applied; each original must occur once."""
    return apply_patches(text, FOOTING_PATCHES, "footing.py", **job)


def _their_folder(work: Path, job: dict[str, Any]) -> None:
    example = copy_modules(work)
    source = example.parent / "footing.py"
    raw = (gzip.open(str(source) + ".gz", "rt").read() if not source.is_file()
           else source.read_text())
    (work / "footing.py").write_text(patch_footing(raw, **job))


def guo_zhao_footing(rve: str | Path, workdir: str | Path, mesh: FootingMesh, steps: int,
                     processes: int = 2, timeout: float = 3600.0) -> dict[str, Any]:
    """Their ``footing.py`` on ``mesh`` with RVE 0 of ``rve`` at every Gauss point for
    ``steps`` load steps (a run stopped at ``timeout`` [s] keeps the steps done). Returns
    ``curve`` (step, settlement [m], their force_x, force_y [N/m] and base length [m],
    iterations, wall_time [s], dem_steps), ``points`` (the probe's Gauss-point states) and
    the summary (wall_s, cpu_s of the process group, processes, timed_out)."""
    work = Path(workdir).resolve()
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    write_gmsh22(mesh, work / "mesh.msh")
    export_rve(rve, work / "rve.scene.json")
    run_script("gz_rve_to_yade.py", {"scene": str(work / "rve.scene.json"),
                                     "out": str(work / "0.yade.gz"),
                                     "summary": str(work / "rve_state.json")}, work)
    job = {"mesh": "mesh.msh", "elements": len(mesh.triangles), "processes": int(processes),
           "steps": int(steps)}
    _their_folder(work, job)
    escript = find_escript()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "DISPLAY": "",
           "PYTHONPATH": os.pathsep.join([str(escript), str(work / "FEMxDEM")]),
           "LD_LIBRARY_PATH": os.pathsep.join(
               p for p in (str(escript / "lib"), os.environ.get("LD_LIBRARY_PATH", "")) if p)}
    start, seen, timed_out = time.perf_counter(), 0.0, False
    with open(work / "footing.log", "w") as fh:
        proc = subprocess.Popen([find_yade(), "-n", "-x", "footing.py"], cwd=work, env=env,
                                stdout=fh, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                start_new_session=True)
        while proc.poll() is None:
            seen = max(seen, group_cpu_s(proc.pid))
            if time.perf_counter() - start > timeout:
                timed_out = True
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
                break
            time.sleep(1.0)
    wall = time.perf_counter() - start
    text = (work / "footing.log").read_text(errors="replace")
    if not timed_out and (proc.returncode != 0 or "Traceback (most recent call last)" in text):
        tail = "\n".join(text.splitlines()[-25:])
        raise YadeError(f"their footing.py failed (exit {proc.returncode}):\n{tail}")
    return finish_footing(work, job, wall, seen, timed_out)


def finish_footing(work: str | Path, job: dict[str, Any], wall_s: float, cpu_s: float,
                   timed_out: bool = False) -> dict[str, Any]:
    """Read back a run of their ``footing.py`` in ``work`` (finished, or stopped with the
    load steps it had done), write ``gz_curve.csv`` and ``gz_summary.json`` there and return
    them as :func:`guo_zhao_footing` does (``wall_s``, ``cpu_s`` [s] as measured by the
    caller)."""
    work = Path(work)
    text = (work / "footing.log").read_text(errors="replace")
    curve = _their_curve(work, text)
    summary = {"job": job, "wall_s": wall_s, "cpu_s": cpu_s, "processes": job["processes"],
               "timed_out": bool(timed_out), "steps_done": int(len(curve) - 1),
               "rve_state": json.loads((work / "rve_state.json").read_text()),
               "patches": [p[0] for p in FOOTING_PATCHES]}
    (work / "gz_summary.json").write_text(json.dumps(summary, indent=1))
    curve.to_csv(work / "gz_curve.csv", index=False)
    return {"curve": curve, "summary": summary}


def _their_curve(work: Path, log: str) -> pd.DataFrame:
    """One row per load step (step 0 included) from bearing.dat, the probe and the log."""
    bearing = [line.split() for line in (work / "result" / "bearing.dat").read_text()
               .splitlines() if line and not line.startswith("#")]
    probe = [json.loads(line) for line in (work / "gz_probe.jsonl").read_text().splitlines()
             if line.endswith("}")]
    iterations = [0] + [int(m.group(1)) for m in _CONVERGED.finditer(log)]
    n = min(len(bearing), len(probe), len(iterations))
    rows = []
    for k in range(n):
        rows.append({"step": k, "settlement": k * SETTLEMENT_PER_STEP,
                     "force_x": float(bearing[k][1]), "force_y": float(bearing[k][2]),
                     "base_length": float(bearing[k][3]), "iterations": iterations[k],
                     "wall_time": probe[k]["wall_s"] - (probe[k - 1]["wall_s"] if k else 0.0),
                     "dem_steps": probe[k]["dem_steps"]
                     - (probe[k - 1]["dem_steps"] if k else 0)})
    return pd.DataFrame(rows)


def scene_text(mesh_file: str | Path, rve: str | Path, steps: int, newton: str = "") -> str:
    """Our ``boundary-value`` scene of their footing on ``mesh_file`` with RVE file ``rve``
    copied to every point, ``steps`` load steps of :data:`SETTLEMENT_PER_STEP`; ``newton``:
    extra lines of its ``[newton]`` table."""
    b = HALF_WIDTH
    return "\n".join([
        'test = "boundary-value"', 'name = "gz-footing-ours"', f"steps = {int(steps)}", "",
        "[mesh]", f'file = "{Path(mesh_file).resolve()}"', "",
        "[boundaries]", 'left = "x = left"', 'right = "x = right"',
        'bottom = "y = bottom"', f'footing = "y = top and x <= {b}"',
        f'surface = "y = top and x >= {b}"', "",
        '[[conditions]]\ntype = "roller"\nboundary = "left"\ncomponent = "x"',
        '[[conditions]]\ntype = "roller"\nboundary = "right"\ncomponent = "x"',
        '[[conditions]]\ntype = "fixed"\nboundary = "bottom"',
        '[[conditions]]\ntype = "rigid"\nboundary = "footing"',
        f"displacement = [0.0, {-steps * SETTLEMENT_PER_STEP!r}]\nrough = true",
        f'[[conditions]]\ntype = "pressure"\nboundary = "surface"\nvalue = {SURCHARGE!r}', "",
        f'[initial]\nstate = "uniform"\npressure = {SURCHARGE!r}', "",
        '[material]\nname = "dem"', "[material.parameters]", f'rve = "{Path(rve).resolve()}"',
        "", "[newton]", newton, "", '[output]\ndevice = "cpu"\nprogress = false', ""])


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def ours_footing(rve: str | Path, workdir: str | Path, mesh: FootingMesh, steps: int,
                 newton: str = "", timeout: float = 3600.0) -> dict[str, Any]:
    """Our ``granular-material run`` of :func:`scene_text` on ``mesh`` in ``workdir``.
    Returns ``steps`` (our steps.csv), ``points`` (points.csv) and the summary (ours, with
    the subprocess's wall_s and cpu_s)."""
    work = Path(workdir).resolve()
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    write_gmsh22(mesh, work / "mesh.msh")
    (work / "scene.toml").write_text(scene_text(work / "mesh.msh", rve, steps, newton))
    exe = Path(sys.executable).with_name("granular-material")
    cpu0, start = _children_cpu_s(), time.perf_counter()
    with open(work / "run.log", "w") as fh:
        proc = subprocess.run([str(exe), "run", str(work / "scene.toml"), "--out",
                               str(work / "run")], stdout=fh, stderr=subprocess.STDOUT,
                              timeout=timeout, check=False)
    wall, cpu = time.perf_counter() - start, _children_cpu_s() - cpu0
    if proc.returncode != 0:
        tail = "\n".join((work / "run.log").read_text().splitlines()[-25:])
        raise RuntimeError(f"our footing run failed (exit {proc.returncode}):\n{tail}")
    summary = json.loads((work / "run" / "summary.json").read_text())
    summary.update(driver_wall_s=wall, driver_cpu_s=cpu)
    (work / "summary.json").write_text(json.dumps(summary, indent=1))
    return {"steps": pd.read_csv(work / "run" / "steps.csv"),
            "points": read_points(work / "run"), "summary": summary}


def main(argv: list[str] | None = None) -> int:
    """Run both codes (theirs first) and write ``comparison.json`` under ``--out``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--rve", type=Path, required=True, help="RVE file (.npz), one RVE")
    ap.add_argument("--steps", type=int, default=12)
    ap.add_argument("--processes", type=int, default=2)
    ap.add_argument("--only", choices=("theirs", "ours", "both"), default="both")
    ap.add_argument("--timeout", type=float, default=3600.0)
    a = ap.parse_args(argv)
    mesh = footing_mesh()
    a.out.mkdir(parents=True, exist_ok=True)
    if a.only in ("theirs", "both"):
        guo_zhao_footing(a.rve, a.out / "guo_zhao", mesh, a.steps, a.processes, a.timeout)
    if a.only in ("ours", "both"):
        ours_footing(a.rve, a.out / "ours", mesh, a.steps, timeout=a.timeout)
    if (a.out / "guo_zhao" / "gz_summary.json").is_file() and \
            (a.out / "ours" / "summary.json").is_file():
        from granular_material_validation.gz_footing_report import compare, markdown

        print(markdown(compare(a.out)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
