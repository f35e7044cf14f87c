"""The trade study's band rows: the knobs that decide whether, when and where a biaxial
specimen's shear band forms, each run on several sets of RVEs and scored by the band's
measures (:mod:`granular_material.results.band_measures`) against the commands' defaults.

A row is one setting: what it changes from the commands' defaults, in the presets' terms (the
``reference`` row changes nothing). Each row runs once per seed of its scale (seed k gives
the specimen's RVEs k, k + 1, …: seeds far apart are independent sets of RVEs), each run
into its own folder under ``band/runs/`` (done once it has ended there, so a restarted study
skips it and continues an interrupted one). Runs go ``jobs`` at a time, each in its own process.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from granular_material.fem.solver.defaults import COMMAND_DEFAULTS, NOISY_DEFAULTS
from granular_material.multiscale.run_hooks import RUN_TANGENT
from granular_material.procedures import progress_bar
from granular_material.procedures.packing import DEFAULT_PRESSURE
from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP
from granular_material.results import read_points, write_json
from granular_material.runs.presets import settings_fields
from granular_material.runs.run_folder import ended_summary, resumable

__all__ = ["BAND_SCALES", "FORCE_TEST", "NEWTON_KNOBS", "BandRow", "BandScale", "band_rows",
           "command_settings", "preset_band_row", "read_band_run", "row_key", "run_band_rows",
           "run_folder"]


@dataclass(frozen=True)
class BandScale:
    """The specimen of the band rows (``--scale``).

    Attributes:
        name: smoke or cpu.
        elements: (nx, ny) quad4 elements of the reference mesh.
        coarse_elements: the mesh knob's coarser mesh.
        discs: discs per RVE of the reference; disc_values: the discs knob's others.
        steps: load steps of the reference to ``axial_strain`` [-].
        seeds: first RVE seed of each set of RVEs (far enough apart to be independent), of
            the reference's and the presets' runs; knob_seeds: those of the other rows.
        confining: p0 [Pa].
        width, height: the specimen's [m].
    """

    name: str
    elements: tuple[int, int]
    coarse_elements: tuple[int, int]
    discs: int
    disc_values: tuple[int, ...]
    steps: int
    axial_strain: float
    seeds: tuple[int, ...]
    knob_seeds: tuple[int, ...]
    confining: float = DEFAULT_PRESSURE
    width: float = 0.05
    height: float = 0.10


BAND_SCALES: dict[str, BandScale] = {
    "smoke": BandScale("smoke", (1, 2), (1, 1), 36, (), 4, 0.02, (1, 101), (1,)),
    # the commands' reduced specimen (5 × 10 quad4 of 64 discs, 100 steps to 10 %): its
    # band forms at 2.42 ± 0.26 % with the defaults (3 sets of RVEs), in 4–7 min a run on
    # one core of this shared 2-core machine
    "cpu": BandScale("cpu", (5, 10), (3, 6), 64, (36,), 100, 0.10, (1, 1001, 2001),
                     (1, 1001)),
}


@dataclass(frozen=True)
class BandRow:
    """One setting of the band rows: its knob, the value shown, what it changes from the
    commands' defaults in the study's terms (:data:`~granular_material.runs.presets.SETTING_NAMES`,
    or a run-spec field such as ``steps``, ``elements``, ``accept_correction``), and the
    seeds it runs."""

    knob: str
    value: str
    settings: dict[str, Any]
    seeds: tuple[int, ...]

    @property
    def key(self) -> str:
        """The row's folder name (:func:`row_key` of its settings)."""
        return row_key(self.knob, self.value, self.settings)


def row_key(knob: str, value: str, changes: Any) -> str:
    """A study row's folder name: its knob and value; a preset's by what it changes (JSON
    values), so that two presets of equal changes share their runs."""
    if knob == "preset":
        text = json.dumps(changes, sort_keys=True, default=str)
        return f"preset-{hashlib.sha1(text.encode()).hexdigest()[:10]}"
    return f"{knob}-{value}".replace(" ", "_").replace("/", "-")


def command_settings() -> dict[str, Any]:
    """The commands' own settings of a DEM run in the study's terms: the band rows'
    reference (:mod:`granular_material.fem.solver.defaults`, the run tangent, Guo & Zhao's strain
    per DEM step, every trial from the committed state, no reuse)."""
    return {"strain_per_step": DEFAULT_STRAIN_PER_STEP,
            "convergence": COMMAND_DEFAULTS["convergence"], "rtol": COMMAND_DEFAULTS["rtol"],
            "stress_floor": None, "tangent": RUN_TANGENT,
            "tangent_update": NOISY_DEFAULTS["tangent_update"],
            "acceleration": f"{COMMAND_DEFAULTS['predictor']}/{NOISY_DEFAULTS['relaxation']}",
            "drive": "restart", "reuse_tol": 0.0}


#: the force test as the presets before the band rows measured it: ‖R‖/‖R₀‖ to 1e-3 or
#: every reaction within 0.02 p0, 25 iterations, a stalled increment accepted once the
#: correction is within 1e-2 (the noise-aware acceptance the commands give DEM runs)
FORCE_TEST = {"convergence": "force", "rtol": 1e-3, "stress_floor": 0.02}

#: the band knobs whose rows a preset may take (the others are the user's problem: the
#: mesh, the load steps)
NEWTON_KNOBS = ("convergence", "relaxation", "tangent", "drive")


def band_rows(scale: BandScale) -> list[BandRow]:
    """The knobs' rows, the reference (the commands' defaults, :func:`command_settings`)
    first; each other row changes one setting. (Not measured here, for the CPU's time: the
    plain displacement test, the Kruyt–Rothenburg tangent, the load steps, more discs.)"""
    seeds, knob_seeds = scale.seeds, scale.knob_seeds
    rows = [BandRow("reference", "defaults", {}, seeds),
            BandRow("relaxation", "none", {"acceleration": "extrapolate/none"}, knob_seeds),
            BandRow("convergence", "residual-displacement 3e-2", {"rtol": 3e-2}, knob_seeds),
            BandRow("convergence", "force 1e-3 floor 0.02p0", dict(FORCE_TEST), knob_seeds),
            BandRow("convergence", "force 1e-3 floor 0.02p0 no acceptance",
                    {**FORCE_TEST, "accept_correction": 0.0}, knob_seeds),
            BandRow("drive", "continue", {"drive": "continue"}, knob_seeds),
            BandRow("tangent", "objective", {"tangent": "objective", "tangent_update": "none"},
                    knob_seeds),
            BandRow("strain_per_step", "3e-5", {"strain_per_step": 3e-5}, knob_seeds),
            BandRow("strain_per_step", "1e-4", {"strain_per_step": 1e-4}, knob_seeds),
            BandRow("mesh", "{}x{}".format(*scale.coarse_elements),
                    {"elements": scale.coarse_elements}, knob_seeds)]
    rows += [BandRow("discs", str(n), {"discs": n}, knob_seeds) for n in scale.disc_values]
    return rows


def preset_band_row(name: str, settings: dict[str, Any], scale: BandScale) -> BandRow:
    """A preset's row: its settings but its discs (the band rows measure the discs apart)
    on the band specimen."""
    return BandRow("preset", name, {k: v for k, v in settings.items() if k != "discs"},
                   scale.seeds)


def run_folder(out: Path, row: BandRow, seed: int) -> Path:
    """Where the run of ``row`` with ``seed`` writes its tables."""
    return out / "band" / "runs" / row.key / f"seed{seed}"


def _spec_fields(row: BandRow, seed: int, scale: BandScale, device: str) -> dict[str, Any]:
    """The flat run spec of one run: the band specimen at the commands' defaults with the
    row's fields."""
    return {"test": "biaxial", "material": "dem", "elements": scale.elements,
            "particles": scale.discs, "steps": scale.steps,
            "axial_strain": scale.axial_strain, "confining": scale.confining, "seed": seed,
            "width": scale.width, "height": scale.height,
            "device": device, "progress": False,
            **settings_fields(row.settings, scale.confining)}


def _run_one(fields: dict[str, Any], folder: str) -> str:
    """One run into ``folder`` (in a worker process): the commands' run of the flat spec
    ``fields``, its steps and points tables and its summary written there."""
    from granular_material.runs import from_flat
    from granular_material.runs import run as run_spec

    spec = from_flat({**fields, "out": folder})
    # a run stopped by an earlier, interrupted study continues from its checkpoint
    outcome = run_spec(spec, resume=resumable(Path(folder)))
    error = outcome.result.error
    return f"{folder}: {outcome.summary.get('wall_time_s', 0.0):.0f} s" + (
        f" ({error})" if error else "")


def run_band_rows(rows: list[BandRow], scale: BandScale, out: Path, device: str = "cpu",
                  jobs: int = 1, progress: bool = False,
                  log: Callable[[str], None] = lambda _: None) -> None:
    """Run every (row, seed) of ``rows`` not yet done (a run is done once it has ended in its
    folder: :func:`~granular_material.runs.run_folder.ended_summary`; rows of equal settings
    share it), ``jobs`` at a time in processes of their own."""
    todo = list({run_folder(out, row, seed): (row, seed) for row in rows for seed in row.seeds
                 if ended_summary(run_folder(out, row, seed)) is None}.values())
    if not todo:
        return
    (out / "band").mkdir(parents=True, exist_ok=True)
    write_json({"scale": scale.name, "rows": [row.__dict__ for row in rows]},
               out / "band" / "plan.json")
    context = multiprocessing.get_context("spawn")  # warp is not fork-safe
    with progress_bar(len(todo), f"band rows ({scale.name})", progress, unit="run") as bar, \
            ProcessPoolExecutor(max_workers=max(1, jobs), mp_context=context) as pool:
        futures = {pool.submit(_run_one, _spec_fields(row, seed, scale, device),
                               str(run_folder(out, row, seed))): (row, seed)
                   for row, seed in todo}
        for future in as_completed(futures):
            log(future.result())
            bar.update(1)


def read_band_run(folder: Path) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """A done run's steps and points tables and summary."""
    return (pd.read_csv(folder / "steps.csv"), read_points(folder),
            json.loads((folder / "summary.json").read_text()))
