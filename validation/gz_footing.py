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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from granular_material_validation.guo_zhao_runner import (
    MODULE_PATCHES,
    find_escript,
    find_femxdem,
    group_cpu_s,
)
from granular_material_validation.yade_io import export_rve
from granular_material_validation.yade_runner import SCRIPTS, YadeError, find_yade, run_script

__all__ = ["FOOTING_PATCHES", "HALF_WIDTH", "SETTLEMENT_PER_STEP", "SURCHARGE", "X_LINES",
           "Y_LINES", "FootingMesh", "footing_mesh", "footing_traction_force",
           "guo_zhao_footing", "lumped_nodal_stress", "match_elements", "ours_footing",
           "patch_footing", "read_gmsh22", "scene_text", "write_gmsh22"]

#: their footing's half-width B [m], settlement a load step [m], surcharge [Pa]
HALF_WIDTH = 0.05
SETTLEMENT_PER_STEP = 0.25e-3
SURCHARGE = 20e3
#: grid lines of the coarse mesh [m]: 8 × 5 cells, a node at the footing's edge x = B
X_LINES = (0.0, 0.025, 0.05, 0.075, 0.1, 0.15, 0.25, 0.4, 0.6)
Y_LINES = (-0.4, -0.2, -0.1, -0.05, -0.025, 0.0)

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


@dataclass(frozen=True)
class FootingMesh:
    """A tri6 mesh of the half domain: ``points`` (n, 2) [m]; ``triangles`` (ne, 6) node
    indices in gmsh order (corners counter-clockwise, then the midsides of 0-1, 1-2, 2-0);
    ``lines`` (nb, 3) the boundary's line3 edges (ends, then midside)."""

    points: np.ndarray
    triangles: np.ndarray
    lines: np.ndarray

    @property
    def corners(self) -> np.ndarray:
        """The (ne, 3) corner nodes of every triangle."""
        return self.triangles[:, :3]


def footing_mesh(x_lines: tuple[float, ...] = X_LINES,
                 y_lines: tuple[float, ...] = Y_LINES) -> FootingMesh:
    """The rectangle spanned by the increasing grid lines ``x_lines`` × ``y_lines`` [m], each
    cell cut into two tri6 along its diagonal from lower left to upper right."""
    xs, ys = np.asarray(x_lines, float), np.asarray(y_lines, float)
    if xs.size < 2 or ys.size < 2 or np.any(np.diff(xs) <= 0) or np.any(np.diff(ys) <= 0):
        raise ValueError("grid lines must be increasing, at least two each way")
    # a (2 nx + 1) × (2 ny + 1) grid of nodes holds the corners and every midside
    gx = np.concatenate([np.ravel(np.column_stack([xs[:-1], 0.5 * (xs[:-1] + xs[1:])])),
                         xs[-1:]])
    gy = np.concatenate([np.ravel(np.column_stack([ys[:-1], 0.5 * (ys[:-1] + ys[1:])])),
                         ys[-1:]])
    nx, ny = gx.size, gy.size
    index = np.full((nx, ny), -1)
    used = np.zeros((nx, ny), dtype=bool)
    used[::2, :] = True
    used[:, ::2] = True
    used[1::2, 1::2] = True  # the cell's diagonal midside
    index[used] = np.arange(int(used.sum()))
    ii, jj = np.nonzero(used)
    order = np.argsort(index[used])
    points = np.column_stack([gx[ii[order]], gy[jj[order]]])
    tris = []
    for i in range(0, nx - 1, 2):
        for j in range(0, ny - 1, 2):
            a, b, c, d = (i, j), (i + 2, j), (i + 2, j + 2), (i, j + 2)
            for p, q, r in ((a, b, c), (a, c, d)):
                mids = [((s[0] + t[0]) // 2, (s[1] + t[1]) // 2)
                        for s, t in ((p, q), (q, r), (r, p))]
                tris.append([index[n] for n in (p, q, r, *mids)])
    lines = []
    for side in ([(i, 0) for i in range(nx)], [(nx - 1, j) for j in range(ny)],
                 [(i, ny - 1) for i in range(nx - 1, -1, -1)],
                 [(0, j) for j in range(ny - 1, -1, -1)]):
        for k in range(0, len(side) - 1, 2):
            lines.append([index[side[k]], index[side[k + 2]], index[side[k + 1]]])
    return FootingMesh(points, np.asarray(tris, dtype=np.int64), np.asarray(lines, np.int64))


def write_gmsh22(mesh: FootingMesh, path: str | Path) -> Path:
    """Write ``mesh`` as an ASCII gmsh 2.2 file (triangle6 in physical group 1, the boundary's
    line3 in group 2), the format escript's ``ReadGmsh`` and ours read."""
    import meshio

    path = Path(path)
    nl, nt = len(mesh.lines), len(mesh.triangles)
    out = meshio.Mesh(
        np.column_stack([mesh.points, np.zeros(len(mesh.points))]),
        [("line3", mesh.lines), ("triangle6", mesh.triangles)],
        cell_data={"gmsh:physical": [np.full(nl, 2), np.full(nt, 1)],
                   "gmsh:geometrical": [np.full(nl, 2), np.full(nt, 1)]})
    meshio.write(path, out, file_format="gmsh22", binary=False)
    return path


def read_gmsh22(path: str | Path) -> FootingMesh:
    """The :class:`FootingMesh` of a file written by :func:`write_gmsh22`."""
    import meshio

    m = meshio.read(path)
    return FootingMesh(np.asarray(m.points[:, :2], float),
                       np.asarray(m.cells_dict["triangle6"], np.int64),
                       np.asarray(m.cells_dict["line3"], np.int64))


def lumped_nodal_stress(points: np.ndarray, corners: np.ndarray, gauss_xy: np.ndarray,
                        stress: np.ndarray) -> np.ndarray:
    """Gauss stresses [Pa] (ne·nq, 2, 2) projected onto the corner nodes as escript's default
    ``Projector`` does (linear shape functions, lumped mass): σ_a = Σ λ_a(q) w_q σ_q /
    Σ λ_a(q) w_q over the points q of the triangles at node a, w_q = area/nq (the equal
    weights of both codes' 3-point rules), λ the barycentric coordinates of the point at
    ``gauss_xy`` (ne·nq, 2) [m] in its triangle (point p lies in triangle p // nq)."""
    stress = np.asarray(stress, float).reshape(-1, 2, 2)
    ne = len(corners)
    nq = len(stress) // ne
    if nq * ne != len(stress) or len(gauss_xy) != len(stress):
        raise ValueError(f"{len(stress)} stresses and {len(gauss_xy)} points for {ne} "
                         "triangles")
    xy = points[corners]  # (ne, 3, 2)
    t = np.stack([xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]], axis=2)  # (ne, 2, 2)
    area = 0.5 * np.abs(np.linalg.det(t))
    rel = np.asarray(gauss_xy, float) - np.repeat(xy[:, 0], nq, axis=0)
    local = np.linalg.solve(np.repeat(t, nq, axis=0), rel[:, :, None])[:, :, 0]
    lam = np.column_stack([1.0 - local.sum(axis=1), local])  # (ne·nq, 3)
    if lam.min() < -1e-9:
        bad = int(np.argmin(lam.min(axis=1)))
        raise ValueError(f"Gauss point {bad} at {gauss_xy[bad]} lies outside triangle "
                         f"{bad // nq} (points must be ordered element by element)")
    w = lam * np.repeat(area / nq, nq)[:, None]
    nodes = np.repeat(corners, nq, axis=0)
    mass = np.zeros(len(points))
    rhs = np.zeros((len(points), 2, 2))
    np.add.at(mass, nodes.ravel(), w.ravel())
    np.add.at(rhs, nodes.ravel(), (w[:, :, None, None] * stress[:, None]).reshape(-1, 2, 2))
    out = np.full((len(points), 2, 2), np.nan)
    has = mass > 0
    out[has] = rhs[has] / mass[has, None, None]
    return out


def match_elements(mesh: FootingMesh, gauss_xy: np.ndarray, nq: int = 3) -> np.ndarray:
    """The triangle of ``mesh`` of each element of a code's Gauss points ``gauss_xy``
    (ne·nq, 2) [m], ordered element by element: the triangle whose centroid is nearest the
    centroid of the element's points (both codes' rules are symmetric, so the two agree).
    ValueError unless the match is one to one."""
    centres = np.asarray(gauss_xy, float).reshape(-1, nq, 2).mean(axis=1)
    ours = mesh.points[mesh.corners].mean(axis=1)
    dist = np.linalg.norm(centres[:, None] - ours[None], axis=2)
    match = dist.argmin(axis=1)
    if len(match) != len(ours) or len(set(match.tolist())) != len(match) \
            or dist.min(axis=1).max() > 1e-6:
        raise ValueError("the Gauss points do not match the mesh's triangles one to one")
    return match


def footing_traction_force(mesh: FootingMesh, gauss_xy: np.ndarray, stress: np.ndarray,
                           half_width: float = HALF_WIDTH, nq: int = 3,
                           ) -> tuple[np.ndarray, float]:
    """Their footing force [N/m] (2,): the traction σ·n (n = (0, 1), the top's outward
    normal) of the lumped nodal stress (:func:`lumped_nodal_stress`), linear along each edge,
    integrated over the top edges with x ≤ ``half_width`` [m]; and the base's length [m].
    ``gauss_xy`` (ne·nq, 2) [m] and ``stress`` (ne·nq, 2, 2) [Pa] element by element in
    any element order (:func:`match_elements`). Reference geometry (theirs integrates on
    the updated mesh)."""
    match = match_elements(mesh, gauss_xy, nq)
    order = np.argsort(match)
    xy = np.asarray(gauss_xy, float).reshape(-1, nq, 2)[order].reshape(-1, 2)
    sig = np.asarray(stress, float).reshape(-1, nq, 2, 2)[order].reshape(-1, 2, 2)
    nodal = lumped_nodal_stress(mesh.points, mesh.corners, xy, sig)
    p = mesh.points
    top = p[:, 1].max()
    force, length = np.zeros(2), 0.0
    for a, b, _ in mesh.lines:
        ends = p[[a, b]]
        if np.all(np.abs(ends[:, 1] - top) < 1e-9) and np.all(ends[:, 0] <= half_width + 1e-9):
            span = float(abs(ends[1, 0] - ends[0, 0]))
            force += span * 0.5 * (nodal[a] + nodal[b]) @ np.array([0.0, 1.0])
            length += span
    return force, length


def patch_footing(text: str, **job: Any) -> str:
    """``footing.py`` with :data:`FOOTING_PATCHES` applied; each original must occur once."""
    for what, old, new in FOOTING_PATCHES:
        if text.count(old) != 1:
            raise ValueError(f"patch '{what}': {old!r} occurs {text.count(old)} times in "
                             "footing.py, expected once (another yade version?)")
        text = text.replace(old, new.format(**job))
    return text


def _their_folder(work: Path, job: dict[str, Any]) -> None:
    module_dir, example = find_femxdem()
    modules = work / "FEMxDEM"
    shutil.copytree(module_dir, modules)
    for name, old, new, count in MODULE_PATCHES:
        path = modules / name
        text = path.read_text()
        if text.count(old) != count:
            raise ValueError(f"{name}: {old!r} occurs {text.count(old)} times, not {count}")
        path.write_text(text.replace(old, new))
    shutil.copy(SCRIPTS / "gz_probe.py", modules / "gz_probe.py")
    (modules / "yadeimport.py").symlink_to(find_yade())
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
    curve = _their_curve(work, text)
    summary = {"job": job, "wall_s": wall, "cpu_s": seen, "processes": int(processes),
               "timed_out": timed_out, "steps_done": int(len(curve) - 1),
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
            "points": pd.read_csv(work / "run" / "points.csv"), "summary": summary}


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
