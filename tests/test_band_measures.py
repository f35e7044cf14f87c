"""The band measures (issue 49) on made-up specimens whose answer is known, and the rule
that lets a preset take a Newton setting only where the band rows say it keeps the band."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from granular_material.results.band_measures import (
    ONSET_RATIO,
    band_measures,
    band_onset,
    localisation_history,
)
from granular_material.studies.band import BAND_SCALES, band_rows, command_settings
from granular_material.studies.band_scoring import BAND_BUDGETS, band_table, keeps_band
from granular_material.studies.plan import SCALES
from granular_material.studies.scoring import recommend

WIDTH, HEIGHT = 0.05, 0.10


def _specimen(onset: float | None, angle_deg: float = 55.0, steps: int = 20,
              final: float = 0.10) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A 10 × 20 grid of points sheared uniformly; from ``onset`` on, the points within 4 mm
    of a line through the centre at ``angle_deg`` take all further shear (None: uniform)."""
    x, y = np.meshgrid(np.linspace(0.0025, WIDTH - 0.0025, 10),
                       np.linspace(0.0025, HEIGHT - 0.0025, 20))
    x, y = x.ravel(), y.ravel()
    angle = math.radians(angle_deg)
    distance = np.abs(-(x - WIDTH / 2) * math.sin(angle) + (y - HEIGHT / 2) * math.cos(angle))
    in_band = distance < 0.004
    tables, rows = [], []
    for step in range(steps + 1):
        e = final * step / steps
        gamma = np.full(x.size, min(e, onset) if onset is not None else e)
        if onset is not None and e > onset:
            gamma = gamma + np.where(in_band, 5 * (e - onset), 0.0)
        tables.append(pd.DataFrame({"step": step, "axial_strain": e, "x": x, "y": y,
                                    "shear_strain": gamma}))
        rows.append({"step": step, "axial_strain": e, "stress_ratio": 1 + 20 * e - 80 * e * e,
                     "volumetric_strain": 0.3 * e})
    return pd.DataFrame(rows), pd.concat(tables, ignore_index=True)


def test_a_uniform_specimen_has_no_band():
    steps, points = _specimen(None)
    history = localisation_history(points)
    assert np.allclose(history["ratio"], 1.0)
    assert math.isnan(band_onset(history))
    measures = band_measures(steps, points, HEIGHT, WIDTH)
    assert math.isnan(measures["onset"])
    assert measures["ratio_10"] == pytest.approx(1.0)


def test_a_band_is_found_when_where_and_at_the_angle_it_forms():
    steps, points = _specimen(0.03, angle_deg=55.0)
    measures = band_measures(steps, points, HEIGHT, WIDTH)
    # γmax/γmean reaches 2 a little after 3 %: found between the two steps around it
    history = localisation_history(points)
    after = history[history["ratio"] >= ONSET_RATIO]["axial_strain"].iloc[0]
    assert 0.03 < measures["onset"] <= after
    assert measures["ratio_2"] == pytest.approx(1.0)
    assert measures["ratio_10"] > 3
    assert measures["inclination_deg"] == pytest.approx(55.0, abs=3.0)
    assert measures["crossing_x"] == pytest.approx(WIDTH / 2, abs=0.003)
    assert measures["stress_ratio_5"] == pytest.approx(1 + 20 * 0.05 - 80 * 0.05 ** 2)
    assert measures["volumetric_strain_10"] == pytest.approx(0.03)
    later = band_measures(*_specimen(0.06), HEIGHT, WIDTH)
    assert later["onset"] > measures["onset"] + 0.02


def test_measures_beyond_the_run_are_nan_not_extrapolated():
    steps, points = _specimen(0.01, final=0.04, steps=8)
    measures = band_measures(steps, points, HEIGHT, WIDTH)
    assert math.isnan(measures["ratio_5"]) and math.isnan(measures["stress_ratio_10"])
    assert measures["onset"] < 0.04


def _band_line(knob: str, value: str, delay: float = 0.0, ratio_error: float = 0.0,
               cost: float = 1.0, banded: str = "2/2") -> dict:
    return {"knob": knob, "value": value, "banded": banded, "onset_delay_pp": delay,
            "stress_ratio_10_pct": ratio_error, "cost_ratio": cost, "failed": 0,
            "particle_steps": 1e9 * cost, "particle_steps_scatter": 2e7}


def test_keeps_band_needs_every_seed_banded_in_time_and_the_softening():
    budget = BAND_BUDGETS["engineering"]
    assert keeps_band(pd.Series(_band_line("x", "y", 0.2, 2.0)), budget)
    assert not keeps_band(pd.Series(_band_line("x", "y", 0.2, 2.0, banded="1/2")), budget)
    assert not keeps_band(pd.Series(_band_line("x", "y", budget["onset_pp"] + 0.1)), budget)
    assert not keeps_band(pd.Series(_band_line("x", "y", 0.0, 6.0)), budget)


def test_a_preset_takes_a_newton_setting_only_where_it_keeps_the_band():
    scale = SCALES["smoke"]
    band = pd.DataFrame([
        _band_line("reference", "defaults"),
        # the force test: cheaper, but its band forms 1.2 points late
        _band_line("convergence", "force 1e-3 floor 0.02p0", delay=1.2, cost=0.4),
        # the plain displacement test keeps it, but costs more: not taken
        _band_line("convergence", "displacement 1e-2", delay=0.1, cost=1.3),
        # continuing the RVEs' drive keeps the band for 30 % less work: taken by both
        _band_line("drive", "continue", delay=0.3, cost=0.7),
        _band_line("strain_per_step", "3e-5", delay=0.8, cost=0.4),
        _band_line("strain_per_step", "1e-4", delay=3.0, cost=0.1, banded="0/2"),
    ])
    chosen = recommend(pd.DataFrame(columns=["knob", "value", "error"]), scale, band)
    defaults = command_settings()
    for name in ("quick", "engineering"):
        assert chosen[name]["drive"] == "continue"
        assert chosen[name]["tangent"] == defaults["tangent"]
    assert chosen["quick"]["convergence"] == defaults["convergence"]  # 1.2 > 1.0 pp
    assert chosen["engineering"]["convergence"] == defaults["convergence"]
    assert chosen["publication"]["drive"] == defaults["drive"]
    # the rows of the scale exist for every Newton knob the rule reads
    assert {r.knob for r in band_rows(BAND_SCALES["smoke"])} >= {
        "convergence", "relaxation", "tangent", "drive", "strain_per_step"}


def test_a_setting_that_breaks_the_footing_s_budget_is_not_taken():
    """Continuing the RVEs' drive keeps the band but moves the footing's pressure at
    s/B = 0.1 by 28 %: within quick's footing budget, not engineering's."""
    scale = SCALES["smoke"]
    band = pd.DataFrame([_band_line("reference", "defaults"),
                         _band_line("drive", "continue", delay=0.3, cost=0.3)])
    footing = pd.DataFrame([{"knob": "drive", "value": "continue", "q_0.05_pct": -6.5,
                             "q_0.1_pct": -28.4, "error": ""}])
    empty = pd.DataFrame(columns=["knob", "value", "error"])
    chosen = recommend(empty, scale, band, footing)
    assert chosen["quick"]["drive"] == "continue"
    assert chosen["engineering"]["drive"] == "restart"
    assert recommend(empty, scale, band)["engineering"]["drive"] == "continue"


def test_a_strain_per_step_that_breaks_the_band_is_replaced():
    scale = SCALES["smoke"]  # its pure-DEM knob offers 1e-5, 4e-5 and 1e-4
    table = pd.DataFrame([{"knob": "strain_per_step", "value": v, "test": "dem",
                           "peak_error_pct": e, "stress_ratio_rms_pct": 0.0, "wall_s": 1.0,
                           "particle_steps": c, "error": ""}
                          for v, e, c in (("1e-05", 0.0, 100), ("4e-05", 1.0, 30),
                                          ("0.0001", 2.0, 10))])
    assert recommend(table, scale)["quick"]["strain_per_step"] == 1e-4  # by the peak alone
    band = pd.DataFrame([_band_line("reference", "defaults"),
                         _band_line("strain_per_step", "4e-05", delay=0.3, cost=0.4),
                         _band_line("strain_per_step", "0.0001", delay=2.0, cost=0.1)])
    chosen = recommend(table, scale, band)
    assert chosen["quick"]["strain_per_step"] == 4e-5
    assert chosen["engineering"]["strain_per_step"] == 4e-5


def test_errors_are_taken_seed_by_seed_so_the_scatter_between_rves_drops_out():
    """Two sets of RVEs whose bands form 1.5 points apart; a knob that delays each by
    exactly 0.4 points is measured as 0.4 with no spread, its cost as its own ratio."""
    def run(knob: str, value: str, seed: int, onset: float, ratio: float, steps: float):
        return {"knob": knob, "value": value, "seed": seed, "onset": onset,
                "final_strain": 0.1, "ratio_2": 1.0, "ratio_3": 2.0, "ratio_5": 2.5,
                "ratio_10": 2.6, "inclination_deg": 50.0, "elongation": 0.9,
                "crossing_x": 0.02, "stress_ratio_5": ratio, "stress_ratio_10": ratio,
                "volumetric_strain_5": 0.02, "volumetric_strain_10": 0.03,
                "particle_steps": steps, "iterations": 300, "wall_s": 100.0, "error": ""}
    runs = pd.DataFrame([run("reference", "defaults", 1, 0.020, 2.0, 1e9),
                         run("reference", "defaults", 2, 0.035, 2.4, 2e9),
                         run("drive", "continue", 1, 0.024, 2.1, 3e8),
                         run("drive", "continue", 2, 0.039, 2.52, 6e8),
                         run("mesh", "3x6", 1, math.nan, 2.0, 5e8)])
    table = band_table(runs, BAND_SCALES["cpu"]).set_index(["knob", "value"])
    drive = table.loc[("drive", "continue")]
    assert drive["onset_delay_pp"] == pytest.approx(0.4)
    assert drive["onset_delay_spread_pp"] == pytest.approx(0.0, abs=1e-9)
    assert drive["stress_ratio_10_pct"] == pytest.approx(5.0)
    assert drive["cost_ratio"] == pytest.approx(0.3)
    reference = table.loc[("reference", "defaults")]
    assert reference["onset_scatter_pp"] == pytest.approx(100 * 0.015 / math.sqrt(2))
    # a run without a band counts at its last strain and is not banded
    mesh = table.loc[("mesh", "3x6")]
    assert mesh["banded"] == "0/1" and mesh["onset_delay_pp"] == pytest.approx(8.0)
