"""Fig. 11 of Wu et al. (2025): the batched DEM against stepping the same RVEs one at a time.

For each RVE size and number of RVEs B, the same packing copied B times is sheared at 10⁻⁵
strain a step (neighbour lists rebuilt as in a real run) as one batch, and, for the serial
reference, one copy alone on one thread: serial time for B RVEs = B × that. The speed-up is
their ratio for the same number of DEM steps; times are medians of ``repeats`` and are
given for the paper's 10⁴ steps (scaled from the steps timed when fewer). One YADE core
stepping the same 400-disc packing gives the rate of the code most users know.
"""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path

import numpy as np
import pandas as pd

from granular_material.dem import DEMBatch, RVEData, load_rve
from granular_material.procedures import progress_bar
from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP

from .scales import ReproductionScale

__all__ = ["PAPER_STEPS", "speedup_table", "step_time", "yade_rate"]

#: DEM steps of Wu et al.'s timing
PAPER_STEPS = 10_000


def step_time(data: RVEData, steps: int, device: str, shards: int | None = None) -> float:
    """Seconds per DEM step of the batch ``data`` sheared at 10⁻⁵ strain a step, after a
    warm-up of 20 steps (kernels loaded, lists built)."""
    batch = DEMBatch(data, device=device, shards=shards)
    shear = np.zeros((batch.n_rve, 2, 2))
    shear[:, 0, 1] = DEFAULT_STRAIN_PER_STEP / batch.dt
    batch.set_affine(shear)
    batch.run(20)
    started = time.perf_counter()
    batch.run(steps, check_every=min(steps, 500))
    return (time.perf_counter() - started) / steps


def speedup_table(scale: ReproductionScale, rve_files: dict[int, Path], device: str,
                  progress: bool = False) -> pd.DataFrame:
    """One row per RVE size and B: discs, rves, batched and serial seconds for 10⁴ steps,
    speed_up, batched particle-steps/s, device, steps timed."""
    rows = []
    cases = len(scale.speedup_sizes) * (len(scale.speedup_batches) + 1)
    with progress_bar(cases, "speed-up", progress, unit="case") as bar:
        for discs in scale.speedup_sizes:
            one = load_rve(rve_files[discs]).take([0])
            serial = statistics.median(step_time(one, scale.speedup_steps, device, shards=1)
                                       for _ in range(scale.repeats))
            bar.update(1)
            for n_rve in scale.speedup_batches:
                batched = statistics.median(
                    step_time(one.replicate(n_rve), scale.speedup_steps, device)
                    for _ in range(scale.repeats))
                rows.append({"discs": discs, "rves": n_rve,
                             "batched_s": batched * PAPER_STEPS,
                             "serial_s": serial * n_rve * PAPER_STEPS,
                             "speed_up": serial * n_rve / batched,
                             "particle_steps_per_s": n_rve * discs / batched,
                             "serial_particle_steps_per_s": discs / serial,
                             "steps_timed": scale.speedup_steps, "device": device})
                bar.update(1)
    return pd.DataFrame(rows)


def yade_rate(rve_file: Path, steps: int) -> float | None:
    """Particle-steps per second of one YADE core stepping RVE 0 of ``rve_file``; None when
    ``steps`` is 0 or YADE is not installed."""
    if steps <= 0:
        return None
    from granular_material_validation.yade_runner import yade_throughput

    rate = yade_throughput(rve_file, steps)
    return None if rate is None or not math.isfinite(rate) else float(rate)
