"""Plain stepping throughput of one RVE in YADE (one OpenMP thread unless told otherwise).

Job keys: ``scene``, ``steps`` (timed steps), ``warmup`` (untimed steps first, default 100),
``out`` (JSON: ``particle_steps_per_s``, ``steps``, ``particles``, ``wall_s``, ``build_s``).
The scene build and the warm-up are excluded from the timing.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(sys.argv[0])))

import scene_io
from yade import O

job = scene_io.read_job()
scene = scene_io.read_scene(job["scene"])
steps = int(job["steps"])
if steps < 1:
    raise ValueError(f"steps must be >= 1, got {steps}")
with scene_io.Stopwatch() as build:
    scene_io.build_scene(scene)
scene_io.advance(int(job.get("warmup", 100)))
with scene_io.Stopwatch() as run:
    scene_io.advance(steps)
n = len(O.bodies)
scene_io.write_json(job["out"], {
    "particle_steps_per_s": n * steps / run.seconds, "steps": steps, "particles": n,
    "wall_s": run.seconds, "build_s": build.seconds, "timestep": O.dt})
