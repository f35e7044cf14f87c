"""The footing cost study (benchmarks/footing_cost.py) at smoke size, and its pieces."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "footing_cost.py"


@pytest.fixture(scope="module")
def study():
    spec = importlib.util.spec_from_file_location("footing_cost", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclass looks itself up there
    spec.loader.exec_module(module)
    return module


def test_variants_parse_into_tables(study):
    name, tables = study.parse_variant("reuse:newton.convergence=force,material.reuse_tol=1e-5")
    assert name == "reuse"
    assert tables == {"newton": {"convergence": "force"}, "material": {"reuse_tol": 1e-5}}
    assert study.parse_variant("scene:") == ("scene", {})
    with pytest.raises(SystemExit, match=r"output\.x"):
        study.parse_variant("bad:output.x=1")


def test_work_division_counts_the_busiest_rves_and_the_edge(study):
    steps = np.array([70, 10, 10, 10] + [0] * 16)
    xy = np.array([[0.05, 0.0]] + [[0.5, -0.3]] * 19)
    division = study.work_division(steps, xy, b=0.05)
    assert division["top_5%"] == pytest.approx(0.7)  # one RVE of 20
    assert division["within_1b"] == pytest.approx(0.7)
    assert division["rves_within_1b"] == pytest.approx(0.05)
    curve = pd.DataFrame({"settlement": [0.0, 0.01], "q": [0.0, 100.0]})
    assert study.q_at(curve, 0.005) == pytest.approx(50.0)
    assert study.q_at(curve, 0.02) is None


def test_the_study_runs_two_variants_with_their_work_counted(study, tmp_path):
    results = study.main(["--steps", "2", "--particles", "16", "--elements", "4", "3",
                          "--out", str(tmp_path), "--variant", "scene:",
                          "--variant", "reuse:newton.convergence=force,material.reuse_tol=1e-5"])
    assert [r["name"] for r in results] == ["scene", "reuse"]
    for r in results:
        assert r["error"] is None and r["steps_done"] == 2
        assert r["evaluations"] >= r["iterations"] >= 2
        assert r["particle_steps"] > 0
        assert sum(r["division"][k] for k in ("top_50%",)) <= 1.0
        assert np.load(tmp_path / r["name"] / "rve_steps.npy").shape == (4 * 3 * 2 * 3,)
    report = (tmp_path / "footing_cost.md").read_text()
    assert "| scene |" in report and "| reuse |" in report
    assert min(results[0]["curve"]["settlement"]) > 0  # down, as footing_settlement
    again = study.main(["--out", str(tmp_path), "--report-only"])
    assert [r["name"] for r in again] == ["scene", "reuse"]
