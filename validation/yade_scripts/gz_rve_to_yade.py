"""Write one RVE of our scene format as the YADE save file Guo & Zhao's code loads.

Guo & Zhao's ``simDEM.initLoad`` loads ``0.yade.gz`` at every Gauss point (their
``prepareRVE.py`` writes it). This script builds the scene of our exporter (same engines as
``prepareRVE.py`` after consolidation: collider, Cundall-Strack contact loop, Newton
integrator with local damping), detects the contacts and evaluates their forces without
integrating (their saved file holds the contacts, and their first stress and tangent are read
from it), and saves it.

Job keys: ``scene`` (scene JSON), ``out`` (the ``.yade.gz`` file to write), ``summary``
(JSON with the stress, void ratio and coordination of the saved state).
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(sys.argv[0])))

import scene_io
from yade import O

job = scene_io.read_job()
scene_io.build_scene(scene_io.read_scene(job["scene"]))
scene_io.update_contacts()
O.save(job["out"])
sxx, syy, sxy = scene_io.stress_2d()
scene_io.write_json(job["summary"], {
    "stress": [sxx, syy, sxy], "void_ratio": scene_io.void_ratio(),
    "coordination": scene_io.coordination(), "timestep": O.dt, "particles": len(O.bodies)})
print("saved", job["out"])
