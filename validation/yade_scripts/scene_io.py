"""Shared helpers for the YADE side of the cross-validation (runs inside ``yade -n -x``).

Imported by the other scripts of this folder, which put the folder on ``sys.path``. It runs
on Debian's python3 with YADE's modules, never in our virtualenv, so it depends on the
standard library and YADE only.

The scene file is a JSON object (see ``granular_material_validation.yade_io``): 2D discs as
cylinders of thickness ``t`` in a periodic cell whose z size is ``t``, so YADE's stress
(Love, volume = cell volume) is in Pa. Tension positive, SI units.
"""

import json
import math
import os
import sys
import time

from yade import O, utils
from yade.minieigenHP import Matrix3, Vector3
from yade.wrapper import (
    Bo1_Sphere_Aabb,
    ForceResetter,
    FrictMat,
    Ig2_Sphere_Sphere_ScGeom,
    InsertionSortCollider,
    InteractionLoop,
    Ip2_FrictMat_FrictMat_FrictPhys,
    Law2_ScGeom_FrictPhys_CundallStrack,
    NewtonIntegrator,
)

SCENE_FORMAT = "granular-material/yade-scene"
SCENE_VERSION = 1


def read_job() -> dict:
    """The job given as the first script argument (a JSON file)."""
    if len(sys.argv) < 2:
        raise SystemExit("usage: yade -n -x <script.py> <job.json>")
    with open(sys.argv[1]) as fh:
        return json.load(fh)


def write_json(path: str, data: dict) -> None:
    """Write ``data`` as JSON; floats are written with repr, so doubles round-trip exactly."""
    with open(path + ".part", "w") as fh:
        json.dump(data, fh)
    os.replace(path + ".part", path)


def read_scene(path: str) -> dict:
    """Read and check a scene file written by our exporter."""
    with open(path) as fh:
        scene = json.load(fh)
    if scene.get("format") != SCENE_FORMAT:
        raise ValueError(f"{path}: format is {scene.get('format')!r}, not {SCENE_FORMAT!r}")
    return scene


def materials_for(scene: dict) -> list:
    """One FrictMat per body (constant law) or one shared FrictMat (frictmat law).

    Ip2_FrictMat_FrictMat_FrictPhys gives kn = 2·Ea·Ra·Eb·Rb/(Ea·Ra + Eb·Rb) and
    ks = kn·(ks/kn) for equal Poisson numbers; with Ei = kn/Ri every pair gets exactly kn.
    """
    stiffness = scene["stiffness"]
    phi = scene["friction_angle"]
    density = scene.get("material_density") or scene["density"]
    radius = scene["radius"]
    if stiffness["law"] == "frictmat":
        mat = FrictMat(young=stiffness["young"], poisson=stiffness["kt_over_kn"],
                       frictionAngle=phi, density=density)
        O.materials.append(mat)
        return [mat] * len(radius)
    if stiffness["law"] == "constant":
        kn, kt = stiffness["kn"], stiffness["kt"]
        mats = [FrictMat(young=kn / r, poisson=kt / kn, frictionAngle=phi, density=density)
                for r in radius]
        for mat in mats:
            O.materials.append(mat)
        return mats
    raise ValueError(f"stiffness.law must be 'frictmat' or 'constant', got {stiffness['law']!r}")


def set_disc_inertia(body, density: float, thickness: float) -> None:
    """Mass and inertia of a disc of thickness t; only z rotation and x, y motion are free."""
    r = body.shape.radius
    body.state.blockedDOFs = "zXY"
    body.state.mass = density * thickness * math.pi * r**2
    inertia = 0.5 * body.state.mass * r**2
    body.state.inertia = Vector3(0.5 * inertia, 0.5 * inertia, inertia)


def standard_engines(controller=None, damping: float = 0.1) -> list:
    """Collider, Cundall-Strack contact loop, optional cell controller, Newton integrator."""
    engines = [
        ForceResetter(),
        InsertionSortCollider([Bo1_Sphere_Aabb()]),
        InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [Ip2_FrictMat_FrictMat_FrictPhys()],
                        [Law2_ScGeom_FrictPhys_CundallStrack()]),
    ]
    if controller is not None:
        engines.append(controller)
    engines.append(NewtonIntegrator(damping=damping, label="newton"))
    return engines


def build_scene(scene: dict, controller=None) -> None:
    """Build the periodic disc scene of ``scene`` in a fresh ``O``; sets ``O.dt``."""
    O.reset()
    O.periodic = True
    t = scene["thickness"]
    h = scene["cell"]
    O.cell.hSize = Matrix3(h[0][0], h[0][1], 0, h[1][0], h[1][1], 0, 0, 0, t)
    O.cell.trsf = Matrix3.Identity
    O.cell.velGrad = Matrix3.Zero
    mats = materials_for(scene)
    bodies = []
    for i, r in enumerate(scene["radius"]):
        x, y = scene["position"][i]
        b = utils.sphere(Vector3(x, y, 0.5 * t), r, material=mats[i], color=(0.5, 0.5, 0.5))
        set_disc_inertia(b, scene["density"], t)
        vx, vy = scene["velocity"][i]
        b.state.vel = Vector3(vx, vy, 0)
        b.state.angVel = Vector3(0, 0, scene["angular_velocity"][i])
        bodies.append(b)
    O.bodies.append(bodies)
    O.engines = standard_engines(controller, scene["damping"])
    O.dt = scene["timestep"] if scene.get("timestep") else utils.PWaveTimeStep()


def advance(steps: int) -> None:
    """Run ``steps`` time steps synchronously (``O.run(n, True)`` polls with a sleep)."""
    for _ in range(steps):
        O.step()


def update_contacts() -> None:
    """Detect contacts and evaluate forces of the current state without integrating.

    Runs the force resetter, the collider and the interaction loop once, so the stress of
    the initial state can be read at iteration 0. The shear increment of this pass is the
    relative velocity times dt, zero for a packing at rest.
    """
    for engine in O.engines[:3]:
        engine()


def cell_2d():
    """The in-plane cell matrix H (columns = cell vectors) as nested lists [m]."""
    h = O.cell.hSize
    return [[h[0, 0], h[0, 1]], [h[1, 0], h[1, 1]]]


def void_ratio() -> float:
    """2D void ratio e = (A − Σπr²)/Σπr² of the current cell."""
    h = O.cell.hSize
    area = abs(h[0, 0] * h[1, 1] - h[0, 1] * h[1, 0])
    solid = sum(math.pi * b.shape.radius**2 for b in O.bodies)
    return (area - solid) / solid


def coordination() -> float:
    """Coordination number Z = 2C/N over real contacts."""
    n_contact = sum(1 for i in O.interactions if i.isReal)
    return 2.0 * n_contact / len(O.bodies)


def stress_2d():
    """In-plane Love stress (sxx, syy, sxy) [Pa], tension positive (sxy symmetrised)."""
    s = utils.getStress()
    return s[0, 0], s[1, 1], 0.5 * (s[0, 1] + s[1, 0])


def stress_and_tangent_2d():
    """YADE's getStressAndTangent: (sxx, syy, sxy) [Pa] and the Voigt (xx, yy, xy) 3×3 tangent.

    The tangent is Kruyt & Rothenburg's S_ijkl = (1/V) Σ (kn n_i l_j n_k l_l + kt t_i l_j t_k l_l)
    in YADE's Voigt order (xx, yy, zz, yz, xz, xy), of which rows/columns 0, 1, 5 are kept [Pa].
    """
    s, t = utils.getStressAndTangent(symmetry=True)
    idx = (0, 1, 5)
    voigt = [[t[a, b] for b in idx] for a in idx]
    return (s[0, 0], s[1, 1], 0.5 * (s[0, 1] + s[1, 0])), voigt


def scene_from_simulation(template: dict, velocity_gradient=None) -> dict:
    """The current simulation as a scene dict (same format as the input scene).

    Positions are YADE's own (not wrapped into the cell); velocities are YADE's total
    velocities, and ``velocity_gradient`` is the L the cell moved with in the last step (a
    velGrad set since then is only YADE's ``nextVelGrad``), so the fluctuation is v − L·x.
    Pass ``velocity_gradient`` to state the L of a packing put at rest by hand.
    """
    out = {k: v for k, v in template.items() if k not in (
        "radius", "position", "velocity", "angular_velocity", "cell")}
    out["format"] = SCENE_FORMAT
    out["version"] = SCENE_VERSION
    out["cell"] = cell_2d()
    if velocity_gradient is None:
        lg = O.cell.velGrad
        velocity_gradient = [[lg[0, 0], lg[0, 1]], [lg[1, 0], lg[1, 1]]]
    out["velocity_gradient"] = velocity_gradient
    out["timestep"] = O.dt
    out["radius"] = [b.shape.radius for b in O.bodies]
    out["position"] = [[b.state.pos[0], b.state.pos[1]] for b in O.bodies]
    out["velocity"] = [[b.state.vel[0], b.state.vel[1]] for b in O.bodies]
    out["angular_velocity"] = [b.state.angVel[2] for b in O.bodies]
    return out


class Stopwatch:
    """Wall-clock seconds of a code block (``with Stopwatch() as sw: ...; sw.seconds``)."""

    def __enter__(self):
        self.start = time.perf_counter()
        self.seconds = 0.0
        return self

    def __exit__(self, *exc):
        self.seconds = time.perf_counter() - self.start
        return False
