"""Ctrl-C and SIGTERM in the DEM commands (issue 12, part 3): the finished records are
written, the report says where the run stopped, and the exit code is the shell's (130 for
Ctrl-C, 143 for SIGTERM); nothing prints a traceback."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

import granular_material.procedures.driven_path as driven_path
import granular_material.procedures.element_tests as element_tests
from granular_material.cli import main
from granular_material.cli.signals import Terminated, stop_signals_as_interrupt
from granular_material.dem import save_rve
from granular_material.procedures import prepare_packing


@pytest.fixture(scope="module")
def rve64(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rve") / "rve64.npz"
    save_rve(path, prepare_packing(n_disc=64, seed=1, pressure=100e3, device="cpu").to_data())
    return path


def _interrupt_on_call(monkeypatch, module, name: str, call: int,
                       interrupt: type[KeyboardInterrupt]) -> None:
    """Make ``module.name`` raise ``interrupt`` on its ``call``-th call (as a signal would,
    in the middle of the work), running normally before."""
    real = getattr(module, name)
    calls = {"n": 0}

    def wrapped(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == call:
            raise interrupt("signal")
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, wrapped)


def _main(capsys, *argv: str) -> tuple[int, dict, str]:
    code = main([*argv, "--json", "--device", "cpu", "--no-progress"])
    captured = capsys.readouterr()
    return code, json.loads(captured.out) if captured.out.strip() else {}, captured.err


@pytest.mark.parametrize(("interrupt", "code"), [(KeyboardInterrupt, 130), (Terminated, 143)])
def test_biaxial_dem_keeps_the_records_made_before_the_signal(interrupt, code, rve64,
                                                                tmp_path, monkeypatch,
                                                                capsys):
    # records every 50 DEM steps; the 4th chunk is interrupted: records 0, 50, 100, 150 kept
    _interrupt_on_call(monkeypatch, element_tests, "servo_steps", 4, interrupt)
    csv, png = tmp_path / "curve.csv", tmp_path / "curve.png"
    got, report, err = _main(capsys, "biaxial-dem", str(rve64), "--axial-strain", "0.01",
                             "--record-every", "50", "--out", str(csv), "--plot", str(png))
    assert got == code
    curve = pd.read_csv(csv)
    assert sorted(curve["step"].unique()) == [0, 50, 100, 150]
    assert png.is_file() and report["steps"] == 150
    assert report["error"].startswith("interrupted after DEM step 150 of 1006")
    assert "Traceback" not in err and report["error"] in err


@pytest.mark.parametrize(("interrupt", "code"), [(KeyboardInterrupt, 130), (Terminated, 143)])
def test_dem_drive_keeps_the_finished_increments(interrupt, code, rve64, tmp_path,
                                                 monkeypatch, capsys):
    _interrupt_on_call(monkeypatch, driven_path, "drive_grad_u", 3, interrupt)
    csv = tmp_path / "path.csv"
    got, report, err = _main(capsys, "dem-drive", str(rve64), "--grad-u", "0,0.001,0,0",
                             "--increments", "5", "--out", str(csv))
    assert got == code
    assert sorted(pd.read_csv(csv)["increment"].unique()) == [0, 1, 2]
    assert report["increments_completed"] == 2
    assert report["error"] == "interrupted after increment 2 of 5: the path to it is kept"
    assert "Traceback" not in err


def test_prepare_interrupted_writes_no_packing(tmp_path, monkeypatch, capsys):
    """A packing is only written once consolidated: nothing is kept, no traceback."""
    import granular_material.procedures.packing as packing

    _interrupt_on_call(monkeypatch, packing, "consolidate", 1, Terminated)
    out = tmp_path / "rve.npz"
    got, _, err = _main(capsys, "prepare", "--particles", "24", "--out", str(out))
    assert got == 143 and not out.exists()
    assert "terminated (SIGTERM)" in err and "Traceback" not in err


def test_sigterm_handler_is_restored():
    before = signal.getsignal(signal.SIGTERM)
    with stop_signals_as_interrupt(), pytest.raises(Terminated):
        os.kill(os.getpid(), signal.SIGTERM)
    assert signal.getsignal(signal.SIGTERM) is before


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
def test_a_real_sigterm_stops_biaxial_dem_with_its_curve(rve64, tmp_path):
    """The signal itself, in a process of its own: sent once the progress bar has moved."""
    csv = tmp_path / "curve.csv"
    process = subprocess.Popen(
        [sys.executable, "-m", "granular_material.cli", "biaxial-dem", str(rve64),
         "--axial-strain", "0.1", "--strain-per-step", "1e-6", "--record-every", "100",
         "--device", "cpu", "--progress", "--json", "--out", str(csv)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    seen = b""
    while b"q=" not in seen:  # the bar's stress ratio: records are being made
        chunk = process.stderr.read1(4096)
        assert chunk, "the run ended before its progress bar moved"
        seen += chunk
    process.send_signal(signal.SIGTERM)
    stdout, rest = process.communicate(timeout=120)
    assert process.returncode == 143, (seen + rest).decode()
    report = json.loads(stdout)
    assert report["error"].startswith("interrupted after DEM step")
    assert len(pd.read_csv(csv)) >= 2 and report["steps"] < 105_000
