"""Drained biaxial element test of one RVE in YADE.

The axial strain εyy is driven at a constant rate (``strain_per_step`` a step) while
``PeriTriaxController`` (static cell, stiffness-based servo) holds σxx at −``confining``;
z is held at zero strain. Rows are written every ``record_strain`` of axial strain.

Job keys: ``scene`` (scene JSON), ``out`` (CSV), ``confining`` [Pa] (1e5, a magnitude),
``axial_strain`` (0.1, engineering, compression positive), ``strain_per_step`` (1e-5),
``record_strain`` (1e-4), ``lateral_rate_factor`` (10: the servo's largest lateral strain
rate in units of the axial one), ``summary`` (JSON path for timings and the step count).

CSV columns: ``step``, ``axial_strain`` = 1 − Hyy/Hyy0 (compression positive),
``volumetric_strain`` = A/A0 − 1 (tension positive), ``sxx``, ``syy``, ``sxy`` [Pa] (tension
positive), ``void_ratio``, ``coordination``.
"""

import csv
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(sys.argv[0])))

import scene_io
from yade import O
from yade.wrapper import PeriTriaxController

job = scene_io.read_job()
scene = scene_io.read_scene(job["scene"])
confining = float(job.get("confining", 1e5))
target = float(job.get("axial_strain", 0.1))
per_step = float(job.get("strain_per_step", 1e-5))
record = float(job.get("record_strain", 1e-4))
lateral_factor = float(job.get("lateral_rate_factor", 10.0))
if not (0 < target < 0.5 and 0 < per_step <= 1e-3 and per_step <= record <= target):
    raise ValueError(f"bad strains: axial_strain={target}, strain_per_step={per_step}, "
                     f"record_strain={record}")

with scene_io.Stopwatch() as build:
    scene_io.build_scene(scene)
    rate = per_step / O.dt
    controller = PeriTriaxController(
        dynCell=False, stressMask=1, goal=(-confining, math.log(1.0 - target), 0.0),
        maxStrainRate=(lateral_factor * rate, rate, 0.0), globUpdate=1, maxUnbalanced=-1.0,
        label="servo")
    O.engines = scene_io.standard_engines(controller, scene["damping"])
    scene_io.update_contacts()
h0 = O.cell.hSize
area0 = h0[0, 0] * h0[1, 1] - h0[0, 1] * h0[1, 0]
hyy0 = h0[1, 1]


def row() -> list:
    h = O.cell.hSize
    area = h[0, 0] * h[1, 1] - h[0, 1] * h[1, 0]
    sxx, syy, sxy = scene_io.stress_2d()
    return [O.iter, 1.0 - h[1, 1] / hyy0, area / area0 - 1.0, sxx, syy, sxy,
            scene_io.void_ratio(), scene_io.coordination()]


rows = [row()]
chunk = max(1, round(record / per_step))
with scene_io.Stopwatch() as run:
    while rows[-1][1] < target - 1e-9:
        scene_io.advance(chunk)
        rows.append(row())
        if len(rows) > 10 * target / record + 100:
            raise RuntimeError(f"axial strain stuck at {rows[-1][1]}")
with open(job["out"], "w", newline="") as fh:
    writer = csv.writer(fh)
    writer.writerow(["step", "axial_strain", "volumetric_strain", "sxx", "syy", "sxy",
                     "void_ratio", "coordination"])
    writer.writerows(rows)
if job.get("summary"):
    scene_io.write_json(job["summary"], {
        "build_s": build.seconds, "run_s": run.seconds, "steps": O.iter,
        "particles": len(O.bodies), "timestep": O.dt, "strain_per_step": per_step})
