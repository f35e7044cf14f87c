"""Tables that grow while a run goes (issue 47): appended rows are whole or absent on disk, a
failed append leaves the table as it was, a killed writer leaves at most a cut last row that
the readers leave out, and a step's rows count only once its ``steps.csv`` row is whole."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from granular_material.results import writers
from granular_material.results.writers import (
    BiaxialWriter,
    append_csv,
    read_run_tables,
    read_table,
    write_csv,
)


def _points(step: int, n: int = 3) -> pd.DataFrame:
    return pd.DataFrame({"step": step, "point": np.arange(n), "sxx": -1e5 - step - np.arange(n)})


def test_rows_are_appended_by_column_name(tmp_path):
    path = tmp_path / "points.csv"
    append_csv(_points(0), path)  # no table yet: written whole, with its header
    append_csv(_points(1)[["sxx", "point", "step"]], path)  # another order, the same columns
    table = read_table(path)
    assert list(table.columns) == ["step", "point", "sxx"]
    pd.testing.assert_frame_equal(table, pd.concat([_points(0), _points(1)], ignore_index=True))


def test_other_columns_rewrite_the_table_whole_with_their_union(tmp_path):
    path = tmp_path / "steps.csv"
    write_csv(pd.DataFrame([{"step": 0, "iterations": 0}]), path)
    append_csv(pd.DataFrame([{"step": 1, "iterations": 3, "dem_steps": 120}]), path)
    table = read_table(path)
    assert list(table["step"]) == [0, 1] and list(table["iterations"]) == [0, 3]
    assert np.isnan(table["dem_steps"][0]) and table["dem_steps"][1] == 120


def test_a_failed_append_leaves_the_table_as_it_was(tmp_path, monkeypatch):
    path = tmp_path / "points.csv"
    write_csv(_points(0), path)
    before = path.read_bytes()
    real_write = os.write

    def full_disk(fd: int, data: bytes) -> int:
        real_write(fd, bytes(data[: len(data) // 2]))  # half the rows go in, then the disk is full
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(writers.os, "write", full_disk)
    with pytest.raises(OSError, match=rf"cannot add to {path}: No space left") as caught:
        append_csv(_points(1), path)
    assert caught.value.errno == errno.ENOSPC
    assert path.read_bytes() == before


def test_a_cut_last_row_is_left_out_and_dropped_by_the_next_append(tmp_path):
    path = tmp_path / "points.csv"
    write_csv(_points(0), path)
    with open(path, "ab") as fh:
        fh.write(b"1,0,-1000")  # a row cut inside its last number: -100001 would read as -1000
    assert len(read_table(path)) == 3
    append_csv(_points(1), path)
    pd.testing.assert_frame_equal(read_table(path),
                                  pd.concat([_points(0), _points(1)], ignore_index=True))


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(steps=st.integers(2, 6), points=st.integers(1, 4), killed=st.integers(2, 11),
       cut=st.floats(0.0, 1.0))
def test_a_run_folder_cut_anywhere_reads_as_its_committed_steps(tmp_path, steps, points,
                                                               killed, cut):
    """The tables of a run written as a run writes them (a step's points, then its steps
    row), killed during its write number ``killed`` (an append; step 0 is written whole,
    never cut), cut at any byte of it: the reader gives a prefix of the steps, every row
    whole, and the points of exactly those steps."""
    out = Path(tempfile.mkdtemp(dir=tmp_path))  # one folder an example (examples repeat)
    writes = [(name, step, frame) for step in range(steps) for name, frame in (
        ("points", _points(step, points)),
        ("steps", pd.DataFrame([{"step": step, "load_factor": step / 10}])))]
    killed = min(killed, len(writes) - 1)
    for name, step, frame in writes[:killed + 1]:
        path = out / f"{name}.csv"
        before = path.stat().st_size if path.exists() else 0
        write_csv(frame, path, append=step > 0)
    after = path.stat().st_size
    with open(path, "r+b") as fh:
        fh.truncate(before + int(cut * (after - before)))
    tables = read_run_tables(out)
    done = list(tables["steps"]["step"])
    assert done == list(range(len(done))) and len(done) >= killed // 2
    assert list(tables["steps"]["load_factor"]) == [s / 10 for s in done]
    expected = pd.concat([_points(s, points) for s in done], ignore_index=True)
    pd.testing.assert_frame_equal(tables["points"], expected)


def test_a_step_writes_its_steps_row_last(tmp_path, monkeypatch):
    order = []
    real = writers.write_csv

    def recording(frame: pd.DataFrame, path: str | Path, append: bool = False,
                  **keywords: bool) -> Path:
        order.append(Path(path).name)
        return real(frame, path, append, **keywords)

    class Fields:
        def write(self, *args: object) -> None:
            pass

    real_points = writers.write_points

    def points_recording(frame: pd.DataFrame, out: Path, append: bool = False,
                         **keywords: bool) -> dict[str, Path]:
        order.append("points.npy")
        return real_points(frame, out, append, **keywords)

    monkeypatch.setattr(writers, "write_csv", recording)
    monkeypatch.setattr(writers, "write_points", points_recording)
    writer = BiaxialWriter(tmp_path)
    writer._fields = Fields()  # the fields file is not what this test is about
    for step in range(3):
        writer.record({"step": step, "axial_strain": step * 1e-3}, _points(step),
                      np.zeros(2), _points(step, 1))
    assert order == ["tracked.csv", "points.npy", "steps.csv"] * 3
    tables = read_run_tables(tmp_path)
    assert list(tables["steps"]["step"]) == [0, 1, 2] and len(tables["points"]) == 9
    assert len(tables["tracked"]) == 3


_WRITER = """
import sys
import numpy as np, pandas as pd
from granular_material.results.writers import write_csv, write_points
out, kind = sys.argv[1:3]
print("ready", flush=True)
for step in range(10**6):
    points = pd.DataFrame({"step": step, "point": np.arange(500), "sxx": np.full(500, -1.0 - step)})
    if kind == "csv":
        write_csv(points, out + "/points.csv", append=step > 0)
    else:
        write_points(points, out, append=step > 0)
    write_csv(pd.DataFrame([{"step": step}]), out + "/steps.csv", append=step > 0)
"""


@pytest.mark.skipif(os.name != "posix", reason="SIGKILL")
@pytest.mark.parametrize(("after", "kind"), [(0.4, "csv"), (0.9, "csv"), (0.6, "npy")])
def test_a_writer_killed_outright_leaves_tables_that_read_whole(tmp_path, after, kind):
    process = subprocess.Popen([sys.executable, "-c", _WRITER, str(tmp_path), kind],
                               stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "ready"
    time.sleep(after)
    process.send_signal(signal.SIGKILL)
    process.wait(timeout=30)
    process.stdout.close()
    tables = read_run_tables(tmp_path)
    done = list(tables["steps"]["step"])
    assert done == list(range(len(done))) and done
    points = tables["points"]
    assert len(points) == 500 * len(done)
    assert (points["sxx"] == -1.0 - points["step"]).all()  # no row cut inside a number


def test_a_rewrite_for_new_columns_keeps_every_float_bit_for_bit(tmp_path):
    path = tmp_path / "steps.csv"
    values = np.random.default_rng(3).random(50) * 10.0 ** np.arange(-25, 25)
    write_csv(pd.DataFrame({"step": range(50), "value": values}), path)
    append_csv(pd.DataFrame([{"step": 50, "value": 1 / 3, "dem_steps": 7}]), path)
    table = read_table(path)
    assert table["value"].tolist() == [*values.tolist(), 1 / 3]
