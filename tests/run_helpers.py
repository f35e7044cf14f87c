"""Helpers shared by the tests that stop and resume FEM runs."""

from __future__ import annotations

import pandas as pd

#: columns that hold clock times, which differ between equal runs
CLOCK = ("wall_time", "seconds")


def without_clock(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` without its clock-time columns."""
    return frame.drop(columns=[c for c in frame.columns if any(k in c for k in CLOCK)])


class StopAtStep:
    """``on_step`` callback of ``run_biaxial``: Ctrl-C once load step ``step`` is committed."""

    def __init__(self, step: int) -> None:
        self.step = step

    def __call__(self, solver, record, points) -> None:
        if record.step == self.step:
            raise KeyboardInterrupt
