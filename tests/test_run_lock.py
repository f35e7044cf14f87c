"""One writer per run folder (issue 24, part 2): a run takes a lock in its --out before it
writes anything; a second run or resume into that folder is refused at once, naming the
folder and the holder's pid, and the lock goes with the process, however it ends."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from granular_material.cli import build_parser, main
from granular_material.dem import save_rve
from granular_material.procedures import prepare_packing
from granular_material.results.lock import LOCK_NAME, FolderLock, FolderLockedError

pytestmark = pytest.mark.skipif(os.name != "posix", reason="fcntl.flock")


def test_a_held_lock_refuses_a_second_holder(tmp_path):
    folder = tmp_path / "new" / "run"
    first = FolderLock(folder)
    first.acquire()
    assert (folder / LOCK_NAME).read_text().strip() == str(os.getpid())
    with pytest.raises(FolderLockedError, match=rf"{folder} .*pid {os.getpid()}"):
        FolderLock(folder).acquire()
    first.release()
    assert not (tmp_path / "new").exists()  # made for the lock alone: removed again
    with FolderLock(folder):
        (folder / "kept").write_text("x")
    assert sorted(p.name for p in folder.iterdir()) == ["kept"]


def test_a_second_run_into_a_running_folder_is_refused_at_once(tmp_path, capsys):
    rve = tmp_path / "rve16.npz"
    save_rve(rve, prepare_packing(n_disc=16, seed=1, pressure=100e3, device="cpu").to_data())
    out = tmp_path / "run"
    argv = ["single-element", "--rve", str(rve), "--steps", "200", "--axial-strain", "0.02",
            "--device", "cpu", "--no-progress", "--json"]
    process = subprocess.Popen([sys.executable, "-m", "granular_material.cli", *argv,
                                "--out", str(out)], stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
    try:
        end = time.monotonic() + 300
        while not (out / "checkpoint" / "steps" / "step_00001.npz").exists():
            assert process.poll() is None, process.stderr.read()
            assert time.monotonic() < end, "the run wrote no step"
            time.sleep(0.05)
        options = (out / "checkpoint" / "options.json").read_bytes()
        build_parser()  # the imports, before the clock starts
        for second in (["--out", str(out)], ["--resume", str(out)]):
            started = time.monotonic()
            code = main([*argv, *second])
            err = capsys.readouterr().err
            assert code == 2 and f"{out} is being written by another run" in err, err
            assert f"pid {process.pid}" in err and "Traceback" not in err
            assert time.monotonic() - started < 5  # refused before any work
        assert (out / "checkpoint" / "options.json").read_bytes() == options
        assert process.poll() is None  # the first run goes on undisturbed
    finally:
        process.send_signal(signal.SIGKILL)
        process.communicate(timeout=60)
    # the killed holder's lock went with it: the folder's checkpoint is read again (and its
    # options checked), not refused for the lock
    code = main([*argv, "--steps", "201", "--resume", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "--steps 201 (the run had 200)" in err, err
    assert "another run" not in err


def test_a_dem_scene_into_a_locked_run_folder_is_refused(tmp_path, capsys):
    """A DEM command's scene (whose summary.json the scene writes) locks its run folder."""
    scene = tmp_path / "p.toml"
    scene.write_text('test = "prepare"\nparticles = 16\ndevice = "cpu"\n')
    run_dir = tmp_path / "p"
    with FolderLock(run_dir):
        code = main(["run", str(scene), "--out", str(run_dir)])
        err = capsys.readouterr().err
        assert code == 2 and f"pid {os.getpid()}" in err, err
        assert sorted(p.name for p in run_dir.iterdir()) == [LOCK_NAME]
    assert not run_dir.exists()
