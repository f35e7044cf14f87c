"""Tables at a cost linear in the steps (issue 62): the rows a step appends are formatted
as pandas formats them, byte for byte, the fields file's text is numpy.savetxt's, and a run's
tables are not written again, whole, at its end when the appended ones are already whole."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from granular_material.results import writers
from granular_material.results.writers import BiaxialWriter, format_rows

_FLOATS = st.floats(allow_nan=True, allow_infinity=True, width=64)
_TEXTS = st.one_of(st.text(alphabet=st.sampled_from('ab ,"\'\n\r[]1.5e-'), max_size=8),
                   st.sampled_from(["", "[]", "[1.0, 0.5]", "force+energy"]))


@settings(max_examples=200, deadline=None)
@given(rows=st.integers(1, 6), data=st.data())
def test_rows_are_formatted_as_pandas_formats_them(rows, data):
    kinds = data.draw(st.lists(st.sampled_from(["f", "i", "b", "c", "s"]), min_size=1,
                               max_size=5))
    columns = {}
    for k, kind in enumerate(kinds):
        if kind == "f":
            values = data.draw(st.lists(_FLOATS, min_size=rows, max_size=rows))
        elif kind == "c":  # one value repeated: formatted once
            values = [data.draw(_FLOATS)] * rows
        elif kind == "i":
            values = data.draw(st.lists(st.integers(-2**63, 2**63 - 1), min_size=rows,
                                        max_size=rows))
        elif kind == "s":  # text, as the histories of steps.csv (quoted where need be)
            values = data.draw(st.lists(_TEXTS, min_size=rows, max_size=rows))
        else:
            values = data.draw(st.lists(st.booleans(), min_size=rows, max_size=rows))
        columns[f"c{k}"] = np.array(values, dtype={"f": float, "c": float, "i": np.int64,
                                                    "b": bool, "s": object}[kind])
    frame = pd.DataFrame(columns)
    assert format_rows(frame) == frame.to_csv(index=False, header=False)
    # a second time (every column remembered, as from one step to the next) alike
    assert format_rows(frame) == frame.to_csv(index=False, header=False)
    # the columns in another order (a table's header's)
    order = list(range(frame.shape[1]))[::-1]
    assert format_rows(frame, order) == frame.iloc[:, order].to_csv(index=False, header=False)


def test_remembered_columns_tell_minus_zero_and_nan_apart():
    for values in ([0.0, 1.0], [-0.0, 1.0], [np.nan, 1.0], [0.0, 1.0]):
        frame = pd.DataFrame({"x": values, "step": 3})
        assert format_rows(frame) == frame.to_csv(index=False, header=False)


@settings(max_examples=100, deadline=None)
@given(base=st.lists(_FLOATS, min_size=2, max_size=12), data=st.data())
def test_a_column_changed_in_a_few_values_is_formatted_as_pandas_formats_it(base, data):
    """From one step to the next only the changed values are formatted anew."""
    frame = pd.DataFrame({"x": np.array(base), "point": np.arange(len(base))})
    assert format_rows(frame) == frame.to_csv(index=False, header=False)
    for _ in range(3):
        changed = data.draw(st.lists(st.integers(0, len(base) - 1), max_size=len(base) // 2))
        values = frame["x"].to_numpy().copy()
        for k in changed:
            values[k] = data.draw(_FLOATS)
        frame = pd.DataFrame({"x": values, "point": np.arange(len(base))})
        assert format_rows(frame) == frame.to_csv(index=False, header=False)


def test_other_columns_are_formatted_by_pandas():
    frame = pd.DataFrame({"step": [1], "history": ["[1.5, 2.0]"], "by": [None]})
    assert format_rows(frame) == frame.to_csv(index=False, header=False)


class _Fields:
    def write(self, *args: object) -> None:
        pass


def _record(writer: BiaxialWriter, steps: int, kind: type = float) -> None:
    writer._fields = _Fields()  # the fields file is not what these tests are about
    for step in range(steps):
        points = pd.DataFrame({"step": step, "point": np.arange(3),
                               "sxx": np.arange(3, dtype=float) - step})
        writer.record({"step": step, "axial_strain": step * 1e-3,
                       "cost": kind(step) if step else 0}, points, np.zeros(2))


class _Result:
    def __init__(self, writer_dir):
        tables = writers.read_run_tables(writer_dir)
        self.steps, self.points, self.tracked = tables["steps"], tables["points"], pd.DataFrame()


def test_a_finished_run_keeps_its_appended_tables(tmp_path, monkeypatch):
    writer = BiaxialWriter(tmp_path)
    _record(writer, 4, kind=int)
    result = _Result(tmp_path)
    rewritten = []
    monkeypatch.setattr(writers, "write_tables", lambda *a, **k: rewritten.append(a))
    assert writer.holds(result)
    writer.finish(result)
    assert rewritten == []
    result.steps = result.steps.iloc[:-1]  # a step the writer has not seen: written anew
    assert not writer.holds(result)


def test_a_column_whose_type_changed_is_written_anew_as_the_result_holds_it(tmp_path):
    writer = BiaxialWriter(tmp_path)
    _record(writer, 3, kind=float)  # cost: 0 (an integer) at step 0, then 1.0, 2.0
    assert "0,0.0,0\n" in (tmp_path / "steps.csv").read_text()
    steps = pd.DataFrame([{"step": s, "axial_strain": s * 1e-3, "cost": float(s) if s else 0}
                          for s in range(3)])
    result = _Result(tmp_path)
    result.steps = steps
    assert not writer.holds(result)
    writer.finish(result)
    assert (tmp_path / "steps.csv").read_text() == steps.to_csv(index=False)


def test_a_stop_between_a_steps_writes_has_the_tables_written_whole(tmp_path, monkeypatch):
    """Ctrl-C delivered after a step's points are appended and before its steps row is: the
    run's result holds the step, so finish() writes the tables whole with it."""
    writer = BiaxialWriter(tmp_path)
    _record(writer, 2, kind=int)
    real = writers.write_points

    def interrupted(*args, **keywords):
        real(*args, **keywords)
        raise KeyboardInterrupt

    monkeypatch.setattr(writers, "write_points", interrupted)
    points = pd.DataFrame({"step": 2, "point": np.arange(3), "sxx": np.arange(3.0) - 2})
    with pytest.raises(KeyboardInterrupt):
        writer.record({"step": 2, "axial_strain": 2e-3, "cost": 2}, points, np.zeros(2))
    monkeypatch.setattr(writers, "write_points", real)
    steps = pd.DataFrame([{"step": s, "axial_strain": s * 1e-3, "cost": s} for s in range(3)])
    result = _Result(tmp_path)
    assert len(result.steps) == 2  # the steps row of step 2 is not on disk
    result.steps = steps  # the run's result holds step 2, its points too
    result.points = writers.read_npy_table(tmp_path / "points.npy")  # step 2's points too
    assert len(result.points) == 9
    assert not writer.holds(result)
    writer.finish(result)
    assert (tmp_path / "steps.csv").read_text() == steps.to_csv(index=False)


def test_the_tables_are_flushed_to_the_disk_now_and_then_and_at_the_end(tmp_path, monkeypatch):
    """A kill loses nothing the kernel holds: the tables are flushed (fsync) with the first
    step SYNC_SECONDS after the last flush, points before steps, and when the run ends."""
    synced = []
    real = writers.os.fsync

    def fsync(fd):
        synced.append(Path(f"/proc/self/fd/{fd}").resolve().name)
        real(fd)

    monkeypatch.setattr(writers.os, "fsync", fsync)
    monkeypatch.setattr(writers, "SYNC_SECONDS", 3600.0)
    # a step appended to points.npy and flushed: its records, then its header's count
    flushed = ["points.npy", "points.npy", "steps.csv"]
    with BiaxialWriter(tmp_path) as writer:
        _record(writer, 2, kind=int)  # step 0 written whole, step 1 appended and flushed
        assert synced == flushed
        _record(writer, 4, kind=int)  # appended only
        assert synced == flushed
        writer.finish(_Result(tmp_path))
        assert synced == [*flushed, "points.npy", "steps.csv"]
    monkeypatch.setattr(writers, "SYNC_SECONDS", 0.0)
    synced.clear()
    with BiaxialWriter(tmp_path / "every") as writer:
        _record(writer, 4, kind=int)
    assert synced == flushed * 3  # each appended step
    synced.clear()
    with BiaxialWriter(tmp_path / "csv", points_csv=True) as writer:
        _record(writer, 2, kind=int)
    assert synced == ["points.npy", "points.npy", "points.csv", "steps.csv"]


def test_the_checkpoints_newton_records_are_converted_once_and_read_alike():
    """The state saved after every step converts each Newton record once: its JSON text is
    that of converting them all again."""
    from dataclasses import asdict

    from granular_material.fem import StepRecord
    from granular_material.runs import checkpoint_files

    records = [StepRecord(step=k, load_factor=k / 3, iterations=2, costs={"dem_steps": k},
                          residual_history=[[1.0, 10.0 ** -k]], timings={"assembly": 0.1})
               for k in range(1, 5)]
    for n in range(len(records) + 1):
        assert str(checkpoint_files._records(records[:n])) == str(
            checkpoint_files.dumps([asdict(r) for r in records[:n]]))
    kept = len(checkpoint_files._RECORD_JSON)
    del records
    import gc

    gc.collect()
    assert len(checkpoint_files._RECORD_JSON) <= kept - 4  # forgotten with their records
