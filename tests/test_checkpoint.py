"""Checkpoints and resume (issue 12, part 3): a FEM run stopped by Ctrl-C, SIGTERM or
SIGKILL at any moment resumes to the tables and final state of a run that never stopped."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from run_helpers import StopAtStep, run_table, without_clock

from granular_material.cli import main
from granular_material.dem import save_rve
from granular_material.errors import ParameterError
from granular_material.fem import (
    BiaxialSetup,
    create_material,
    default_settings,
    default_stress_tol,
)
from granular_material.procedures import prepare_packing
from granular_material.runs import CheckpointError, RunCheckpoint, run_biaxial
from granular_material.runs.execute import run as execute_run
from granular_material.runs.serial import from_dict

SETUP = BiaxialSetup(width=1.0, height=1.0, nx=1, ny=1, confining=100e3, axial_strain=0.003)
#: columns that hold a clock time [s], the only ones a resumed run may change


@pytest.fixture(scope="module")
def rve64(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 64-disc RVE file (seed 1, 100 kPa)."""
    path = tmp_path_factory.mktemp("rve") / "rve64.npz"
    save_rve(path, prepare_packing(n_disc=64, seed=1, pressure=100e3, device="cpu").to_data())
    return path




def _same_arrays(a: Path, b: Path) -> bool:
    """Whether two .npz files hold the same arrays, bit for bit (NaN equal to NaN)."""
    with np.load(a) as x, np.load(b) as y:
        return set(x.files) == set(y.files) and all(
            np.array_equal(x[k], y[k], equal_nan=x[k].dtype.kind == "f") for k in x.files)


def _run(kind: str, material, n_steps: int, **keywords):
    """``run_biaxial`` with the settings the commands use for the material."""
    name = "linear-elastic" if kind == "linear-elastic" else "dem"
    # reused RVEs answer in steps, which the displacement test cannot see converge: the
    # reuse run takes the force test (as the command line requires) with the loop it was
    # measured with (Aitken, 25 iterations)
    loop = ({"convergence": "force", "relaxation": "aitken", "max_iterations": 25}
            if kind == "dem-continue-reuse" else {})
    return run_biaxial(SETUP, material, n_steps, default_settings(name, **loop),
                       stress_tol=default_stress_tol(name, SETUP.confining), **keywords)


def _material(kind: str, rve: Path):
    if kind == "linear-elastic":
        return create_material("linear-elastic", young=50e6, poisson=0.25,
                               initial_stress=-100e3)
    drive, reuse = ("continue", 1e-4) if kind == "dem-continue-reuse" else ("restart", 0.0)
    return create_material("dem", rve=rve, replicate=True, device="cpu", drive=drive,
                           reuse_tol=reuse)


def _records(result) -> pd.DataFrame:
    """The Newton records of a run as a table, without their clock times."""
    return without_clock(pd.DataFrame([asdict(r) for r in result.records]))




# -- the checkpoint folder ------------------------------------------------------------------
def test_tables_round_trip_exactly(tmp_path):
    checkpoint = RunCheckpoint(tmp_path / "ck")
    checkpoint.start({"steps": 3})
    curve = pd.DataFrame({"axial_strain": [0.0, 0.1 / 3, np.nextafter(0.2, 1)],
                          "rve": np.array([0, 0, 0], dtype=np.int32)})
    checkpoint.save_table("curve", curve)
    back = checkpoint.load_table("curve")
    pd.testing.assert_frame_equal(back, curve, check_exact=True)
    assert checkpoint.load_table("other") is None
    assert checkpoint.read_options() == {"steps": 3} and not checkpoint.has_state()
    with pytest.raises(CheckpointError, match="no committed state"):
        checkpoint.load()
    checkpoint.remove()
    assert not (tmp_path / "ck").exists()
    with pytest.raises(CheckpointError, match=r"options\.json is missing"):
        checkpoint.read_options()
    with pytest.raises(ValueError, match="integer >= 1"):
        RunCheckpoint(tmp_path, every=0)


@pytest.mark.parametrize("kind", ["linear-elastic", "dem-restart", "dem-continue-reuse"])
def test_resume_in_process_equals_a_run_that_never_stopped(kind, rve64, tmp_path):
    whole = _material(kind, rve64)
    whole.allocate(SETUP.n_points)
    full = _run(kind, whole, 7, checkpoint=RunCheckpoint(tmp_path / "full"))
    assert full.error is None and full.resumed_from is None

    checkpoint = RunCheckpoint(tmp_path / "part", every=3)
    first = _material(kind, rve64)
    first.allocate(SETUP.n_points)
    stopped = _run(kind, first, 7, checkpoint=checkpoint, on_step=StopAtStep(5))
    assert "interrupted after load step 5 of 7" in stopped.error
    assert isinstance(stopped.interrupt, KeyboardInterrupt)
    assert (checkpoint.folder / "steps" / "step_00005.npz").is_file()

    again = _material(kind, rve64)  # a new process: nothing allocated
    resumed = _run(kind, again, 7, checkpoint=checkpoint, resume=True)
    assert resumed.error is None and resumed.resumed_from == 3  # the last saved state
    pd.testing.assert_frame_equal(without_clock(resumed.steps), without_clock(full.steps),
                                  check_exact=True)
    pd.testing.assert_frame_equal(resumed.points, full.points, check_exact=True)
    np.testing.assert_array_equal(resumed.displacements, full.displacements)
    pd.testing.assert_frame_equal(_records(resumed), _records(full), check_exact=True)
    assert _same_arrays(checkpoint.folder / "material_00007.npz",
                        tmp_path / "full" / "material_00007.npz")


def test_load_keeps_the_last_whole_checkpoint(rve64, tmp_path):
    checkpoint = RunCheckpoint(tmp_path / "ck", every=2)
    material = _material("linear-elastic", rve64)
    material.allocate(SETUP.n_points)
    _run("linear-elastic", material, 6, checkpoint=checkpoint, on_step=StopAtStep(3))
    saved = checkpoint.load()
    assert saved.step == 2 and [s.row["step"] for s in saved.steps] == [0, 1, 2]
    assert not (checkpoint.folder / "steps" / "step_00003.npz").exists()  # past the state
    assert saved.material_path.name == "material_00002.npz"
    saved.material_path.unlink()
    with pytest.raises(CheckpointError, match="incomplete"):
        checkpoint.load()


# -- the commands ---------------------------------------------------------------------------
SINGLE = ["single-element", "--steps", "6", "--axial-strain", "0.003", "--device", "cpu",
          "--no-progress"]


def _main(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, dict | None, str]:
    code = main([*argv, "--json"])
    captured = capsys.readouterr()
    return code, json.loads(captured.out) if captured.out.strip() else None, captured.err


def test_resume_checks_the_options(rve64, tmp_path, capsys):
    out = tmp_path / "run"
    argv = [*SINGLE, "--rve", str(rve64)]
    code, report, _ = _main(capsys, *argv, "--out", str(out))
    assert code == 0 and report["resumed_from_step"] is None
    code, _, err = _main(capsys, *argv, "--steps", "7", "--resume", str(out))
    assert code == 2 and "--steps 7 (the run had 6)" in err
    code, _, err = _main(capsys, "biaxial", "--elements", "1", "1", "--rve", str(rve64),
                         "--device", "cpu", "--resume", str(out))
    assert code == 2 and "is a single-element run, not biaxial" in err
    code, _, err = _main(capsys, *argv, "--resume", str(out), "--out", str(tmp_path / "x"))
    assert code == 2 and "names another" in err
    # the finished run resumes to itself; checkpoint spacing and threads may change
    code, report, _ = _main(capsys, *argv, "--resume", str(out), "--checkpoint-every", "4",
                            "--shards", "1")
    assert code == 0 and report["resumed_from_step"] == 6 and report["steps_completed"] == 6


def test_resume_of_a_folder_without_checkpoint_starts_the_run(rve64, tmp_path, capsys):
    out = tmp_path / "new"
    code, report, err = _main(capsys, *SINGLE, "--rve", str(rve64), "--resume", str(out))
    assert code == 0 and report["resumed_from_step"] is None
    assert "starts from the beginning" in err
    assert (out / "checkpoint" / "state.npz").is_file() and (out / "steps.csv").is_file()


def test_rejected_run_leaves_no_checkpoint(tmp_path, capsys):
    new = tmp_path / "new"
    code, _, _ = _main(capsys, "single-element", "--material", "linear-elastic", "--rtol",
                       "-1", "--out", str(new / "deeper"))
    assert code == 2 and not new.exists()


# -- signals, in a process of its own -------------------------------------------------------
def _command(rve: Path, out_option: str, out: Path, steps: int = 24) -> list[str]:
    return [sys.executable, "-m", "granular_material.cli", "single-element", "--rve",
            str(rve), "--steps", str(steps), "--axial-strain", "0.006", "--device", "cpu",
            "--no-progress", "--json", "--drive", "continue", "--checkpoint-every", "2",
            "--track", "0", "--every", "5", out_option, str(out)]


def _assert_same_run(out: Path, reference: Path, steps: int = 24) -> None:
    for table in ("steps.csv", "points.csv", "tracked.csv"):
        pd.testing.assert_frame_equal(without_clock(run_table(out, table)),
                                      without_clock(run_table(reference, table)),
                                      check_exact=True, obj=table)
    name = f"material_{steps:05d}.npz"
    assert _same_arrays(out / "checkpoint" / name, reference / "checkpoint" / name)
    for figure in ("stress_strain.png", "maps.png", "fields.xdmf"):
        assert (out / figure).is_file()


@pytest.fixture(scope="module")
def reference_run(rve64, tmp_path_factory) -> tuple[Path, float]:
    """The uninterrupted run the signal tests compare with, and its duration [s] (start-up
    and figures included)."""
    out = tmp_path_factory.mktemp("reference") / "run"
    started = time.monotonic()
    done = subprocess.run(_command(rve64, "--out", out), capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    return out, time.monotonic() - started


def _wait_for(path: Path, process: subprocess.Popen, timeout: float = 300) -> None:
    end = time.monotonic() + timeout
    while not path.exists():
        assert process.poll() is None, "the run ended before the file appeared"
        assert time.monotonic() < end, f"{path} did not appear"
        time.sleep(0.02)


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
@pytest.mark.parametrize(("stop", "code"), [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_stopped_run_keeps_its_work_and_resumes(stop, code, rve64, reference_run,
                                                  tmp_path):
    """SIGTERM (a scheduler's stop) and SIGINT (Ctrl-C): the shell's exit code, the tables,
    figures and summary of the steps done, the --resume line, no traceback; the resumed run
    is the reference."""
    out = tmp_path / "run"
    # as from a terminal: a job a shell starts in the background has SIGINT ignored, and
    # Python then keeps it ignored; the run must get Ctrl-C as it would in the foreground
    process = subprocess.Popen(_command(rve64, "--out", out), stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    _wait_for(out / "checkpoint" / "steps" / "step_00007.npz", process)
    process.send_signal(stop)
    stdout, stderr = process.communicate(timeout=300)
    assert process.returncode == code, stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["error"].startswith("interrupted after load step")
    assert json.loads(stdout) == summary
    assert f"--resume {out}" in stderr and "Traceback" not in stderr
    assert (out / "stress_strain.png").is_file()  # the figures of the steps done
    assert len(pd.read_csv(out / "steps.csv")) == summary["steps_completed"] + 1
    done = subprocess.run(_command(rve64, "--resume", out), capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["resumed_from_step"] >= 6
    _assert_same_run(out, reference_run[0])


def test_sigkill_at_random_moments_resumes_to_the_same_run(rve64, reference_run, tmp_path):
    """Ten or more SIGKILLs at random moments (seeded), each followed by ``--resume`` until
    the run ends; the first moment of a chain falls in the first third of a whole run
    (start-up, before anything is saved, included), the others anywhere in it. A run that
    ends before its moment ends its chain; the next starts in a new folder. Every chain
    ends with the tables and RVEs of the reference."""
    rng = random.Random(12)
    span = reference_run[1]
    kills, kills_before_a_save, chains = 0, 0, 0
    while kills < 10:
        out = tmp_path / f"run{chains}"
        chains += 1
        argv, moment = _command(rve64, "--out", out), rng.uniform(0.0, span / 3)
        while True:
            process = subprocess.Popen(argv, stdout=subprocess.PIPE,
                                       stderr=subprocess.PIPE, text=True)
            try:
                process.wait(timeout=moment if kills < 10 else None)
            except subprocess.TimeoutExpired:
                process.kill()
            _, stderr = process.communicate(timeout=600)
            if process.returncode != -signal.SIGKILL:
                assert process.returncode == 0, stderr  # it ended before its moment came
                break
            kills += 1
            kills_before_a_save += not (out / "checkpoint" / "state.npz").is_file()
            argv, moment = _command(rve64, "--resume", out), rng.uniform(0.0, span)
        _assert_same_run(out, reference_run[0])
        assert not list(out.glob("**/*.part"))
    print(f"{kills} SIGKILLs ({kills_before_a_save} before the first save) in {chains} "
          "chains")
    assert kills_before_a_save < kills, "no kill came after the first saved step"


def test_a_fresh_run_is_refused_over_a_stopped_runs_checkpoint(tmp_path, capsys):
    """Only ``--resume`` continues a stopped run's work: a plain rerun into its folder is
    refused (exit 2) and changes nothing; a finished run's folder may be run again."""
    out = tmp_path / "le"
    argv = ["single-element", "--material", "linear-elastic", "--steps", "4",
            "--axial-strain", "0.004", "--device", "cpu", "--no-progress", "--json",
            "--out", str(out)]
    assert main(argv) == 0
    assert main(argv) == 0  # finished: run again
    capsys.readouterr()
    options = out / "checkpoint" / "options.json"
    record = json.loads(options.read_text())
    record["spec"]["problem"]["steps"] = 8  # as if it had stopped after step 4 of 8
    options.write_text(json.dumps(record))
    before = {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "stopped after load step 4 of 8" in err and "--resume" in err
    assert {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()} == before


def test_the_refusal_over_a_failed_runs_checkpoint_says_it_cannot_be_resumed(tmp_path,
                                                                             capsys):
    """A run that failed (its summary's error, written after its last saved state) is not
    offered --resume: another folder, or its checkpoint removed; a summary older than the
    state (an earlier run's) leaves the folder a stopped run's."""
    out = tmp_path / "le"
    argv = ["single-element", "--material", "linear-elastic", "--steps", "4",
            "--axial-strain", "0.004", "--device", "cpu", "--no-progress", "--json",
            "--out", str(out)]
    assert main(argv) == 0
    capsys.readouterr()
    options = out / "checkpoint" / "options.json"
    record = json.loads(options.read_text())
    record["spec"]["problem"]["steps"] = 8  # as if it had failed at step 5 of 8
    options.write_text(json.dumps(record))
    summary = json.loads((out / "summary.json").read_text())
    summary["error"] = "load step 5 (load factor 0.5 -> 0.625) did not converge"
    (out / "summary.json").write_text(json.dumps(summary))
    before = {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "a run that failed (load step 5" in err and "cannot be resumed" in err
    assert "another folder" in err and "--resume" not in err
    assert {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()} == before
    with pytest.raises(ParameterError, match=r"cannot be resumed.*run\(spec, fresh=True\)"):
        execute_run(from_dict(record["spec"]))
    state = (out / "checkpoint" / "state.npz").stat().st_mtime_ns
    os.utime(out / "summary.json", ns=(state - 10**9, state - 10**9))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "stopped after load step 4 of 8" in err and "--resume" in err
