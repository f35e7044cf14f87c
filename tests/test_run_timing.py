"""Where a run's time goes (issue 25, part 3): the timing table by phase, and checkpoints of
the committed state by elapsed time."""

from __future__ import annotations

import json

import pytest

from granular_material.cli import main
from granular_material.runs import RunCheckpoint
from granular_material.runs import checkpoint as checkpoint_module
from granular_material.timing import RUN_PHASES, PhaseTimes, phase_table


def test_phase_times_add_up_and_count_a_block_that_raises():
    times = PhaseTimes({"dem": 1.0})
    times.add("dem", 0.5)
    times.add_all({"assembly": 2.0, "dem": 0.25})
    with pytest.raises(RuntimeError), times.phase("tables"):
        raise RuntimeError("stop")
    assert times.as_dict()["dem"] == 1.75 and times.as_dict()["assembly"] == 2.0
    assert times.as_dict()["tables"] >= 0.0


def test_the_phase_table_splits_the_wholes_into_parts_that_sum_to_the_run():
    raw = {"preparation": 3.0, "material": 10.0, "dem": 7.0, "homogenization": 1.0,
           "tangent": 0.5, "assembly": 2.0, "linear_solve": 1.0, "steps": 14.0,
           "tables": 0.5, "checkpoint": 1.5}
    table = phase_table(raw, total=19.0)
    assert table["material_other"] == pytest.approx(1.5)  # 10 − 7 − 1 − 0.5
    assert table["newton_other"] == pytest.approx(1.0)  # 14 − (10 + 2 + 1)
    assert table["other"] == pytest.approx(0.0)
    parts = sum(v for k, v in table.items() if k != "total")
    assert parts == pytest.approx(table["total"]) and table["total"] == 19.0
    assert set(table) <= {*RUN_PHASES, "other", "total"}
    # time the phases do not account for is the rest
    assert phase_table(raw, total=28.0)["other"] == pytest.approx(9.0)
    # a phase entered is listed however short; one never entered is not
    short = phase_table({**raw, "linear_solve": 2e-5}, total=19.0)
    assert short["linear_solve"] == 2e-5 and "reference" not in short


def test_a_dem_run_reports_its_time_by_phase(tmp_path, capsys):
    out = tmp_path / "se"
    assert main(["single-element", "--material", "dem", "--particles", "36", "--steps", "2",
                 "--axial-strain", "0.002", "--device", "cpu", "--no-progress", "--json",
                 "--out", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out)
    timing = summary["timing_s"]
    for phase in ("preparation", "initial_state", "dem", "homogenization", "assembly",
                  "linear_solve", "tables", "checkpoint", "outputs"):
        assert timing[phase] > 0, phase
    assert "reference" not in timing  # no pure-DEM curve was asked for (--compare-dem)
    parts = sum(v for k, v in timing.items() if k != "total")
    assert parts == pytest.approx(timing["total"], abs=0.01)
    assert timing["total"] >= summary["wall_time_s"]
    assert json.loads((out / "summary.json").read_text())["timing_s"] == timing


class _Clock:
    """A stand-in for time.monotonic that the test moves by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_by_elapsed_time_the_state_is_saved_when_saving_is_cheap_or_overdue(
        tmp_path, monkeypatch):
    clock = _Clock()
    monkeypatch.setattr(checkpoint_module.time, "monotonic", clock)
    checkpoint = RunCheckpoint(tmp_path, every=None, minutes=2.0)
    assert checkpoint.due(0, 50)  # nothing saved yet
    checkpoint._saved_at, checkpoint._save_seconds = clock.now, 5.0  # a save of 5 s
    clock.now += 49.0
    assert not checkpoint.due(3, 50)  # under 10 × 5 s since it
    clock.now += 1.0
    assert checkpoint.due(4, 50)
    assert checkpoint.due(50, 50)  # the last step always
    checkpoint._save_seconds = 30.0  # 10 × 30 s is longer than the 2 min cap
    clock.now = checkpoint._saved_at + 119.0
    assert not checkpoint.due(5, 50)
    clock.now += 1.0
    assert checkpoint.due(5, 50)
    checkpoint._save_seconds = 0.003  # a cheap save: at most once a second
    clock.now = checkpoint._saved_at + 0.99
    assert not checkpoint.due(6, 50)
    clock.now += 0.01
    assert checkpoint.due(6, 50)
    with pytest.raises(ValueError, match="minutes"):
        RunCheckpoint(tmp_path, every=None, minutes=0.0)


def test_every_n_steps_still_counts_steps(tmp_path):
    checkpoint = RunCheckpoint(tmp_path, every=3)
    assert [s for s in range(8) if checkpoint.due(s, 7)] == [0, 3, 6, 7]
