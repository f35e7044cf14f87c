"""Smoke-size run of benchmarks/compare_commits.py (this working tree against itself)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "compare_commits.py"


def test_compare_commits_smoke(tmp_path):
    spec = importlib.util.spec_from_file_location("compare_commits", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = tmp_path / "compare.csv"
    table = module.main([".", ".", "--batches", "1,2", "--particles", "30", "--steps", "200",
                         "--repeats", "2", "--out", str(out)])
    assert out.exists()
    assert table["batch"].tolist() == [1, 1, 2, 2]
    assert (table["rate_cpu"] > 0).all() and (table["rate_wall"] > 0).all()
    first = table[table.index % 2 == 0]
    assert (first["ratio"] == 1.0).all()  # each repeat against itself
    second = table[table.index % 2 == 1]
    assert ((second["ratio_min"] <= second["ratio"])
            & (second["ratio"] <= second["ratio_max"])).all()
