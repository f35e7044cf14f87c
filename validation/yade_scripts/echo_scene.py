"""Build a scene from our scene file and write it straight back (the exact round-trip check).

Job keys: ``scene`` (input scene JSON), ``out`` (scene JSON written from the simulation),
``steps`` (optional: run this many steps before writing, default 0). The written scene also
holds ``stress`` (sxx, syy, sxy) [Pa] of that state, contacts and forces evaluated in place.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(sys.argv[0])))

import scene_io

job = scene_io.read_job()
scene = scene_io.read_scene(job["scene"])
scene_io.build_scene(scene)
steps = int(job.get("steps", 0))
if steps:
    scene_io.advance(steps)
else:
    scene_io.update_contacts()
out = scene_io.scene_from_simulation(scene)
out["stress"] = list(scene_io.stress_2d())
scene_io.write_json(job["out"], out)
