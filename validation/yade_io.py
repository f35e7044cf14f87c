"""Exporter and importer between our RVE file (docs/design.md#rve-file) and a YADE scene file.

The scene file is a JSON object read by ``yade_scripts/scene_io.py`` inside YADE (Debian's
python3, no numpy needed). JSON floats are written with ``repr`` and parsed back to the same
double, so the exchange is exact. Keys:

- ``format`` = ``"granular-material/yade-scene"``, ``version`` = 1;
- ``thickness`` [m], ``density`` [kg/m³], ``friction_angle`` [rad], ``damping`` [-],
  ``stiffness`` (as ``RVEMeta.stiffness``), ``seed``, ``timestep`` [s] or null (then YADE
  uses ``PWaveTimeStep()`` with material density ``density``);
- ``cell`` 2×2 [m] (columns = cell vectors), ``radius`` (N,) [m], ``position`` (N, 2) [m],
  ``velocity`` (N, 2) [m/s], ``angular_velocity`` (N,) [rad/s];
- written by YADE only: ``velocity_gradient`` 2×2 [1/s], the cell's L; YADE velocities are
  total velocities, our file holds the fluctuation v − L·x.

In YADE a disc is a sphere with blocked z, X and Y DOFs, mass ρ·t·π·r², inertia ½·m·r², in
a cell of z size t; the ``frictmat`` law is one FrictMat (young = E, poisson = kt/kn); the
``constant`` law is one FrictMat per disc with young = kn/r, which YADE's
Ip2_FrictMat_FrictMat_FrictPhys turns into exactly kn and kt for every pair.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from granular_material.dem.rve.checks import validate_rve
from granular_material.dem.rve.file import RVEData, RVEMeta, load_rve, save_rve

__all__ = [
    "SCENE_FORMAT",
    "export_rve",
    "import_scene",
    "rve_to_scene",
    "scene_to_rve",
    "wrap_into_cell",
]

SCENE_FORMAT = "granular-material/yade-scene"
SCENE_VERSION = 1


def _floats(a: np.ndarray) -> Any:
    """Nested lists of Python floats (exact under JSON's repr)."""
    return np.asarray(a, dtype=np.float64).tolist()


def rve_to_scene(data: RVEData, index: int = 0) -> dict[str, Any]:
    """The scene dict of RVE ``index`` of ``data`` (contact history is not carried over)."""
    if not -data.n_rve <= index < data.n_rve:
        raise ValueError(f"index {index} is out of range for a batch of {data.n_rve} RVE(s)")
    meta = data.meta
    return {
        "format": SCENE_FORMAT,
        "version": SCENE_VERSION,
        "thickness": float(meta.thickness),
        "density": float(meta.density),
        "friction_angle": float(meta.friction_angle),
        "damping": float(meta.damping),
        "stiffness": dict(meta.stiffness),
        "seed": meta.seed,
        "timestep": meta.timestep,
        "cell": _floats(data.cell[index]),
        "radius": _floats(data.radius[index]),
        "position": _floats(data.position[index]),
        "velocity": _floats(data.velocity[index]),
        "angular_velocity": _floats(data.angular_velocity[index]),
    }


def export_rve(rve: str | Path | RVEData, out: str | Path, index: int = 0) -> Path:
    """Write RVE ``index`` of an RVE file (or data) as a YADE scene file ``out`` (.json)."""
    data = load_rve(rve) if isinstance(rve, (str, Path)) else rve
    out = Path(out)
    scene = rve_to_scene(data, index)
    tmp = out.with_name(out.name + ".part")
    tmp.write_text(json.dumps(scene))
    tmp.replace(out)
    return out


def wrap_into_cell(position: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """Map positions (N, 2) [m] into the cell ``cell`` (2, 2) (columns = cell vectors).

    Discs already inside (fractional coordinates in [0, 1)) are returned bit for bit; only
    the others are shifted by whole cell vectors.
    """
    position = np.array(position, dtype=np.float64)
    frac = np.linalg.solve(cell, position.T).T
    shift = np.floor(frac)
    outside = (shift != 0).any(axis=1)
    if outside.any():
        position[outside] -= shift[outside] @ cell.T
    return position


def scene_to_rve(scene: dict[str, Any]) -> RVEData:
    """A batch of one RVE from a scene dict (ours or written by YADE).

    YADE's unwrapped positions are wrapped into the cell, its total velocities are reduced
    to the fluctuation v − L·x about the cell's affine field, and its time step becomes
    ``meta.timestep`` so our engine runs with exactly YADE's dt.
    """
    if scene.get("format") != SCENE_FORMAT:
        raise ValueError(f"scene format must be {SCENE_FORMAT!r}, got {scene.get('format')!r}")
    if scene.get("version", SCENE_VERSION) > SCENE_VERSION:
        raise ValueError(f"scene version {scene['version']} is newer than {SCENE_VERSION}")
    cell = np.asarray(scene["cell"], dtype=np.float64)
    radius = np.asarray(scene["radius"], dtype=np.float64)
    position = np.asarray(scene["position"], dtype=np.float64)
    velocity = np.asarray(scene["velocity"], dtype=np.float64)
    omega = np.asarray(scene["angular_velocity"], dtype=np.float64)
    n = radius.shape[0]
    for name, arr, shape in (("cell", cell, (2, 2)), ("position", position, (n, 2)),
                             ("velocity", velocity, (n, 2)), ("angular_velocity", omega, (n,))):
        if arr.shape != shape:
            raise ValueError(f"scene {name} must have shape {shape}, got {arr.shape}")
    grad = scene.get("velocity_gradient")
    if grad is not None:
        lg = np.asarray(grad, dtype=np.float64)
        if lg.any():
            velocity = velocity - position @ lg.T
    position = wrap_into_cell(position, cell)
    timestep = scene.get("timestep")
    meta = RVEMeta(
        thickness=float(scene["thickness"]),
        density=float(scene["density"]),
        friction_angle=float(scene["friction_angle"]),
        damping=float(scene["damping"]),
        stiffness=dict(scene["stiffness"]),
        seed=scene.get("seed"),
        timestep=None if timestep is None else float(timestep),
    )
    data = RVEData(radius=radius[None], position=position[None], cell=cell[None],
                   velocity=velocity[None], angular_velocity=omega[None], meta=meta)
    validate_rve(data)
    return data


def import_scene(scene_path: str | Path, out: str | Path | None = None) -> RVEData:
    """Read a scene file (e.g. written by YADE) as RVE data; write it as an RVE file to ``out``.

    A ``frictmat`` scene keeps ``{"law": "frictmat", "young": E, "kt_over_kn": ratio}``.
    """
    scene = json.loads(Path(scene_path).read_text())
    data = scene_to_rve(scene)
    if out is not None:
        save_rve(out, data)
    return data

