"""Rigid rotation of a periodic disc packing: a cell velocity gradient that is a pure spin.

The cell turns by ``theta`` [rad] over ``steps`` steps with L = (θ/(steps·dt))·[[0, −1],
[1, 0]] and L is then set back to zero. YADE's homoDeform adds the change of the affine
field to every body's velocity and the change of the cell's spin to every body's angular
velocity (NewtonIntegrator), and integrates the cell with H += dt·L·H (forward Euler: a
spin also dilates the cell, by a factor 1 + (θ/steps)² in area a step).

Job keys: ``scene``, ``out`` (JSON), ``theta`` [rad], ``steps``.
Output: ``stress0``, ``stress1`` (sxx, syy, sxy) [Pa] before and after, ``cell0``, ``cell1``
(2×2, columns = cell vectors) [m], ``steps``, ``timestep`` [s], ``run_s``.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(sys.argv[0])))

import scene_io
from yade import O
from yade.minieigenHP import Matrix3

job = scene_io.read_job()
scene = scene_io.read_scene(job["scene"])
theta = float(job["theta"])
steps = int(job["steps"])
if steps < 1:
    raise ValueError(f"steps must be >= 1, got {steps}")

scene_io.build_scene(scene)
scene_io.update_contacts()
stress0 = list(scene_io.stress_2d())
cell0 = scene_io.cell_2d()
w = theta / (steps * O.dt)
with scene_io.Stopwatch() as run:
    O.cell.velGrad = Matrix3(0, -w, 0, w, 0, 0, 0, 0, 0)
    scene_io.advance(steps)
    O.cell.velGrad = Matrix3.Zero
scene_io.write_json(job["out"], {
    "stress0": stress0, "stress1": list(scene_io.stress_2d()), "cell0": cell0,
    "cell1": scene_io.cell_2d(), "steps": steps, "timestep": O.dt, "run_s": run.seconds})
