"""Wall-clock seconds by phase: what a run spent preparing RVEs, stepping discs,
homogenising, assembling, solving, writing tables and checkpoints.

A :class:`PhaseTimes` is filled by whoever does the work (``with times.phase("dem"): ...``)
and read as a plain mapping of phase name to seconds. Phases nest freely: a phase's seconds
include those of phases timed inside it, so a report that wants the parts to sum to the
whole subtracts the inner ones (:func:`phase_table` does, for the run's phases).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator, Mapping

__all__ = ["MATERIAL_PHASES", "RUN_PHASES", "PhaseTimes", "phase_table"]


class PhaseTimes:
    """Seconds [s] spent by phase name, summed over every time the phase was entered."""

    def __init__(self, seconds: Mapping[str, float] | None = None) -> None:
        self.seconds: dict[str, float] = {}
        if seconds:
            self.add_all(seconds)

    def add(self, name: str, seconds: float) -> None:
        """Count ``seconds`` [s] more for phase ``name``."""
        self.seconds[name] = self.seconds.get(name, 0.0) + float(seconds)

    def add_all(self, seconds: Mapping[str, float]) -> None:
        """Count every phase of ``seconds`` (name → s) more."""
        for name, value in seconds.items():
            self.add(name, value)

    @contextlib.contextmanager
    def phase(self, name: str) -> Iterator[None]:
        """Time the block as phase ``name`` (counted even when the block raises)."""
        start = time.perf_counter()
        try:
            yield
        finally:
            self.add(name, time.perf_counter() - start)

    def as_dict(self) -> dict[str, float]:
        """A copy of the seconds by phase."""
        return dict(self.seconds)


#: the phases of a FEM run, in the order a report lists them, with what each holds; the
#: ``*_other`` phases are what their enclosing phase spent outside the phases listed in it
RUN_PHASES: dict[str, str] = {
    "preparation": "preparing (or loading) the RVEs before the first step",
    "reference": "the pure-DEM reference curve of a single element",
    "initial_state": "the material's response in its initial state (step 0)",
    "dem": "stepping the RVEs' discs along their ∇u paths",
    "homogenization": "Love stress, the Kruyt-Rothenburg tangent and fabric of the RVEs",
    "tangent": "the tangent on top of them (objective, condensed)",
    "material_other": "the rest of the material's evaluations (transfers, checks)",
    "assembly": "stiffness matrix, internal and external forces, boundary conditions",
    "linear_solve": "the sparse linear solves of Newton's corrections",
    "newton_other": "the rest of the load steps (gradients, norms, predictor)",
    "tables": "each committed step's table rows, written and saved for a resume",
    "tracking": "post-processing the tracked points' RVEs",
    "checkpoint": "saving the committed state (the RVEs) for a resume",
    "outputs": "the figures, maps and fields written at the end",
}

#: the phases a material reports inside its evaluations (timed by the Newton solver as
#: ``material``), as the DEM material's backends time them
MATERIAL_PHASES = ("dem", "homogenization", "tangent")


def phase_table(seconds: Mapping[str, float], total: float) -> dict[str, float]:
    """The run's seconds [s] by :data:`RUN_PHASES` (parts that sum to the whole) from raw
    phase times: ``material`` (the whole of the material's evaluations) and ``steps`` (the
    whole of the load steps' Newton work) are split into their parts and the other phases
    they hold; ``total`` [s] is the run's wall time, whose unaccounted rest is ``other``."""
    raw = dict(seconds)
    inner = sum(raw.get(name, 0.0) for name in MATERIAL_PHASES)
    material = raw.pop("material", inner)
    steps = raw.pop("steps", None)
    table = {name: raw.get(name, 0.0) for name in RUN_PHASES}
    table["material_other"] = max(material - inner, 0.0)
    if steps is not None:
        newton = material + table["assembly"] + table["linear_solve"]
        table["newton_other"] = max(steps - newton, 0.0)
    # a phase the run never entered is left out; one it entered is listed, however short
    table = {name: value for name, value in table.items() if value > 0.0}
    table["other"] = max(total - sum(table.values()), 0.0)
    table["total"] = float(total)
    return table
