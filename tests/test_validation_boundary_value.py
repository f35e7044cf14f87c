"""The closed-form bounds of the boundary-value report (Prandtl, Rankine), against the values
DESIGN.md §5 quotes."""

from __future__ import annotations

import pytest
from granular_material_validation.boundary_value import bearing_factor, rankine


@pytest.mark.parametrize("phi, n_q", [(29.0, 16.4), (30.0, 18.4), (35.0, 33.3)])
def test_prandtl_bearing_factor(phi, n_q):
    assert bearing_factor(phi) == pytest.approx(n_q, abs=0.05)


def test_rankine_coefficients():
    k_p, k_a = rankine(30.0)
    assert k_p == pytest.approx(3.0)
    assert k_a == pytest.approx(1 / 3)
    assert rankine(0.0) == pytest.approx((1.0, 1.0))


def test_a_run_records_its_load_continues_when_stopped_and_is_reused(tmp_path, monkeypatch):
    import json

    from granular_material_validation import boundary_value as report
    from test_bvp_resume import _stop_at
    from test_bvp_scene_bounds import SCENE

    scene = {**SCENE, "steps": 3}
    folder = tmp_path / "run"
    with monkeypatch.context() as m:
        _stop_at(m, 2)
        assert report._run(scene, folder)["error"].startswith("interrupted after load step 1")
    summary = report._run(scene, folder)  # continued from its checkpoint, not refused
    assert summary["steps"] == 3 and summary["error"] is None
    host = json.loads((folder / "host.json").read_text())
    assert host["cores"] >= 1 and host["load_max"] >= host["load_median"] >= 0
    assert report._load(folder) != "–" and report._load(tmp_path) == "–"
    (folder / "steps.csv").unlink()  # a reused run is read from its summary, not rerun
    assert report._run(scene, folder) == summary
