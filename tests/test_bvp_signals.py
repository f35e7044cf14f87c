"""A boundary-value run stopped by Ctrl-C, SIGTERM or SIGHUP exits as the specimen commands
do, 130, 143 or 129, with the command that continues it on stderr; that command reaches the
run that never stopped (issue 61, kind 7)."""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest
from run_helpers import PRESSED_BLOCK

from granular_material.cli import main
from granular_material.cli.signals import Terminated
from granular_material.fem.solver.newton import NewtonSolver

SCENE = """test = "boundary-value"
steps = {steps}
[mesh]
size = [0.4, 0.2]
elements = [{nx}, 2]
""" + PRESSED_BLOCK.format(base="bottom").replace("{", "{{").replace("}", "}}")
SIGNALS = {"SIGINT": 130, "SIGTERM": 143, "SIGHUP": 129}


def _stop(name: str) -> KeyboardInterrupt:
    if name == "SIGINT":
        return KeyboardInterrupt()
    exc = Terminated(f"signal {name}")
    exc.signum = int(getattr(signal, name))
    return exc


def _resume_command(err: str) -> list[str]:
    line = next(t for t in err.splitlines() if t.startswith("continue it with `"))
    words = shlex.split(line.split("`")[1])
    assert words[:2] == ["granular-material", "run"] and words[-1] == "--resume"
    return words[1:]


@pytest.mark.parametrize("name", list(SIGNALS))
def test_a_stopped_run_exits_with_the_signals_code_and_how_to_resume(tmp_path, monkeypatch,
                                                                      capsys, name):
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.format(steps=4, nx=2))
    original = NewtonSolver.step

    def step_or_stop(self, target, k):
        if k == 3:
            raise _stop(name)
        return original(self, target, k)

    with monkeypatch.context() as m:
        m.setattr(NewtonSolver, "step", step_or_stop)
        assert main(["run", str(scene), "--out", str(tmp_path / "run")]) == SIGNALS[name]
    err = capsys.readouterr().err
    assert "interrupted after load step 2 of 4" in err and "Traceback" not in err
    assert main(_resume_command(err)) == 0
    assert main(["run", str(scene), "--out", str(tmp_path / "whole")]) == 0
    a, b = (pd.read_csv(tmp_path / f / "steps.csv").drop(columns=["wall_time"])
            for f in ("run", "whole"))
    pd.testing.assert_frame_equal(a, b, check_exact=True)


def _signals_as_at_a_terminal() -> None:
    """The child's stop signals at their defaults: a suite run under ``nohup`` or as a shell's
    background job ignores SIGHUP or SIGINT, and a command keeps a signal ignored at its
    start (as it should), which would leave these runs unstoppable."""
    for name in SIGNALS:
        signal.signal(getattr(signal, name), signal.SIG_DFL)


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
@pytest.mark.parametrize("name", list(SIGNALS))
def test_a_real_signal_stops_a_boundary_value_run(tmp_path, name):
    """The signal itself, in a process of its own, sent once two steps are committed."""
    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE.format(steps=100000, nx=40))
    out = tmp_path / "run"
    process = subprocess.Popen([sys.executable, "-m", "granular_material.cli", "run",
                                str(scene), "--out", str(out)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               preexec_fn=_signals_as_at_a_terminal)
    deadline = time.monotonic() + 120
    while not ((out / "steps.csv").is_file()
               and len((out / "steps.csv").read_text().splitlines()) >= 3):
        assert process.poll() is None and time.monotonic() < deadline, "no step committed"
        time.sleep(0.05)
    process.send_signal(getattr(signal, name))
    _, err = process.communicate(timeout=120)
    err = err.decode()
    assert process.returncode == SIGNALS[name], err
    assert f"--out {out} --resume`" in err and "Traceback" not in err
