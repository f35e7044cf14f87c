"""points.npy, the Gauss-point history as a NumPy table of records grown step by step: read
by numpy.load and pandas alike, its count the commit of a step, a failed or killed append
leaving the steps before, and read_points reading it or points.csv."""

from __future__ import annotations

import errno
import os

import numpy as np
import pandas as pd
import pytest

from granular_material.results import point_table, read_points, write_points
from granular_material.results.point_table import append_npy, read_npy_table, write_npy_table
from granular_material.results.writers import write_csv


def _points(step: int, n: int = 4, region: str = "sand") -> pd.DataFrame:
    rng = np.random.default_rng(step)
    return pd.DataFrame({"step": step, "point": np.arange(n), "sxx": -rng.random(n) * 1e5,
                         "friction_angle": np.where(np.arange(n) % 2, np.nan, 0.6),
                         "failed": rng.random(n) > 0.5, "region": region})


def test_appended_steps_read_back_bit_for_bit_by_numpy_and_pandas(tmp_path):
    path = tmp_path / "points.npy"
    frames = [_points(step) for step in range(5)]
    for frame in frames:
        append_npy(frame, path)
    whole = pd.concat(frames, ignore_index=True)
    records = np.load(path)
    assert records.shape == (20,) and records.dtype.names == tuple(whole.columns)
    assert records.dtype["step"] == np.int64 and records.dtype["failed"] == np.bool_
    pd.testing.assert_frame_equal(pd.DataFrame(records), whole, check_exact=True)
    pd.testing.assert_frame_equal(read_npy_table(path), whole, check_exact=True)
    # the header keeps its length: the records never move
    assert (path.stat().st_size - 20 * records.dtype.itemsize) % 64 == 0


def test_records_past_the_count_are_not_read_and_the_next_step_writes_over_them(tmp_path):
    """A kill after a step's records and before its count: numpy reads the steps before."""
    path = tmp_path / "points.npy"
    write_npy_table(_points(0), path)
    with open(path, "ab") as fh:
        fh.write(b"\x01" * 100)  # half a step's records
    assert len(np.load(path)) == 4 and len(np.load(path, mmap_mode="r")) == 4
    append_npy(_points(1), path)
    pd.testing.assert_frame_equal(read_npy_table(path),
                                  pd.concat([_points(0), _points(1)], ignore_index=True))


def test_a_longer_text_or_a_new_column_rewrites_the_table_whole(tmp_path):
    path = tmp_path / "points.npy"
    append_npy(_points(0), path)
    append_npy(_points(1, region="clay and silt"), path)  # wider than the field
    assert np.load(path).dtype["region"] == np.dtype("<U13")
    more = _points(2).assign(void_ratio=0.7)
    append_npy(more, path)
    table = read_npy_table(path)
    assert list(table["region"]) == ["sand"] * 4 + ["clay and silt"] * 4 + ["sand"] * 4
    assert table["void_ratio"].isna().sum() == 8 and (table["void_ratio"].iloc[8:] == 0.7).all()


def test_flags_with_gaps_are_numbers_and_text_stays_text(tmp_path):
    """A flag a region's material does not report (True/False, NaN there) is stored as
    float64, 1.0/0.0/NaN; a column of text as text."""
    frame = pd.DataFrame({"step": [0, 0, 0], "failed": [True, np.nan, False],
                          "phase": ["load", "load", "gravity"]})
    write_npy_table(frame, tmp_path / "points.npy")
    records = np.load(tmp_path / "points.npy")
    assert records.dtype["failed"] == np.float64 and records.dtype["phase"] == np.dtype("<U7")
    np.testing.assert_array_equal(records["failed"], [1.0, np.nan, 0.0])
    assert list(read_npy_table(tmp_path / "points.npy")["phase"]) == list(frame["phase"])
    size = (tmp_path / "points.npy").stat().st_size
    append_npy(frame.assign(failed=[True, False, True]), tmp_path / "points.npy")  # no gaps
    records = np.load(tmp_path / "points.npy")
    assert (tmp_path / "points.npy").stat().st_size == size + 3 * records.dtype.itemsize
    np.testing.assert_array_equal(records["failed"][3:], [1.0, 0.0, 1.0])  # appended


def test_a_failed_append_leaves_the_table_as_it_was(tmp_path, monkeypatch):
    path = tmp_path / "points.npy"
    write_npy_table(_points(0), path)
    before = path.read_bytes()
    real = os.pwrite

    def full_disk(fd: int, data: bytes, offset: int) -> int:
        real(fd, bytes(data[: len(data) // 2]), offset)
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(point_table.os, "pwrite", full_disk)
    with pytest.raises(OSError, match=rf"cannot add to {path}: No space left"):
        append_npy(_points(1), path)
    monkeypatch.undo()
    assert path.read_bytes() == before


def test_read_points_reads_either_file_without_uncommitted_steps(tmp_path):
    frames = [_points(step) for step in range(3)]
    for folder, csv in ((tmp_path / "npy", False), (tmp_path / "csv", True)):
        for step, frame in enumerate(frames):
            write_points(frame, folder, append=step > 0, csv=csv)
        write_csv(pd.DataFrame({"step": [0, 1]}), folder / "steps.csv")  # step 2 uncommitted
    (tmp_path / "csv" / "points.npy").unlink()  # a folder of points.csv alone
    expected = pd.concat(frames[:2], ignore_index=True)
    for name in ("npy", "csv"):
        pd.testing.assert_frame_equal(read_points(tmp_path / name), expected, check_exact=True)
    with pytest.raises(FileNotFoundError, match=r"no points\.npy nor points\.csv"):
        read_points(tmp_path)
