"""Strain-driven path through ∇u, applied the way Guo & Zhao's ``shear2D`` does.

The total displacement gradient G is split into K equal increments; each increment ΔG is
applied by a constant cell velocity gradient over n = max(1e5·max|ΔG|, 2) steps (≤ 1e-5
strain a step), after which the velocity gradient is set back to zero. ``kinematics``:

- ``"shear2d"`` (default, Guo & Zhao's ``shear2D``): L = ΔG/(n·dt) with ΔG = G/K, so the
  cell follows exp(ΔG) per increment (trace-free ∇u keeps the area exactly);
- ``"exact"``: ΔG_k = F_k·F_(k−1)⁻¹ − I with F_k = I + G·k/K and L = log(I + ΔG_k)/(n·dt), so
  the cell is (I + G·k/K)·H0 after increment k, as our engine's ``dem-drive`` does.

Job keys: ``scene``, ``out`` (CSV), ``grad_u`` [Gxx, Gxy, Gyx, Gyy] (G_ij = ∂u_i/∂x_j),
``increments`` K, ``kinematics``, ``tangent_at`` (increment indices at which YADE's
getStressAndTangent is written, default none), ``summary`` (JSON path for timings),
``final_scene`` (optional JSON).

CSV: one row per increment, increment 0 the initial state: ``rve``, ``increment``, ``Gxx``,
``Gxy``, ``Gyx``, ``Gyy`` (the nominal accumulated ∇u), ``sxx``, ``syy``, ``sxy`` [Pa],
``void_ratio``, ``coordination``, ``steps``, and where asked ``D_xx_xx`` … the Voigt
(xx, yy, xy) tangent [Pa] (empty cells elsewhere).
"""

import csv
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(sys.argv[0])))

import scene_io
from yade import O
from yade.minieigenHP import Matrix3

VOIGT = ("xx", "yy", "xy")
TANGENT_COLUMNS = [f"D_{a}_{b}" for a in VOIGT for b in VOIGT]

job = scene_io.read_job()
scene = scene_io.read_scene(job["scene"])
grad = [float(g) for g in job["grad_u"]]
k_total = int(job["increments"])
if len(grad) != 4 or k_total < 1:
    raise ValueError(f"grad_u needs 4 components and increments >= 1, got {grad}, {k_total}")
tangent_at = {int(i) for i in job.get("tangent_at", [])}
kinematics = job.get("kinematics", "shear2d")
if kinematics not in ("shear2d", "exact"):
    raise ValueError(f"kinematics must be 'shear2d' or 'exact', got {kinematics!r}")


def matmul(a, b):
    return [[sum(a[i][m] * b[m][j] for m in range(2)) for j in range(2)] for i in range(2)]


def inverse(a):
    det = a[0][0] * a[1][1] - a[0][1] * a[1][0]
    return [[a[1][1] / det, -a[0][1] / det], [-a[1][0] / det, a[0][0] / det]]


def log_near_identity(a):
    """log(I + a) of a 2×2 matrix with small entries, by its power series."""
    result = [[0.0, 0.0], [0.0, 0.0]]
    power = [row[:] for row in a]
    for k in range(1, 60):
        sign = 1.0 if k % 2 else -1.0
        result = [[result[i][j] + sign * power[i][j] / k for j in range(2)] for i in range(2)]
        power = matmul(power, a)
        if max(abs(v) for row in power for v in row) < 1e-20:
            break
    return result


def increment(k: int):
    """(ΔG used for the step count, the matrix integrated over the increment) of increment k."""
    if kinematics == "shear2d":
        dg = [[grad[0] / k_total, grad[1] / k_total], [grad[2] / k_total, grad[3] / k_total]]
        return dg, dg

    def f(i):
        return [[1.0 + grad[0] * i / k_total, grad[1] * i / k_total],
                [grad[2] * i / k_total, 1.0 + grad[3] * i / k_total]]

    step = matmul(f(k), inverse(f(k - 1)))
    dg = [[step[0][0] - 1.0, step[0][1]], [step[1][0], step[1][1] - 1.0]]
    return dg, log_near_identity(dg)


with scene_io.Stopwatch() as build:
    scene_io.build_scene(scene)
    scene_io.update_contacts()


def row(k: int) -> list:
    frac = k / k_total
    if k in tangent_at:
        (sxx, syy, sxy), voigt = scene_io.stress_and_tangent_2d()
        tangent = [voigt[a][b] for a in range(3) for b in range(3)]
    else:
        sxx, syy, sxy = scene_io.stress_2d()
        tangent = [""] * 9
    return [0, k, *(g * frac for g in grad), sxx, syy, sxy, scene_io.void_ratio(),
            scene_io.coordination(), O.iter, *tangent]


rows = [row(0)]
with scene_io.Stopwatch() as run:
    for k in range(1, k_total + 1):
        dg, lg = increment(k)
        largest = max(abs(v) for r in dg for v in r)
        # Guo & Zhao's count, or our dem-drive's ceil(max|ΔG|/1e-5) for the exact kinematics
        ns = int(max(1e5 * largest, 2)) if kinematics == "shear2d" else max(
            math.ceil(largest / 1e-5), 2)
        O.cell.velGrad = Matrix3(lg[0][0], lg[0][1], 0, lg[1][0], lg[1][1], 0, 0, 0, 0) / (
            ns * O.dt)
        scene_io.advance(ns)
        O.cell.velGrad = Matrix3.Zero
        rows.append(row(k))
with open(job["out"], "w", newline="") as fh:
    writer = csv.writer(fh)
    writer.writerow(["rve", "increment", "Gxx", "Gxy", "Gyx", "Gyy", "sxx", "syy", "sxy",
                     "void_ratio", "coordination", "steps", *TANGENT_COLUMNS])
    writer.writerows(rows)
if job.get("final_scene"):
    scene_io.write_json(job["final_scene"], scene_io.scene_from_simulation(scene))
if job.get("summary"):
    scene_io.write_json(job["summary"], {
        "build_s": build.seconds, "run_s": run.seconds, "steps": O.iter,
        "steps_per_increment": ns, "kinematics": kinematics, "particles": len(O.bodies),
        "timestep": O.dt})
