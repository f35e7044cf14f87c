"""Guo & Zhao's RVE preparation (docs/design.md#guo-zhao-rve), written for our scene format.

Discs with radius uniform in [rMean(1 − fuzz), rMean(1 + fuzz)] are placed by YADE's
``SpherePack.makeCloud`` in a square periodic cell, consolidated without friction to an
isotropic stress by ``PeriTriaxController`` (dynamic cell), then the friction angle is set on the
material and on the existing contacts, the cell is frozen and velocities are zeroed.

Job keys: ``out`` (scene JSON), ``particles`` (400), ``seed`` (1), ``pressure`` [Pa] (1e5),
``friction_angle`` [rad] (0.5), ``young`` [Pa] (6e8), ``kt_over_kn`` (0.8), ``density``
[kg/m³] (2650, disc masses), ``thickness`` [m] (0.1), ``damping`` (0.1), ``r_mean`` [m]
(0.005), ``r_rel_fuzz`` (0.4), ``cloud_size`` [m] (0.24), ``max_steps`` (2e6).
The material density used by ``PWaveTimeStep`` is YADE's FrictMat default, as in the example.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(sys.argv[0])))

import scene_io
from yade import O, pack, utils
from yade.minieigenHP import Matrix3, Vector3
from yade.wrapper import FrictMat, PeriTriaxController

job = scene_io.read_job()
n = int(job.get("particles", 400))
seed = int(job.get("seed", 1))
pressure = float(job.get("pressure", 1e5))
phi = float(job.get("friction_angle", 0.5))
young = float(job.get("young", 6e8))
ratio = float(job.get("kt_over_kn", 0.8))
density = float(job.get("density", 2650.0))
t = float(job.get("thickness", 0.1))
damping = float(job.get("damping", 0.1))
size = float(job.get("cloud_size", 0.24))
max_steps = int(job.get("max_steps", 2_000_000))

O.reset()
O.materials.append(FrictMat(young=young, poisson=ratio, frictionAngle=0.0))
sp = pack.SpherePack()
sp.makeCloud(minCorner=(0, 0, 0.5 * t), maxCorner=(size, size, 0.5 * t),
             rMean=float(job.get("r_mean", 0.005)), rRelFuzz=float(job.get("r_rel_fuzz", 0.4)),
             num=n, periodic=True, seed=seed)
sp.toSimulation()
O.cell.hSize = Matrix3(size, 0, 0, 0, size, 0, 0, 0, t)
if len(O.bodies) != n:
    raise RuntimeError(f"makeCloud placed {len(O.bodies)} discs, asked for {n}")
for b in O.bodies:
    scene_io.set_disc_inertia(b, density, t)
O.dt = utils.PWaveTimeStep()

state = {"done": False}


def consolidated():
    state["done"] = True
    O.pause()


controller = PeriTriaxController(
    dynCell=True, goal=(-pressure, -pressure, 0), stressMask=3, relStressTol=1e-3,
    maxUnbalanced=1e-3, maxStrainRate=(0.5, 0.5, 0.0), doneHook="consolidated()", label="biax")
O.engines = scene_io.standard_engines(controller, damping)
# doneHook strings run in YADE's __main__ namespace
import __main__  # noqa: E402

__main__.consolidated = consolidated

with scene_io.Stopwatch() as sw:
    O.run(max_steps, True)
if not state["done"]:
    raise RuntimeError(f"consolidation did not converge in {max_steps} steps")
steps = O.iter
O.engines = scene_io.standard_engines(None, damping)
utils.setContactFriction(phi)
O.cell.trsf = Matrix3.Identity
O.cell.velGrad = Matrix3.Zero
for b in O.bodies:
    b.state.vel = Vector3.Zero
    b.state.angVel = Vector3.Zero
template = {
    "format": scene_io.SCENE_FORMAT, "version": scene_io.SCENE_VERSION, "thickness": t,
    "density": density, "friction_angle": phi, "damping": damping,
    "stiffness": {"law": "frictmat", "young": young, "kt_over_kn": ratio}, "seed": seed,
}
# at rest in a frozen cell (the velGrad set above is still only YADE's nextVelGrad)
out = scene_io.scene_from_simulation(template, velocity_gradient=[[0.0, 0.0], [0.0, 0.0]])
sxx, syy, sxy = scene_io.stress_2d()
out["prepare"] = {
    "stress": [sxx, syy, sxy], "void_ratio": scene_io.void_ratio(),
    "coordination": scene_io.coordination(), "steps": steps, "wall_s": sw.seconds,
    "procedure": "Guo & Zhao prepareRVE (YADE makeCloud, frictionless PeriTriaxController)",
}
scene_io.write_json(job["out"], out)
print("prepared", out["prepare"])
