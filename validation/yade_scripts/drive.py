"""Strain-driven path through ∇u, applied the way Guo & Zhao's ``shear2D`` does.

The total displacement gradient G is split into K equal increments; each increment ΔG is
applied by a constant cell velocity gradient ΔG/(n·dt) over n = max(1e5·max|ΔG|, 2) steps
(≤ 1e-5 strain a step), after which the velocity gradient is set back to zero.

Job keys: ``scene``, ``out`` (CSV), ``grad_u`` [Gxx, Gxy, Gyx, Gyy] (G_ij = ∂u_i/∂x_j),
``increments`` K, ``tangent_at`` (increment indices at which YADE's getStressAndTangent is
written, default none), ``summary`` (JSON path for timings), ``final_scene`` (optional JSON).

CSV: one row per increment, increment 0 the initial state: ``rve``, ``increment``, ``Gxx``,
``Gxy``, ``Gyx``, ``Gyy`` (the nominal accumulated ∇u), ``sxx``, ``syy``, ``sxy`` [Pa],
``void_ratio``, ``coordination``, ``steps``, and where asked ``D_xx_xx`` … the Voigt
(xx, yy, xy) tangent [Pa] (empty cells elsewhere).
"""

import csv
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

with scene_io.Stopwatch() as build:
    scene_io.build_scene(scene)
    scene_io.update_contacts()
dg = [g / k_total for g in grad]
ns = int(max(1e5 * max(abs(g) for g in dg), 2))


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
        O.cell.velGrad = Matrix3(dg[0], dg[1], 0, dg[2], dg[3], 0, 0, 0, 0) / (ns * O.dt)
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
        "steps_per_increment": ns, "particles": len(O.bodies), "timestep": O.dt})
