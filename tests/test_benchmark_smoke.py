"""Smoke-size run of the throughput benchmark (the full one is `tox -e bench`)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "dem_throughput.py"


def test_throughput_benchmark_smoke(tmp_path):
    spec = importlib.util.spec_from_file_location("dem_throughput", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = tmp_path / "throughput.csv"
    table = module.main(["--device", "cpu", "--batches", "1,3", "--particles", "30",
                         "--seconds", "0.05", "--repeats", "2", "--no-yade", "--out", str(out)])
    assert out.exists()
    assert table["batch"].tolist() == [1, 3]
    assert (table["particle_steps_per_s"] > 0).all()
    assert (table["steps"] >= 20).all()


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
