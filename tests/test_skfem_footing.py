"""The user's strip footing (examples/skfem_footing.py) runs end to end, at a small size."""

from __future__ import annotations

import re
import subprocess
import sys

import meshio
import numpy as np
import pytest
from granular_material_examples import skfem_footing as example


def _increments(result: example.Footing) -> np.ndarray:
    return np.diff(result.pressure)


def test_linear_elastic_footing_starts_in_equilibrium_and_is_linear():
    result = example.main("linear-elastic", steps=4, settlement=0.004, progress=False)
    # the geostatic start: no residual with no step taken, the footing carrying q
    assert result.initial_residual < 1e-6 * result.tolerance
    assert result.pressure[0] == pytest.approx(example.Q, rel=1e-9)
    assert result.settlement == pytest.approx([0.0, 0.001, 0.002, 0.003, 0.004], abs=1e-12)
    steps = _increments(result)
    assert steps.min() > 0
    assert np.ptp(steps) < 1e-6 * steps.mean()  # small strain: exactly linear
    assert result.cutbacks == [0] * 5


def test_mohr_coulomb_footing_levels_off_near_prandtl():
    result = example.main("mohr-coulomb", steps=10, settlement=0.02, progress=False)
    assert result.initial_residual < 1e-6 * result.tolerance
    p = np.asarray(result.pressure)
    # a plateau: the last two increments change the pressure by less than 5 %
    assert abs(p[-1] - p[-2]) < 0.05 * p[-2] and abs(p[-2] - p[-3]) < 0.05 * p[-3]
    # well past the elastic line: the first increment was over ten times the last
    assert p[1] - p[0] > 10 * (p[-1] - p[-2])
    # a coarse mesh's limit load lies above Prandtl's, and not far above
    assert 1.0 < p[-1] / example.prandtl() < 1.5


def test_plain_newton_loop_matches_the_solver_on_linear_elastic():
    solver = example.main("linear-elastic", steps=2, settlement=0.002, progress=False)
    plain = example.main("linear-elastic", steps=2, settlement=0.002, progress=False,
                         plain=True)
    assert plain.pressure == pytest.approx(solver.pressure, rel=1e-6)


def test_prandtl_bound_is_terzaghi_sum():
    # φ = 30°: N_q = 18.40, Meyerhof's N_γ = 15.67; q N_q + ½ γ (2b) N_γ
    assert example.prandtl(30.0) == pytest.approx(20e3 * 18.401 + 0.5 * 16e3 * 0.2 * 15.668,
                                                  rel=1e-3)


@pytest.mark.parametrize("material", ["linear-elastic", "mohr-coulomb"])
def test_command_line_writes_fields_and_curve(material, tmp_path):
    out = tmp_path / material
    run = subprocess.run([sys.executable, "-m", "granular_material_examples.skfem_footing",
                          material, "--steps", "2", "--settlement", "0.002",
                          "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "initial residual" in run.stdout and "step  2 settlement   2.00 mm" in run.stdout
    assert (out / "bearing.png").stat().st_size > 0
    with meshio.xdmf.TimeSeriesReader(str(out / "fields.xdmf")) as fields:
        points, cells = fields.read_points_cells()
        assert points.shape == (91, 3)  # tri6: corner and midside nodes of 6 x 3 x 2
        assert cells[0].type == "triangle6" and fields.num_steps == 3  # steps 0, 1, 2
        time, point_data, cell_data = fields.read_data(2)
    assert time == pytest.approx(0.002)  # the settlement [m]
    assert point_data["displacement"][:, 1].min() == pytest.approx(-0.002, rel=1e-9)
    assert {"sxx", "syy", "sxy", "shear_strain"} <= set(cell_data)
    if material == "mohr-coulomb":
        assert "Prandtl" in run.stdout


def test_dem_footing_at_its_smallest_size(tmp_path):
    out = tmp_path / "dem"
    run = subprocess.run([sys.executable, "-m", "granular_material_examples.skfem_footing",
                          "dem", "--steps", "2", "--settlement", "0.001", "--out", str(out)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    lines = [line for line in run.stdout.splitlines() if "bearing pressure" in line]
    pressures = [float(line.split("bearing pressure")[1].split()[0]) for line in lines]
    assert len(pressures) == 3
    # prepared to the geostatic state within the servo's 2 %: the footing starts near q
    assert pressures[0] == pytest.approx(example.Q / 1e3, rel=0.05)
    assert pressures[0] < pressures[1] < pressures[2]
    assert "void_ratio" in (out / "fields.xdmf").read_text()
    # the initial residual is the preparation's error: every RVE within 2 % of its σv (the
    # servo) plus half the share tolerance; the residual of a stress error of that size at
    # every point bounds it (the tolerance printed is that of 0.5 % of q)
    found = re.search(r"initial residual (\S+) N/m \(tolerance (\S+) N/m\)", run.stdout)
    residual, tolerance = float(found[1]), float(found[2])
    sigma_v = example.Q + example.GAMMA * example.DEPTH
    share = example.parameters("dem", None)["share_tolerance"]
    bound = (0.02 + share / 2) * sigma_v * tolerance / (5e-3 * example.Q)
    assert 0 < residual < bound
