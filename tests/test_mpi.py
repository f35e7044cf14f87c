"""The MPI backend (issue 16): RVE shards on the ranks of ``mpiexec -n K`` give the in-process
run's tables bit for bit; a failing rank stops every rank with its error named, never a
hang; a run stopped that way resumes from its checkpoint on another number of ranks.

The runs need mpi4py and an ``mpiexec`` (``pip install granular-material[mpi]``); without
them they are skipped. Every run is a subprocess with a timeout whose whole process group is
killed when it expires, so that a hang fails the test instead of blocking it.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import signal
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from run_helpers import run_table

from granular_material.dem import DEMBatch, Homogenized, load_rve, save_rve
from granular_material.multiscale.mpi import (
    FAULT_VARIABLE,
    HEADER,
    ROW,
    message_bytes,
    shard_bounds,
)
from granular_material.multiscale.mpi_wire import _pack, _unpack
from granular_material.procedures import drive_grad_u, prepare_packing


def _find_mpiexec() -> str | None:
    """The mpiexec beside this Python (the mpich wheel's) or on PATH; None without mpi4py."""
    if importlib.util.find_spec("mpi4py") is None:
        return None
    beside = Path(sys.executable).parent / "mpiexec"
    return str(beside) if beside.is_file() else shutil.which("mpiexec")


MPIEXEC = _find_mpiexec()
needs_mpi = pytest.mark.skipif(
    MPIEXEC is None,
    reason="the MPI backend needs mpi4py and mpiexec: pip install 'granular-material[mpi]'")

#: the clock columns of the tables, the only ones two runs may differ in
CLOCK = ("wall_time", "seconds", "timings")
#: summary entries that are clock times or the output folder
SUMMARY_FREE = ("wall_time_s", "tracking_time_s", "timing_s", "out")
#: seconds any one run may take before it counts as a hang (a whole run takes about 10-20 s)
TIMEOUT = 240

SINGLE = ["single-element", "--steps", "5", "--axial-strain", "0.005", "--device", "cpu",
          "--no-progress", "--json"]
BIAXIAL = ["biaxial", "--elements", "1", "2", "--steps", "5", "--axial-strain", "0.005",
           "--device", "cpu", "--no-progress", "--json", "--drive", "continue",
           "--track", "0", "5", "--every", "2", "--checkpoint-every", "1"]


def _environment(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env.pop(FAULT_VARIABLE, None)
    # Open MPI refuses root and more ranks than cores unless told; MPICH needs neither
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1",
               PRTE_MCA_rmaps_default_mapping_policy=":oversubscribe")
    env.update(extra)
    return env


def _run(argv: list[str], ranks: int | None = None, **env: str
         ) -> subprocess.CompletedProcess[str]:
    """``granular-material argv`` in process with two CPU shards (``ranks`` None) or under
    ``mpiexec -n ranks`` with ``--backend mpi`` and one thread a rank (so that two ranks
    group the RVEs as the two in-process shards do, on any machine); a run past TIMEOUT is
    killed with its process group and fails."""
    command = [sys.executable, "-m", "granular_material.cli", *argv]
    if ranks is None:
        command += ["--shards", "2"]
    else:
        assert MPIEXEC is not None
        command = [MPIEXEC, "-n", str(ranks), *command, "--backend", "mpi", "--shards", "1"]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, env=_environment(**env), start_new_session=True)
    try:
        stdout, stderr = process.communicate(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        stdout, stderr = process.communicate()
        pytest.fail(f"{' '.join(command)} hung for {TIMEOUT} s:\n{stderr[-3000:]}")
    return subprocess.CompletedProcess(command, process.returncode, stdout, stderr)


def _without_clock(frame: pd.DataFrame) -> pd.DataFrame:
    return frame.drop(columns=[c for c in frame.columns if any(k in c for k in CLOCK)])


def _assert_same_tables(out: Path, reference: Path) -> None:
    for table in ("steps.csv", "points.csv", "tracked.csv"):
        if table != "points.csv" and not (reference / table).is_file():
            continue
        pd.testing.assert_frame_equal(_without_clock(run_table(out, table)),
                                      _without_clock(run_table(reference, table)),
                                      check_exact=True, obj=table)


def _summary(run: subprocess.CompletedProcess[str]) -> dict:
    return {k: v for k, v in json.loads(run.stdout).items() if k not in SUMMARY_FREE}


#: arrays of the RVE file that hold the discs' state and what the backend carries; of the
#: others, the contact slots in use must agree too, while the rest is contact-list
#: bookkeeping (when a list was last rebuilt, stale slots), which follows how the RVEs are
#: grouped into shards and never changes a result
STATE_KEYS = ("radius", "position", "cell", "velocity", "angular_velocity",
              "fractional_position", "contact_count")


def _assert_same_state(a: Path, b: Path, every_array: bool) -> None:
    with np.load(a) as x, np.load(b) as y:
        assert set(x.files) == set(y.files)
        keys = x.files if every_array else [k for k in x.files
                                             if k in STATE_KEYS or k.startswith("backend_")]
        for key in keys:
            np.testing.assert_array_equal(x[key], y[key], err_msg=key)
        slots = x["contact_partner"].shape[-1]
        live = np.arange(slots) < x["contact_count"][..., None]
        for key in ("contact_partner", "contact_shear_force"):
            np.testing.assert_array_equal(x[key][live], y[key][live], err_msg=key)


@pytest.fixture(scope="module")
def rve_files(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """RVE files of 4 and 8 independent 64-disc RVEs (seed 1, 100 kPa)."""
    folder = tmp_path_factory.mktemp("rves")
    files = {}
    for n in (4, 8):
        files[n] = folder / f"rve{n}.npz"
        save_rve(files[n], prepare_packing(n_disc=64, n_rve=n, seed=1, pressure=100e3,
                                           device="cpu").to_data())
    return files


@pytest.fixture(scope="module")
def single_reference(rve_files, tmp_path_factory) -> tuple[Path, dict]:
    """The in-process single element (4 points) the MPI runs are compared with."""
    out = tmp_path_factory.mktemp("single") / "inprocess"
    run = _run([*SINGLE, "--rve", str(rve_files[4]), "--out", str(out)])
    assert run.returncode == 0, run.stderr
    return out, _summary(run)


@pytest.fixture(scope="module")
def biaxial_reference(rve_files, tmp_path_factory) -> tuple[Path, dict]:
    """The in-process reduced biaxial (1 x 2 elements, 8 points, driven on, two points
    tracked) the MPI runs are compared with."""
    out = tmp_path_factory.mktemp("biaxial") / "inprocess"
    run = _run([*BIAXIAL, "--rve", str(rve_files[8]), "--out", str(out)])
    assert run.returncode == 0, run.stderr
    return out, _summary(run)


# -- without MPI ------------------------------------------------------------------------------
def test_rows_carry_every_homogenised_field_exactly(small_rve_path):
    batch = DEMBatch(load_rve(small_rve_path).replicate(3), device="cpu", shards=1)
    drive_grad_u(batch, np.array([[1e-4, 0.0], [0.0, -2e-4]]))
    h = batch.homogenize()
    failed = np.array([False, True, True])
    rows = _pack(h, failed, np.array(["", "max_dem_steps", "blow_up"], dtype=object))
    assert rows.shape == (3, ROW) and rows.dtype == np.float64 and ROW == 31
    back, back_failed, reasons = _unpack(rows)
    np.testing.assert_array_equal(back_failed, failed)
    assert reasons.tolist() == ["", "max_dem_steps", "blow_up"]
    for f in fields(Homogenized):
        mine, theirs = getattr(back, f.name), np.asarray(getattr(h, f.name))
        assert mine.dtype == theirs.dtype and mine.shape == theirs.shape, f.name
        np.testing.assert_array_equal(mine, theirs, err_msg=f.name)


def test_shards_are_contiguous_and_balanced():
    np.testing.assert_array_equal(shard_bounds(8, 3), [0, 3, 6, 8])
    np.testing.assert_array_equal(shard_bounds(4, 2), [0, 2, 4])
    np.testing.assert_array_equal(shard_bounds(2, 4), [0, 1, 2, 2, 2])  # ranks without RVEs


def test_message_sizes_follow_the_layout():
    sizes = message_bytes(600, 4)
    assert sizes["grad_u"] == 600 * 4 * 8 and sizes["rows"] == 600 * ROW * 8
    assert sizes["header"] == 4 * HEADER * 8 and sizes["command"] == 3 * 16
    assert sizes["total"] == sum(v for k, v in sizes.items() if k != "total")


# -- under mpiexec ----------------------------------------------------------------------------
@needs_mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_single_element_on_ranks_is_the_in_process_run(ranks, rve_files, single_reference,
                                                       tmp_path):
    reference, summary = single_reference
    out = tmp_path / "mpi"
    run = _run([*SINGLE, "--rve", str(rve_files[4]), "--out", str(out)], ranks)
    assert run.returncode == 0, run.stderr
    assert _summary(run) == summary
    assert json.loads((out / "summary.json").read_text())["steps_completed"] == 5
    _assert_same_tables(out, reference)
    # two ranks hold the two CPU shards of the in-process batch: the file is the same too
    name = Path("checkpoint") / "material_00005.npz"
    _assert_same_state(out / name, reference / name, every_array=ranks == 2)


@needs_mpi
def test_prepared_rves_of_a_material_on_two_ranks_are_the_in_process_ones(tmp_path):
    """The RVE material options reach the RVEs the run prepares under MPI too: the same
    tables as in process, and the checkpoint's RVEs carry the friction and damping given."""
    argv = ["single-element", "--particles", "24", "--independent", "--steps", "1",
            "--axial-strain", "0.001", "--device", "cpu", "--no-progress", "--json",
            "--contact-friction-angle", "0.3", "--damping", "0.2", "--radius-min", "4e-3"]
    runs = {}
    for ranks in (None, 2):
        out = tmp_path / f"ranks{ranks}"
        run = _run([*argv, "--out", str(out)], ranks)
        assert run.returncode == 0, run.stderr
        runs[ranks] = _summary(run)
    assert runs[2] == runs[None] and runs[2]["rve_material"]["friction_angle"] == 0.3
    _assert_same_tables(tmp_path / "ranks2", tmp_path / "ranksNone")
    rves = load_rve(tmp_path / "ranks2" / "checkpoint" / "material_00001.npz")
    assert (rves.meta.friction_angle, rves.meta.damping) == (0.3, 0.2)
    assert rves.radius.min() >= 4e-3


@needs_mpi
def test_biaxial_on_two_ranks_is_the_in_process_run(rve_files, biaxial_reference, tmp_path):
    reference, summary = biaxial_reference
    out = tmp_path / "mpi"
    run = _run([*BIAXIAL, "--rve", str(rve_files[8]), "--out", str(out)], 2)
    assert run.returncode == 0, run.stderr
    assert _summary(run) == summary and summary["tracked_rows"] == 6
    _assert_same_tables(out, reference)
    # the ranks' phases reach the summary: the slowest rank's DEM and homogenisation, a
    # part of the material's time as in process
    timing = json.loads((out / "summary.json").read_text())["timing_s"]
    assert timing["dem"] > 0 and timing["homogenization"] > 0
    assert timing["dem"] + timing["homogenization"] < timing["total"]


@needs_mpi
def test_a_failing_rank_stops_every_rank_and_the_run_resumes_on_three(
        rve_files, biaxial_reference, tmp_path):
    reference, summary = biaxial_reference
    out = tmp_path / "mpi"
    argv = [*BIAXIAL, "--rve", str(rve_files[8])]
    # rank 1 raises at its 12th evaluation (in load step 2 or 3): every rank stops
    failed = _run([*argv, "--out", str(out)], 2, **{FAULT_VARIABLE: "1:12"})
    assert failed.returncode == 1, failed.stderr
    assert "MPI rank 1 failed in evaluate" in failed.stderr
    assert f"fault injected by {FAULT_VARIABLE} at evaluation 12" in failed.stderr
    assert failed.stdout == ""  # no rank printed a summary
    saved = sorted((out / "checkpoint" / "steps").glob("step_*.npz"))
    assert 1 <= len(saved) - 1 < 5
    resumed = _run([*argv, "--resume", str(out)], 3)
    assert resumed.returncode == 0, resumed.stderr
    report = _summary(resumed)
    assert report.pop("resumed_from_step") == len(saved) - 1
    assert report == {k: v for k, v in summary.items() if k != "resumed_from_step"}
    _assert_same_tables(out, reference)
    name = Path("checkpoint") / "material_00005.npz"
    _assert_same_state(out / name, reference / name, every_array=False)


@needs_mpi
def test_rank_0_failing_stops_the_workers(rve_files, tmp_path):
    run = _run([*SINGLE, "--rve", str(rve_files[4]), "--steps", "1"], 3,
               **{FAULT_VARIABLE: "0:2"})
    assert run.returncode == 1, run.stderr
    assert "MPI rank 0 failed in evaluate: RuntimeError: fault injected" in run.stderr


#: run under mpiexec: every rank counts its condensations while rank 0 holds the tangent for
#: two evaluations, commits, and evaluates once more; each rank writes its count to argv[2]
_HOLD_SCRIPT = """
import sys
from pathlib import Path

import numpy as np
import granular_material.multiscale.backend as backend
from granular_material.dem.homogenization import spin_tangent
from granular_material.multiscale.mpi import MPIBackend, launch
from granular_material.multiscale.parameters import DEMMaterialParameters
from granular_material.dem import load_rve

condensations = 0
condense = backend.condense


def counting(*args, **kwargs):
    global condensations
    condensations += 1
    return condense(*args, **kwargs)


backend.condense = counting


def main():
    data = load_rve(sys.argv[1])
    rves = MPIBackend(data, DEMMaterialParameters(tangent="condensed", device="cpu",
                                                  shards=1, backend="mpi"))
    grad_u = np.tile(np.array([[0.0, 1e-4], [0.0, -2e-4]]), (data.n_rve, 1, 1))
    rves.hold_tangent(True)
    first = rves.evaluate(grad_u)
    second = rves.evaluate(1.5 * grad_u)  # the held tangent, with the new stress's spin
    rves.commit()  # ends the hold: the next evaluation condenses
    rves.evaluate(grad_u)

    def without_spin(ev):
        s = np.asarray(ev.homogenized.stress)
        spin = spin_tangent(0.5 * (s + s.transpose(0, 2, 1)))
        return np.asarray(ev.homogenized.tangent) - spin

    assert np.array_equal(without_spin(first), without_spin(second)), "the tangent changed"
    return 0


code = launch(main)
from mpi4py import MPI
Path(sys.argv[2], f"rank{MPI.COMM_WORLD.rank}").write_text(str(condensations))
sys.exit(code)
"""


@needs_mpi
def test_a_held_tangent_is_condensed_once_an_increment_on_every_rank(rve_files, tmp_path):
    """``hold_tangent`` reaches every rank: with it on, a rank condenses its RVEs at the
    first evaluation only and returns that tangent for the second; after a commit it
    condenses again. Two condensations a rank for three evaluations."""
    script = tmp_path / "hold.py"
    script.write_text(_HOLD_SCRIPT)
    command = [MPIEXEC, "-n", "2", sys.executable, str(script), str(rve_files[4]),
               str(tmp_path)]
    run = subprocess.run(command, capture_output=True, text=True, env=_environment(),
                         timeout=TIMEOUT)
    assert run.returncode == 0, run.stderr
    assert [(tmp_path / f"rank{r}").read_text() for r in (0, 1)] == ["2", "2"]
