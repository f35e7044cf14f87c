"""The trade study (issue 13) at smoke size: every knob value gets a measured row, errors
shrink as the strain per DEM step shrinks, the presets are chosen by the stated rule and
measured, and a restarted study redoes nothing."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from granular_material.cli import main
from granular_material.results.compare import curve_errors, mean_curve
from granular_material.results.trade_plots import pareto_front
from granular_material.runs.presets import Preset
from granular_material.studies import SCALES, plan_runs
from granular_material.studies.band import BAND_SCALES, band_rows
from granular_material.studies.trade import PRESETS, accuracy, knobs, read_trade_table, recommend


def _curve(peak: float = 2.0, scale_ev: float = 1.0) -> pd.DataFrame:
    e = np.linspace(0.0, 0.05, 51)
    ratio = 1.0 + (peak - 1.0) * np.sin(np.pi * e / 0.06)
    return pd.DataFrame({"axial_strain": e, "stress_ratio": ratio,
                         "volumetric_strain": scale_ev * (-e + 10 * e ** 2),
                         "void_ratio": 0.2 + e})


def test_curve_errors_measure_what_they_say():
    ref = _curve()
    zero = curve_errors(ref, ref)
    assert all(v == 0 for v in zero.values())
    higher = curve_errors(_curve(peak=2.2), ref)
    assert higher["peak_error_pct"] == pytest.approx(10.0)
    assert 0 < higher["stress_ratio_rms_pct"] < 10.0
    assert higher["volumetric_strain_rms_pct"] == 0
    # a curve on other strains is compared on the reference's interpolant
    coarse = ref.iloc[::5].reset_index(drop=True)
    assert abs(curve_errors(coarse, ref)["stress_ratio_rms_pct"]) < 1e-12
    assert mean_curve([_curve(2.0), _curve(2.2)])["stress_ratio"].max() == pytest.approx(
        _curve(2.1)["stress_ratio"].max())


def test_pareto_front_keeps_the_undominated():
    cost = np.array([1.0, 2.0, 3.0, 4.0, 2.5])
    error = np.array([5.0, 3.0, 4.0, 1.0, 3.0])
    assert pareto_front(cost, error).tolist() == [0, 1, 3]


def test_plan_covers_every_knob_value_once():
    scale = SCALES["cpu"]
    rows = plan_runs(scale)
    assert {(r.knob, str(r.value)) for r in rows} == {
        (k.name, str(v)) for k in knobs(scale) for v in k.values}
    assert len(rows) == sum(len(k.values) for k in knobs(scale))
    for row in rows:  # one setting changed from the knob's reference
        changed = {k for k in row.settings if row.settings[k] != row.reference.get(k)}
        assert changed <= {row.knob}


def test_recommend_takes_the_cheapest_within_budget():
    scale = SCALES["smoke"]
    table = pd.DataFrame([
        {"knob": "strain_per_step", "value": "1e-05", "peak_error_pct": 0.0,
         "stress_ratio_rms_pct": 0.0, "wall_s": 10.0, "particle_steps": 100, "error": ""},
        {"knob": "strain_per_step", "value": "4e-05", "peak_error_pct": -2.5,
         "stress_ratio_rms_pct": 1.0, "wall_s": 3.0, "particle_steps": 40, "error": ""},
        {"knob": "strain_per_step", "value": "0.0001", "peak_error_pct": 8.0,
         "stress_ratio_rms_pct": 3.0, "wall_s": 1.0, "particle_steps": 10, "error": ""},
    ])
    chosen = recommend(table, scale)
    assert chosen["quick"]["strain_per_step"] == 1e-4
    assert chosen["engineering"]["strain_per_step"] == 4e-5
    assert chosen["publication"]["strain_per_step"] == 1e-5
    assert set(chosen) == set(PRESETS)


def test_recommend_counts_the_tangent_s_own_work():
    """A value with fewer particle-steps whose tangent costs more than the DEM it saves is
    not the cheaper one."""
    scale = SCALES["smoke"]
    rows = [("1e-05", 0.0, 100, 110.0), ("4e-05", 0.5, 80, 160.0)]
    table = pd.DataFrame([{"knob": "strain_per_step", "value": value, "test": "dem",
                           "peak_error_pct": error, "stress_ratio_rms_pct": 0.0,
                           "wall_s": 1.0, "particle_steps": steps, "cost_particle_steps": cost,
                           "error": ""} for value, error, steps, cost in rows])
    assert recommend(table, scale)["quick"]["strain_per_step"] == 1e-5
    cheaper = table.assign(cost_particle_steps=[110.0, 90.0])
    assert recommend(cheaper, scale)["quick"]["strain_per_step"] == 4e-5
    # a table of an older study, without the cost, is judged by its particle-steps
    assert recommend(table.drop(columns="cost_particle_steps"), scale)["quick"][
        "strain_per_step"] == 4e-5
    # a saving within what round-off alone moves the reference's cost is a tie: the
    # reference wins it
    keyed = cheaper.assign(run=["ref", "coarse"], reference_run="ref")
    noise = keyed.iloc[[0]].assign(knob="noise", value="1e-09", run="jiggled",
                                   cost_particle_steps=137.5)  # 25 % off the reference
    assert recommend(pd.concat([keyed, noise]), scale)["quick"]["strain_per_step"] == 1e-5
    noise = noise.assign(cost_particle_steps=112.2)  # 2 %: the 18 % saving is real
    assert recommend(pd.concat([keyed, noise]), scale)["quick"]["strain_per_step"] == 4e-5


def test_a_run_s_cost_adds_its_tangent_s_share_of_the_material_s_time():
    from granular_material.studies.trade import _dem_equivalent

    assert _dem_equivalent(1000, {"dem": 2.0, "homogenization": 0.5, "tangent": 1.5}) == 2000
    assert _dem_equivalent(1000, {}) == 1000  # nothing timed: the particle-steps


@pytest.fixture(scope="module")
def smoke_study(tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("trade") / "study"
    code = main(["trade-study", "--scale", "smoke", "--out", str(out), "--device", "cpu",
                 "--no-progress", "--json"])
    assert code == 0
    return out, json.loads((out / "presets.json").read_text())


def test_smoke_study_writes_every_row_figure_and_section(smoke_study):
    out, presets = smoke_study
    table = read_trade_table(out / "trade.csv")
    scale = SCALES["smoke"]
    for knob in knobs(scale):
        rows = table[(table["knob"] == knob.name) & (table["test"] == knob.test)]
        assert sorted(rows["value"]) == sorted(map(str, knob.values)), knob.name
        assert (out / f"knob_{knob.name}.png").stat().st_size > 1000
    rows_ok = table[table["error"] == ""]
    assert rows_ok["wall_s"].gt(0).all()
    assert rows_ok["particle_steps"].gt(0).all()
    assert (rows_ok["cost_particle_steps"] >= rows_ok["particle_steps"]).all()
    condensed = rows_ok[rows_ok["value"] == "condensed-hold"]
    assert (condensed["cost_particle_steps"] > condensed["particle_steps"]).all()
    reference = table[table["is_reference"] & ~table["knob"].isin(["discs", "preset"])]
    assert np.allclose(reference[["peak_error_pct", "stress_ratio_rms_pct"]], 0.0)
    dem = table[table["test"] == "dem"]
    assert dem["inertial_number"].gt(0).all() and dem["seed_scatter_pct"].notna().all()
    assert set(presets) == set(PRESETS)
    for name, values in presets.items():  # the record the commands read
        assert Preset(name=name, **values).tangent_update in ("none", "secant", "hold")
    assert len(table[table["knob"] == "preset"]) == 2 * len(PRESETS)
    report = (out / "report.md").read_text()
    for heading in ("## strain_per_step", "## mesh", "## preset", "## Recommended settings",
                    "## The shear band", "### convergence", "### What each preset keeps"):
        assert heading in report
    for figure in ("pareto.png", "band_pareto.png", "band_histories.png"):
        assert (out / figure).stat().st_size > 1000
    band = pd.read_csv(out / "band.csv")
    band_scale = BAND_SCALES["smoke"]
    expected = {(r.knob, r.value) for r in band_rows(band_scale)}
    assert expected <= set(zip(band["knob"], band["value"], strict=True))
    reference = band[band["knob"] == "reference"].iloc[0]
    assert reference["cost_ratio"] == 1.0 and reference["seeds"] == len(band_scale.seeds)
    assert band["particle_steps"].gt(0).all()
    # every preset with a band budget ran on the band specimen
    assert {"quick", "engineering"} <= set(band.loc[band["knob"] == "preset", "value"])
    footing = pd.read_csv(out / "footing.csv")
    assert {"reference", "seed", "convergence", "reuse_tol", "material"} <= set(
        footing["knob"])
    assert footing["q_peak"].gt(0).all() and "## The footing" in report
    assert (out / "footing_pareto.png").stat().st_size > 1000


def test_error_grows_with_the_strain_per_dem_step(smoke_study):
    """The quasi-static criterion: coarser DEM steps, larger error (physics, not a
    tolerance we chose)."""
    out, _ = smoke_study
    table = read_trade_table(out / "trade.csv")
    rows = table[table["knob"] == "strain_per_step"].copy()
    rows["step"] = rows["value"].astype(float)
    rows = rows.sort_values("step")
    assert np.all(np.diff(accuracy(rows).to_numpy()) > 0)
    assert np.all(np.diff(rows["inertial_number"].to_numpy()) > 0)


def test_restarted_study_runs_nothing_again(smoke_study, capsys):
    out, _ = smoke_study
    before = (out / "trade.csv").read_text()
    code = main(["trade-study", "--scale", "smoke", "--out", str(out), "--device", "cpu",
                 "--no-progress", "--json"])
    captured = capsys.readouterr()
    assert code == 0
    assert not re.search(r"^(dem|element|specimen)-[0-9a-f]{10}: ", captured.err, re.M)
    assert "band/runs/" not in captured.err  # no band run again either
    assert (out / "trade.csv").read_text() == before


# -- the presets the commands take -----------------------------------------------------------
def test_command_presets_are_the_committed_study_s():
    from granular_material.runs.presets import PRESETS_FILE

    committed = Path(__file__).parents[1] / "docs" / "trade-study" / "presets.json"
    assert json.loads(PRESETS_FILE.read_text()) == json.loads(committed.read_text())
    assert set(json.loads(committed.read_text())) == set(PRESETS)


def test_preset_sets_the_options_left_at_their_defaults(tmp_path, capsys):
    from granular_material.cli import build_parser
    from granular_material.cli.fem import spec_from_args
    from granular_material.runs.presets import load_presets

    quick = load_presets()["quick"]
    args = build_parser().parse_args(["single-element", "--preset", "quick",
                                      "--rtol", "0.02"])
    spec = spec_from_args(args)
    dem = spec.material.parameters
    assert spec.newton.rtol == 0.02  # given: kept
    assert spec.preset == "quick"
    assert dem.particles == quick.discs
    assert dem.max_strain_per_step == quick.strain_per_step
    assert dem.reuse_tol == quick.reuse_tol
    assert spec.newton.convergence == quick.convergence
    assert spec.material.parameters.drive == quick.drive
    if quick.stress_floor is None:  # the commands' own floor
        assert spec.newton.stress_tol is None
    else:
        assert spec.newton.stress_tol == pytest.approx(quick.stress_floor * args.confining)
    code = main(["single-element", "--material", "linear-elastic", "--preset", "quick",
                 "--steps", "2"])
    assert code == 2 and "--material dem" in capsys.readouterr().err


@pytest.mark.parametrize(("value", "settings"), [
    ("objective", {"tangent": "objective", "tangent_update": "none"}),
    ("secant", {"tangent": "objective", "tangent_update": "secant"}),
    ("condensed-hold", {"tangent": "condensed", "tangent_update": "hold"}),
])
def test_a_tangent_knob_value_names_the_tangent_and_its_update(value, settings):
    from granular_material.runs.presets import preset_fields
    from granular_material.studies.trade import tangent_settings

    assert tangent_settings(value) == settings
    for name in PRESETS:  # every committed preset names one of these updates
        fields = preset_fields(name, 100e3)
        assert fields["tangent_update"] in ("none", "secant", "hold")
