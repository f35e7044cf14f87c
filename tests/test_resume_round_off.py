"""A run killed right after the state of a load step is saved and resumed gives the steps of a
run that never stopped, bit for bit, also the relative residuals of the next step: the
checkpoint keeps the internal force the step assembled (from the step before's ∇u plus its
increment's), where one assembled anew from the total ∇u differed at round-off (the 4 × 8
Mohr–Coulomb specimen killed after step 30 resumed with step 31's first residual ratio one
digit off in its last place)."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

from granular_material.cli import main

_OPTIONS = ["biaxial", "--material", "mohr-coulomb", "--friction-angle", "35",
            "--critical-friction-angle", "28", "--softening-strain", "0.02",
            "--dilation-angle", "5", "--platens", "rough", "--axial-strain", "0.05",
            "--steps", "50", "--elements", "4", "8", "--no-progress",
            "--checkpoint-every", "1"]  # the state of step 30 saved, whatever the clock

_DIE_AFTER = """
import os, sys
from granular_material.cli import main
from granular_material.runs import checkpoint
real = checkpoint.RunCheckpoint.save_state
def save_state(self, step, solver, material):
    real(self, step, solver, material)
    if step == int(sys.argv[1]):
        os._exit(137)  # as a SIGKILL right after the save
checkpoint.RunCheckpoint.save_state = save_state
main(sys.argv[3:] + ["--out", sys.argv[2]])
"""


def _rows(path: Path) -> list[list[str]]:
    """``steps.csv`` without its wall times."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    clock = rows[0].index("wall_time")
    return [row[:clock] + row[clock + 1:] for row in rows]


def test_a_run_killed_after_a_save_resumes_to_the_same_residuals(tmp_path):
    assert main([*_OPTIONS, "--out", str(tmp_path / "whole")]) == 0
    stopped = tmp_path / "stopped"
    done = subprocess.run([sys.executable, "-c", _DIE_AFTER, "30", str(stopped), *_OPTIONS],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 137, done.stderr[-2000:]
    assert main([*_OPTIONS, "--resume", str(stopped)]) == 0
    assert _rows(stopped / "steps.csv") == _rows(tmp_path / "whole" / "steps.csv")
    for name in ("points.npy", "fields.xdmf", "fields.h5"):
        assert (stopped / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()
