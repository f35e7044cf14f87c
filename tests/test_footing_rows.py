"""The footing rows' measures (issue 49) on a made-up footing whose answer is known, and
the scene variants a preset makes."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from granular_material.studies.band import command_settings
from granular_material.studies.footing_rows import (
    FOOTING_BUDGETS,
    MECHANISM_FRACTION,
    footing_measures,
    footing_rows,
    half_width,
    keeps_footing,
    preset_footing_row,
)

B_HALF = 0.05


def _footing(settlements: np.ndarray, pressures: np.ndarray) -> tuple[pd.DataFrame,
                                                                      pd.DataFrame]:
    steps = pd.DataFrame({"step": np.arange(len(settlements)),
                          "footing_settlement": settlements,
                          "footing_force_y": -pressures * B_HALF})
    x, y = np.meshgrid(np.linspace(0.01, 0.59, 30), np.linspace(0.01, 0.39, 20))
    x, y = x.ravel(), y.ravel()
    tables = []
    for step in steps["step"]:
        # shear strain concentrated in a wedge under the footing: 0.12 m wide, 0.08 m deep
        gamma = np.where((x < 0.12) & (y > 0.4 - 0.08), 0.1, 0.001) * step
        tables.append(pd.DataFrame({"step": step, "x": x, "y": y, "shear_strain": gamma}))
    return steps, pd.concat(tables, ignore_index=True)


def test_the_bearing_pressures_and_the_mechanism_are_read_where_they_are():
    s = np.linspace(0.0, 0.0145, 59)
    q = 200e3 * np.minimum(s / 0.004, 1.0) - 2e6 * np.maximum(s - 0.008, 0.0)
    steps, points = _footing(s, q)
    measures = footing_measures(steps, points, B_HALF)
    assert measures["q_0.05"] == pytest.approx(200.0)  # at 5 mm, before the softening
    assert measures["q_0.1"] == pytest.approx((200e3 - 2e6 * 0.002) / 1e3)
    assert measures["q_peak"] == pytest.approx(200.0)
    assert 4.0 <= measures["s_peak_mm"] <= 8.0
    # the wedge reaches x < 0.12 m and 0.08 m down: in B = 0.1 m, up to one grid spacing
    assert 1.0 <= measures["mechanism_reach_B"] <= 1.2
    assert 0.6 <= measures["mechanism_depth_B"] <= 0.8
    assert 0 < MECHANISM_FRACTION < 1


def test_a_footing_that_stopped_short_has_no_pressure_at_s_over_b_0_1():
    s = np.linspace(0.0, 0.006, 25)
    steps, points = _footing(s, 1e5 * np.ones_like(s))
    measures = footing_measures(steps, points, B_HALF)
    assert measures["q_0.05"] == pytest.approx(100.0)
    assert math.isnan(measures["q_0.1"]) and math.isnan(measures["mechanism_depth_B"])


def test_a_preset_changes_the_scene_only_where_it_differs_from_the_commands():
    assert half_width() == pytest.approx(0.05)
    assert preset_footing_row("engineering", command_settings()) is None
    faster = {**command_settings(), "drive": "continue", "strain_per_step": 3e-5}
    row = preset_footing_row("engineering", faster)
    assert row.parameters == {"drive": "continue", "max_strain_per_step": 3e-5}
    assert row.newton == {}
    # two presets of the same changes share their run
    assert preset_footing_row("quick", faster).key == row.key
    force = {**command_settings(), "convergence": "force", "rtol": 1e-3, "stress_floor": 0.02}
    row = preset_footing_row("quick", force)
    assert row.newton["convergence"] == "force" and row.newton["max_iterations"] == 25
    assert row.newton["stress_tol"] == pytest.approx(0.02 * 20e3)  # of the surcharge
    assert {"reference", "seed", "material"} <= {r.knob for r in footing_rows()}


def test_keeps_footing_reads_both_pressures_and_the_run_s_end():
    budget = FOOTING_BUDGETS["engineering"]
    line = pd.Series({"q_0.05_pct": 5.0, "q_0.1_pct": -12.0, "error": ""})
    assert keeps_footing(line, budget)
    assert not keeps_footing(line.copy().replace(-12.0, -28.0), budget)
    assert not keeps_footing(pd.Series({**line, "error": "stopped at step 20"}), budget)


def test_an_interrupted_row_is_not_done_and_continues_where_it_stopped(tmp_path, monkeypatch):
    from test_bvp_resume import _stop_at

    from granular_material.runs.run_folder import ended_summary, resumable
    from granular_material.studies.footing_rows import (
        FOOTING_SCALES,
        FootingRow,
        footing_table,
        run_footing_rows,
    )

    rows = [FootingRow("reference", "scene")]
    folder = tmp_path / "footing" / rows[0].key
    with monkeypatch.context() as m:
        _stop_at(m, 2)
        run_footing_rows(rows, FOOTING_SCALES["smoke"], tmp_path)
    assert (folder / "summary.json").is_file() and ended_summary(folder) is None
    assert resumable(folder) and footing_table(rows, tmp_path, B_HALF).empty
    run_footing_rows(rows, FOOTING_SCALES["smoke"], tmp_path)
    summary = ended_summary(folder)
    assert summary is not None and summary["error"] is None and summary["steps"] == 3
    assert summary["resumed_from_step"] is not None
    assert list(footing_table(rows, tmp_path, B_HALF)["steps"]) == [3]


def test_the_adaptivity_row_runs_the_scene_with_its_table(tmp_path):
    from granular_material.studies.footing_rows import (
        FOOTING_SCALES,
        _scene_of,
        footing_table,
        run_footing_rows,
    )

    row = next(r for r in footing_rows() if r.knob == "adaptivity")
    assert "adaptivity" in _scene_of(row, FOOTING_SCALES["smoke"])
    assert "adaptivity" not in _scene_of(footing_rows()[0], FOOTING_SCALES["smoke"])
    run_footing_rows([row], FOOTING_SCALES["smoke"], tmp_path)
    steps = pd.read_csv(tmp_path / "footing" / row.key / "steps.csv")
    # every point starts on the twin: the first steps do not cost the whole mesh's DEM work
    assert steps["dem_points"].iloc[0] == 0 and "switch_particle_steps" in steps
    table = footing_table([row], tmp_path, B_HALF)
    assert list(table["steps"]) == [3] and table["particle_steps"].iloc[0] >= 0
