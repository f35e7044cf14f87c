"""The fields file of a run (``fields.xdmf``, its values in ``fields.h5``): what meshio's
time-series reader (ParaView's route too) reads back is what the run holds, the same steps
give the same bytes, and a writer killed outright leaves a pair that reads whole up to its
last written step."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import meshio
import numpy as np
import pandas as pd
import pytest

from granular_material.fem import BiaxialSetup, MohrCoulomb, build_biaxial
from granular_material.results import BiaxialWriter
from granular_material.results.writers import FieldWriter
from granular_material.runs import run_biaxial


def _read(path):
    with meshio.xdmf.TimeSeriesReader(str(path)) as reader:
        points, cells = reader.read_points_cells()
        return points, cells, [reader.read_data(k) for k in range(reader.num_steps)]


def _run(out, steps=4):
    material = MohrCoulomb(young=30e6, poisson=0.3, friction_angle=35.0,
                           critical_friction_angle=28.0, softening_strain=0.02,
                           dilation_angle=5.0, initial_stress=-100e3)
    with BiaxialWriter(out) as writer:
        return run_biaxial(BiaxialSetup(nx=2, ny=4, axial_strain=0.02), material, steps,
                           observer=writer)


def test_meshio_reads_back_the_values_the_run_holds(tmp_path):
    result = _run(tmp_path)
    assert (tmp_path / "fields.h5").is_file()
    assert 'Format="HDF"' in (tmp_path / "fields.xdmf").read_text()
    points, cells, steps = _read(tmp_path / "fields.xdmf")
    xy, connectivity, kind, dofs = result.problem.nodes()
    assert np.array_equal(points[:, :2], xy) and not points[:, 2].any()
    assert cells[0].type == kind and np.array_equal(cells[0].data, connectivity)
    assert len(steps) == len(result.steps)
    for (time_, point_data, cell_data), (_, row), u in zip(
            steps, result.steps.iterrows(), result.displacements, strict=True):
        assert time_ == row["axial_strain"]
        assert np.array_equal(point_data["displacement"][:, 0], u[dofs[0]])
        assert np.array_equal(point_data["displacement"][:, 1], u[dofs[1]])
        table = result.points[result.points["step"] == row["step"]]
        means = table.groupby("element").mean(numeric_only=True)
        for name in ("sxx", "syy", "plastic_shear_strain", "friction_angle"):
            assert np.array_equal(cell_data[name][0], means[name].to_numpy()), name


def test_the_same_steps_give_the_same_bytes(tmp_path):
    _run(tmp_path / "a")
    time.sleep(1.1)  # a file that stored times would differ now
    _run(tmp_path / "b")
    for name in ("fields.xdmf", "fields.h5"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def test_a_region_column_is_numbered_per_element(tmp_path):
    problem = build_biaxial(BiaxialSetup(nx=1, ny=2))
    table = pd.DataFrame({"element": np.repeat([0, 1], 4), "sxx": np.arange(8.0),
                          "region": np.repeat(["soft", "hard"], 4)})
    with FieldWriter(tmp_path / "fields.xdmf", problem) as fields:
        fields.write(0.5, np.zeros(problem.basis.N), table)
    _, _, [(time_, _, cell_data)] = _read(tmp_path / "fields.xdmf")
    assert time_ == 0.5
    assert cell_data["region"][0].tolist() == [1.0, 0.0]
    assert cell_data["sxx"][0].tolist() == [1.5, 5.5]


_WRITER = """
import sys
import numpy as np, pandas as pd
from granular_material.fem import BiaxialSetup, build_biaxial
from granular_material.results.writers import FieldWriter
problem = build_biaxial(BiaxialSetup(nx=8, ny=16))
table = pd.DataFrame({"element": np.arange(512) // 4, "sxx": np.ones(512)})
with FieldWriter(sys.argv[1] + "/fields.xdmf", problem) as fields:
    for step in range(100000):
        fields.write(float(step), np.full(problem.basis.N, float(step)), table.assign(sxx=-step))
        if step == 3:
            print("ready", flush=True)
"""


@pytest.mark.skipif(os.name != "posix", reason="SIGKILL")
def test_a_writer_killed_outright_leaves_fields_that_read_whole(tmp_path):
    process = subprocess.Popen([sys.executable, "-c", _WRITER, str(tmp_path)],
                               stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "ready"
    time.sleep(0.5)
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=30)
    process.stdout.close()
    _, _, steps = _read(tmp_path / "fields.xdmf")
    assert len(steps) >= 4
    for k, (time_, point_data, cell_data) in enumerate(steps):
        assert time_ == k and (point_data["displacement"][:, :2] == k).all()
        assert (cell_data["sxx"][0] == -k).all()


def test_a_biaxial_writer_without_steps_leaves_an_empty_series(tmp_path):
    problem = build_biaxial(BiaxialSetup(nx=1, ny=2))
    with FieldWriter(tmp_path / "fields.xdmf", problem):
        pass
    points, _, steps = _read(tmp_path / "fields.xdmf")
    assert len(points) == 6 and steps == []
