"""Whole files, signals and collapse (issue 24, parts 7-9): every output is written whole or
not at all and a failed write names its file and leaves no ``.part`` (a full disk where the
platform lets a test make one); SIGHUP stops a run as SIGTERM does (exit 129, with its
summary and figures); stop signals wait until the file being written is whole; a strain path
that would collapse an RVE (void ratio <= 0) fails with exit 1 naming it."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from granular_material.cli import main
from granular_material.cli.signals import (
    Terminated,
    interrupt_exit_code,
    stop_signals_as_interrupt,
)
from granular_material.dem import DEMBatch, load_rve, save_rve
from granular_material.filesafe import write_whole
from granular_material.procedures import RVECollapseError, drive_grad_u, prepare_packing
from granular_material.results import write_csv, write_json

posix = pytest.mark.skipif(os.name != "posix", reason="POSIX signals")


@pytest.fixture(scope="module")
def rve16(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rve") / "rve16.npz"
    save_rve(path, prepare_packing(n_disc=16, seed=1, pressure=100e3, device="cpu").to_data())
    return path


# -- whole files ------------------------------------------------------------------------------
def test_a_failed_write_names_the_file_and_leaves_no_part(tmp_path):
    target = tmp_path / "table.csv"
    target.write_text("the old table\n")

    def full_disk(tmp: Path) -> None:
        tmp.write_text("half")
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError, match=rf"cannot write {target}: No space left") as caught:
        write_whole(target, full_disk)
    assert caught.value.errno == errno.ENOSPC
    assert target.read_text() == "the old table\n"  # the old file, untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.csv"]


@posix
def test_stop_signals_wait_until_the_file_is_whole(tmp_path):
    """SIGTERM and SIGHUP sent while a file is written are delivered after it is renamed
    into place: whole file, no .part, then the stop."""
    # under nohup SIGHUP starts ignored, and a command leaves an ignored signal ignored
    hangup = signal.signal(signal.SIGHUP, signal.SIG_DFL)
    try:
        _stop_while_writing(tmp_path)
    finally:
        signal.signal(signal.SIGHUP, hangup)


def _stop_while_writing(tmp_path: Path) -> None:
    for stop in (signal.SIGTERM, signal.SIGHUP):
        path = tmp_path / f"{stop.name}.json"

        def write(tmp: Path, stop: signal.Signals = stop) -> None:
            tmp.write_text("{")
            os.kill(os.getpid(), stop)
            time.sleep(0.05)  # the signal is pending, held back
            with open(tmp, "a") as fh:
                fh.write('"whole": true}')

        with stop_signals_as_interrupt(), pytest.raises(Terminated) as caught:
            write_whole(path, write)
        assert json.loads(path.read_text()) == {"whole": True}
        assert interrupt_exit_code(caught.value) == 128 + stop
        assert not list(tmp_path.glob("*.part"))


@pytest.fixture
def full_disk(tmp_path: Path):
    """A 256 kB tmpfs (root only) and a function that fills it to ``room`` bytes free."""
    folder = tmp_path / "small"
    folder.mkdir()
    if os.name != "posix" or os.geteuid() != 0:
        pytest.skip("a small file system needs root to mount (tmpfs)")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(folder)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")

    def fill(room: int) -> None:
        free = os.statvfs(folder).f_bavail * os.statvfs(folder).f_frsize
        (folder / "filler").write_bytes(b"\0" * max(free - room, 0))

    try:
        yield folder, fill
    finally:
        subprocess.run(["umount", str(folder)], check=False)


def test_a_full_disk_names_the_file_and_leaves_no_part(full_disk, rve16, capsys):
    folder, fill = full_disk
    fill(0)
    code = main(["prepare", "--particles", "16", "--device", "cpu", "--out",
                 str(folder / "r.npz")])
    err = capsys.readouterr().err
    assert code == 2 and f"cannot write {folder / 'r.npz'}" in err, err
    assert "No space left" in err and "Traceback" not in err
    assert sorted(p.name for p in folder.iterdir()) == ["filler"]
    (folder / "filler").unlink()
    fill(24_000)  # room for the start of a run, not for all of it
    out = folder / "run"
    code = main(["single-element", "--rve", str(rve16), "--steps", "6", "--axial-strain",
                 "0.003", "--device", "cpu", "--no-progress", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "cannot write" in err and "No space left" in err, err
    assert not list(folder.rglob("*.part"))
    assert all(p.stat().st_size > 0 for p in folder.rglob("*") if p.is_file()), \
        [p.name for p in folder.rglob("*") if p.is_file() and p.stat().st_size == 0]


# -- SIGHUP -------------------------------------------------------------------------------------
@posix
def test_sighup_stops_a_run_with_its_summary_and_figures(rve16, tmp_path):
    out = tmp_path / "run"
    process = subprocess.Popen(
        [sys.executable, "-m", "granular_material.cli", "single-element", "--rve", str(rve16),
         "--steps", "200", "--axial-strain", "0.02", "--device", "cpu", "--no-progress",
         "--json", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        # a test run under nohup hands its children SIGHUP ignored, which a command keeps
        text=True, preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_DFL))
    end = time.monotonic() + 300
    while not (out / "checkpoint" / "steps" / "step_00002.npz").exists():
        assert process.poll() is None, process.communicate()[1]
        assert time.monotonic() < end
        time.sleep(0.05)
    process.send_signal(signal.SIGHUP)
    stdout, stderr = process.communicate(timeout=300)
    assert process.returncode == 129, stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["error"].startswith("interrupted after load step")
    assert json.loads(stdout) == summary and "Traceback" not in stderr
    assert f"--resume {out}" in stderr
    assert (out / "stress_strain.png").stat().st_size > 0
    assert (out / "fields.xdmf").stat().st_size > 0
    assert len(pd.read_csv(out / "steps.csv")) == summary["steps_completed"] + 1
    assert not list(out.rglob("*.part"))


def test_sighup_and_sigterm_exit_codes():
    hup = Terminated("signal SIGHUP")
    hup.signum = int(signal.SIGHUP)
    assert interrupt_exit_code(hup) == 129
    assert interrupt_exit_code(Terminated("signal SIGTERM")) == 143
    assert interrupt_exit_code(KeyboardInterrupt()) == 130


# -- collapse -----------------------------------------------------------------------------------
def test_a_path_that_collapses_the_rve_fails_naming_it(rve16, tmp_path, capsys):
    out = tmp_path / "path.csv"
    code = main(["dem-drive", str(rve16), "--grad-u=-0.5,0,0,0", "--increments", "1",
                 "--max-dem-steps", "100000000", "--device", "cpu", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1 and "collapse RVE(s) 0 (e = -0.4" in err and "void ratio <= 0" in err
    code = main(["dem-drive", str(rve16), "--grad-u=-0.6,0,0,0", "--increments", "4",
                 "--max-dem-steps", "100000000", "--device", "cpu", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1 and "in increment 2 of 4; the path to increment 1 is kept" in err
    assert sorted(pd.read_csv(out)["increment"]) == [0, 1]  # the path before it is kept
    assert (pd.read_csv(out)["void_ratio"] > 0).all()
    batch = DEMBatch(load_rve(rve16).replicate(3), device="cpu")
    before = batch.to_data()
    grad = np.zeros((3, 2, 2))
    grad[1] = [[-0.5, 0.0], [0.0, 0.0]]
    with pytest.raises(RVECollapseError) as caught:
        drive_grad_u(batch, grad)
    assert caught.value.rve == [1]
    np.testing.assert_array_equal(batch.to_data().position, before.position)  # no step run


def test_writers_still_write(tmp_path):
    assert pd.read_csv(write_csv(pd.DataFrame({"a": [1]}), tmp_path / "t.csv"))["a"][0] == 1
    assert json.loads(write_json({"a": 1}, tmp_path / "s.json").read_text()) == {"a": 1}


@posix
def test_only_the_first_stop_signal_is_raised():
    # a background job starts with Ctrl-C ignored, which a command keeps: restore it here
    interrupt = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _only_the_first_stop()
    finally:
        signal.signal(signal.SIGINT, interrupt)


def _only_the_first_stop() -> None:
    with stop_signals_as_interrupt():
        with pytest.raises(Terminated):
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1)
        os.kill(os.getpid(), signal.SIGTERM)  # stopping already: ignored
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)
    with stop_signals_as_interrupt(), pytest.raises(KeyboardInterrupt):  # a new command
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(1)


@posix
@pytest.mark.parametrize(("stop", "count"), [(signal.SIGTERM, 30), (signal.SIGINT, 5)])
def test_a_storm_of_signals_near_the_end_cuts_no_file(stop, count, rve16, tmp_path):
    """Signals every 50 ms from load step 4 of 6 to the end: the exit code of the first,
    the summary, whole files, no .part, no traceback."""
    out = tmp_path / "run"
    process = subprocess.Popen(
        [sys.executable, "-m", "granular_material.cli", "single-element", "--rve", str(rve16),
         "--steps", "6", "--axial-strain", "0.003", "--device", "cpu", "--no-progress",
         "--json", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    while not (out / "checkpoint" / "steps" / "step_00004.npz").exists():
        assert process.poll() is None, process.communicate()[1]
        time.sleep(0.01)
    sent = 0
    while process.poll() is None and sent < count:
        process.send_signal(stop)
        sent += 1
        time.sleep(0.05)
    _, stderr = process.communicate(timeout=300)
    assert process.returncode == 128 + stop, stderr
    assert "Traceback" not in stderr
    assert json.loads((out / "summary.json").read_text())["error"]
    files = [p for p in out.rglob("*") if p.is_file()]
    assert not [p for p in files if p.name.endswith(".part") or p.stat().st_size == 0]


class _StoppedInItsFinaliser:
    """Sends SIGTERM to this process from its ``__del__``: the handler's exception is then
    raised inside the finaliser, where Python swallows it ("Exception ignored in")."""

    def __del__(self) -> None:
        signal.raise_signal(signal.SIGTERM)
        for _ in range(1000):  # the handler runs at one of these bytecodes, still in here
            pass


def test_a_stop_swallowed_by_a_finaliser_is_sent_again() -> None:
    """A SIGTERM that lands in a garbage collector's finaliser (seen on a long biaxial run:
    "Exception ignored in WeakKeyDictionary ... Terminated", and the run went on) stops the
    command all the same, a moment later, instead of being lost with every later signal
    ignored."""
    from granular_material.cli.signals import Terminated, stop_signals_as_interrupt

    with stop_signals_as_interrupt(), pytest.raises(Terminated):
        dying = _StoppedInItsFinaliser()
        del dying
        time.sleep(5.0)  # the signal comes back within 0.05 s
