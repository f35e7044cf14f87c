"""The speed/accuracy trade study: each knob a user can turn, measured against a
high-fidelity reference run from the same RVEs, in one run on one machine.

Three tests carry the knobs:

- ``dem``: the drained biaxial test of pure-DEM RVEs (one per seed, batched): discs per RVE,
  strain per DEM step, time-step safety factor, local damping, float32 against float64;
- ``element``: the FEM × DEM single element (one RVE copied to its 4 Gauss points): Newton
  tolerance, stress floor, tangent, predictor and relaxation, reuse of undisturbed RVEs;
- ``specimen``: the biaxial specimen: the mesh.

Every knob varies one setting with the others at the reference (:data:`REFERENCE`). A run's
errors (:func:`~granular_material.results.compare.curve_errors`) are taken against the
reference run of its test: seed by seed for the pure-DEM knobs (the same packings, so the
knob's own effect), against the seeds' mean curve for the discs knob (each seed's own
departure, the scatter a user of one RVE buys, is part of the error there), and against the
finest mesh for the mesh knob. Runs with equal settings run once.

Everything is written under the output folder as it goes: ``curves/`` (each run's curve),
``trade.csv`` (one row per knob value, appended after each run; a restarted study skips the
runs already in it), then ``pareto.png``, ``knob_<name>.png``, ``presets.json`` and
``report.md``. The three recommended settings are chosen from the rows by a stated rule
(:func:`recommend`) and then run and measured themselves.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.dem import DEMBatch, RVEData, critical_timestep, load_rve, save_rve
from granular_material.fem.presets import tangent_settings
from granular_material.procedures import biaxial_test, prepare_packing, progress_bar
from granular_material.procedures.element_tests import biaxial_steps
from granular_material.procedures.packing import DEFAULT_PRESSURE
from granular_material.provenance import code_commit
from granular_material.results import band_summary, write_csv
from granular_material.results.compare import (
    ERROR_COLUMNS,
    curve_errors,
    markdown_table,
    mean_curve,
)
from granular_material.runs import from_flat
from granular_material.runs import run as run_spec

__all__ = ["PRESETS", "REFERENCE", "SCALES", "Knob", "StudyScale", "plan_runs",
           "read_trade_table", "recommend", "run_trade_study"]


# -- what is studied -------------------------------------------------------------------------
@dataclass(frozen=True)
class StudyScale:
    """The sizes of one study (``--scale``).

    Attributes:
        name: smoke, cpu or gpu.
        axial_strain: axial strain every test runs to [-].
        confining: confining pressure p0 [Pa].
        seeds: packings of every pure-DEM run (one RVE each).
        discs: values of the discs-per-RVE knob; the largest is its reference.
        base_discs: discs of the other pure-DEM runs.
        strain_steps, safeties, dampings: values of those pure-DEM knobs [-].
        element_discs: discs of the single element's RVE; element_steps: its load steps.
        rtols, stress_floors (fractions of p0), reuse_tols [-], tangents, accelerations
            ("predictor/relaxation"): values of the element knobs.
        meshes: (nx, ny) of the mesh knob; the finest is its reference.
        mesh_discs, mesh_steps: discs per RVE and load steps of the specimens.
        records: records of each pure-DEM curve.
        mesh_replicate: the specimens' Gauss points share one RVE (smoke: a homogeneous
            specimen that converges in a few iterations) instead of one packing each.
    """

    name: str
    axial_strain: float
    seeds: tuple[int, ...]
    discs: tuple[int, ...]
    base_discs: int
    strain_steps: tuple[float, ...]
    safeties: tuple[float, ...]
    dampings: tuple[float, ...]
    element_discs: int
    element_steps: int
    rtols: tuple[float, ...]
    stress_floors: tuple[float, ...]
    tangents: tuple[str, ...]
    accelerations: tuple[str, ...]
    reuse_tols: tuple[float, ...]
    meshes: tuple[tuple[int, int], ...]
    mesh_discs: int
    mesh_steps: int
    confining: float = DEFAULT_PRESSURE
    records: int = 100
    mesh_replicate: bool = False


#: the reference settings: float64, 10⁻⁶ strain per DEM step (10⁻⁵ at smoke scale), the
#: engine's default time step (0.3 of the critical one) and damping (0.1); Newton to
#: rtol 10⁻³ with a stress floor of 0.001 p0, the objective tangent, extrapolating
#: predictor with Aitken relaxation, every RVE stepped (no reuse)
REFERENCE: dict[str, Any] = {
    "strain_per_step": 1.0e-6, "safety": 0.3, "damping": 0.1, "dtype": "float64",
    "rtol": 1.0e-3, "stress_floor": 0.001, "tangent": "objective",
    "acceleration": "extrapolate/aitken", "reuse_tol": 0.0,
}

SCALES: dict[str, StudyScale] = {
    "smoke": StudyScale(
        name="smoke", axial_strain=0.02, seeds=(1, 2), discs=(16, 36), base_discs=16,
        strain_steps=(1.0e-5, 4.0e-5, 1.0e-4), safeties=(0.3, 0.8), dampings=(0.1, 0.3),
        element_discs=16, element_steps=4, rtols=(1.0e-3, 1.0e-2), stress_floors=(0.001,),
        tangents=("objective", "condensed-hold"), accelerations=("extrapolate/aitken",),
        reuse_tols=(0.0, 1.0e-4), meshes=((1, 1), (1, 2)), mesh_discs=16, mesh_steps=2,
        records=20, mesh_replicate=True,
    ),
    "cpu": StudyScale(
        name="cpu", axial_strain=0.08, seeds=(1, 2, 3), discs=(100, 196, 400, 676, 900),
        base_discs=400, strain_steps=(1.0e-6, 3.0e-6, 1.0e-5, 3.0e-5, 1.0e-4),
        safeties=(0.1, 0.3, 0.6, 0.9), dampings=(0.05, 0.1, 0.2, 0.3), element_discs=100,
        element_steps=40, rtols=(1.0e-3, 5.0e-3, 1.0e-2, 2.0e-2),
        stress_floors=(0.001, 0.005, 0.02),
        tangents=("objective", "kruyt-rothenburg", "perturbation", "secant", "condensed",
                  "condensed-hold"),
        accelerations=("tangent/none", "extrapolate/none", "extrapolate/aitken"),
        reuse_tols=(0.0, 1.0e-6, 1.0e-5, 1.0e-4), meshes=((1, 2), (2, 4)), mesh_discs=64,
        mesh_steps=20,
    ),
}


#: the specimens' Newton tolerances: looser than the reference's (rtol 10⁻³ with a 0.001 p0
#: floor took 60–235 iterations a step past the peak on the 2 × 4 mesh of 64-disc RVEs, 14
#: minutes for 15 of 40 steps here), the force test's defaults before the commands took Guo
#: & Zhao's displacement test; the mesh knob is measured at them
SPECIMEN_NEWTON = {"rtol": 5.0e-3, "stress_floor": 5.0e-3}

#: the ``noise`` knob: disc positions moved by this fraction of their radius (random,
#: seeded), the reference otherwise: how far round-off alone carries a chaotic run
NOISE = 1.0e-9

#: full size for a GPU: five seeds, 400-disc elements in 100 load steps, the meshes up to Wu
#: et al.'s 10 × 15 of 400-disc RVEs, to 10 % axial strain
SCALES["gpu"] = replace(
    SCALES["cpu"], name="gpu", axial_strain=0.1, seeds=(1, 2, 3, 4, 5), element_discs=400,
    element_steps=100, meshes=((2, 4), (5, 10), (10, 15)), mesh_discs=400, mesh_steps=100,
)


@dataclass(frozen=True)
class Knob:
    """One setting varied: its ``name`` (a key of the run settings), the ``test`` that
    carries it, its ``values`` and the value of its reference run."""

    name: str
    test: str
    values: tuple[Any, ...]
    reference: Any


def knobs(scale: StudyScale) -> list[Knob]:
    """The knobs of a study, in the order of the report."""
    ref = _reference(scale)
    return [
        Knob("discs", "dem", scale.discs, max(scale.discs)),
        Knob("strain_per_step", "dem", scale.strain_steps, ref["strain_per_step"]),
        Knob("safety", "dem", scale.safeties, ref["safety"]),
        Knob("damping", "dem", scale.dampings, ref["damping"]),
        Knob("dtype", "dem", ("float64", "float32"), "float64"),
        Knob("rtol", "element", scale.rtols, ref["rtol"]),
        Knob("stress_floor", "element", scale.stress_floors, ref["stress_floor"]),
        Knob("tangent", "element", scale.tangents, ref["tangent"]),
        Knob("acceleration", "element", scale.accelerations, ref["acceleration"]),
        Knob("reuse_tol", "element", scale.reuse_tols, ref["reuse_tol"]),
        Knob("mesh", "specimen", tuple(f"{nx}x{ny}" for nx, ny in scale.meshes),
             "{}x{}".format(*max(scale.meshes, key=lambda m: m[0] * m[1]))),
        Knob("noise", "dem", (NOISE,), 0.0),
        Knob("noise", "element", (NOISE,), 0.0),
    ]


def _reference(scale: StudyScale) -> dict[str, Any]:
    """The reference settings at this scale (smoke runs 10⁻⁵ strain per DEM step)."""
    ref = dict(REFERENCE)
    ref["strain_per_step"] = min(scale.strain_steps)
    return ref


def _settings(scale: StudyScale, test: str, **change: Any) -> dict[str, Any]:
    """The full settings of one run of ``test``: the reference with ``change``."""
    values = {**_reference(scale), **change}
    noise = {"noise": values["noise"]} if values.get("noise") else {}
    if test == "dem":
        values.setdefault("discs", scale.base_discs)
        return {k: values[k] for k in ("discs", "strain_per_step", "safety", "damping",
                                       "dtype")} | {"test": "dem"} | noise
    common = {k: values[k] for k in ("rtol", "stress_floor", "tangent", "acceleration",
                                     "reuse_tol")}
    if test == "element":
        return common | {"test": "element",
                         "discs": values.get("discs", scale.element_discs)} | noise
    finest = max(scale.meshes, key=lambda m: m[0] * m[1])
    return common | SPECIMEN_NEWTON | {"test": "specimen", "discs": scale.mesh_discs,
                                       "mesh": values.get("mesh", "{}x{}".format(*finest))}


def run_key(settings: dict[str, Any]) -> str:
    """A short stable name of a run's settings (its curve file and ``trade.csv`` key)."""
    text = json.dumps(settings, sort_keys=True, default=str)
    return f"{settings['test']}-{hashlib.sha1(text.encode()).hexdigest()[:10]}"


@dataclass
class PlannedRow:
    """One row of ``trade.csv``: a knob's value, the run that measures it and its
    reference run."""

    knob: str
    value: Any
    settings: dict[str, Any]
    reference: dict[str, Any]
    per_seed: bool = True  # pure DEM: compare seed by seed (False: with the seeds' mean)


def plan_runs(scale: StudyScale) -> list[PlannedRow]:
    """The rows of the study, knob by knob."""
    rows = []
    for knob in knobs(scale):
        reference = _settings(scale, knob.test, **{knob.name: knob.reference})
        for value in knob.values:
            rows.append(PlannedRow(knob.name, value,
                                   _settings(scale, knob.test, **{knob.name: value}),
                                   reference, per_seed=knob.name != "discs"))
    return rows


# -- running ---------------------------------------------------------------------------------
@dataclass
class RunResult:
    """What one run measured: its curve and cost."""

    curve: pd.DataFrame
    wall_s: float
    particle_steps: int
    iterations: int = 0
    error: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def _dem_equivalent(particle_steps: int, timing: dict[str, float]) -> float:
    """A FEM run's cost in DEM particle-steps, its tangent's work included: the
    particle-steps scaled by the material's seconds (DEM, homogenisation, tangent) over its
    DEM seconds, both timed in the same run (so the machine's load mostly cancels): the
    condensed tangent costs work of its own that no particle-step counts."""
    dem = timing.get("dem", 0.0)
    if dem <= 0.0:
        return float(particle_steps)
    material = dem + timing.get("homogenization", 0.0) + timing.get("tangent", 0.0)
    return particle_steps * material / dem


class _Runner:
    """Runs of one study: the RVE files it prepares once, and the runs themselves."""

    def __init__(self, scale: StudyScale, out: Path, device: str) -> None:
        self.scale, self.out, self.device = scale, out, device
        self._warm: set[str] = set()
        (out / "rves").mkdir(parents=True, exist_ok=True)

    def packings(self, discs: int) -> Path:
        """The seeds' packings of ``discs`` discs (prepared once, kept under ``rves/``)."""
        path = self.out / "rves" / f"discs{discs}.npz"
        if not path.exists():
            batch = prepare_packing(n_disc=discs, n_rve=len(self.scale.seeds),
                                    seed=self.scale.seeds[0], pressure=self.scale.confining,
                                    device=self.device)
            save_rve(path, batch.to_data())
        return path

    def single(self, discs: int, noise: float = 0.0) -> Path:
        """The first seed's packing alone (the element's RVE), its discs moved by ``noise``
        of their radius (see :func:`_jiggled`)."""
        name = f"discs{discs}_seed{self.scale.seeds[0]}" + (f"_noise{noise:g}" if noise else "")
        path = self.out / "rves" / f"{name}.npz"
        if not path.exists():
            save_rve(path, _jiggled(load_rve(self.packings(discs)).take([0]), noise))
        return path

    def run(self, settings: dict[str, Any]) -> RunResult:
        """One run; kernels are compiled beforehand (:meth:`_warm_up`), so that its wall
        time is the run's own."""
        self._warm_up(settings.get("dtype", "float64"))
        return {"dem": self._dem, "element": self._element,
                "specimen": self._specimen}[settings["test"]](settings)

    def _warm_up(self, dtype: str) -> None:
        """Compile (or load) the kernels of ``dtype`` for one and two CPU threads: a few
        DEM steps of two small RVEs, and for float64 a two-step single element."""
        if dtype in self._warm:
            return
        data = load_rve(self.packings(min(self.scale.discs)))
        pair = data.take([0, 0]) if data.n_rve == 1 else data.take([0, 1])
        biaxial_test(DEMBatch(pair, device=self.device, dtype=dtype, shards=2),
                     axial_strain=1e-4, confining=self.scale.confining,
                     strain_per_step=2e-5, record_every=5)
        if dtype == "float64":
            run_spec(from_flat({"test": "single-element", "material": "dem", "steps": 2,
                           "axial_strain": 1e-3, "confining": self.scale.confining,
                           "rve": self.single(min(self.scale.discs)),
                           "device": self.device}))
        self._warm.add(dtype)

    def _dem(self, s: dict[str, Any]) -> RunResult:
        data = _jiggled(load_rve(self.packings(s["discs"])), s.get("noise", 0.0))
        data = replace(data, meta=replace(data.meta, damping=float(s["damping"])))
        dt = s["safety"] * min(critical_timestep(r, data.meta) for r in data.radius)
        batch = DEMBatch(data, device=self.device, dtype=s["dtype"], timestep=dt)
        total = biaxial_steps(self.scale.axial_strain, s["strain_per_step"])
        started = time.perf_counter()
        curve = biaxial_test(batch, axial_strain=self.scale.axial_strain,
                             confining=self.scale.confining,
                             strain_per_step=s["strain_per_step"],
                             record_every=max(1, total // self.scale.records))
        wall = time.perf_counter() - started
        diameter = 2.0 * float(np.mean(data.radius))
        rate = s["strain_per_step"] / dt  # axial strain rate [1/s]
        inertial = rate * diameter * math.sqrt(data.meta.density / self.scale.confining)
        particle_steps = total * data.n_rve * data.n_disc
        return RunResult(curve, wall, particle_steps,
                         extra={"inertial_number": inertial, "timestep_s": dt,
                                "cost_particle_steps": particle_steps})

    def _fem(self, s: dict[str, Any], problem: dict[str, Any], rve: Path | None) -> RunResult:
        """The FEM run of the study's settings ``s``: a run spec of ``problem`` (flat
        fields) on the RVE file ``rve`` (one RVE, copied to every point) or, without one,
        packings prepared from the study's first seed, run by :func:`run`."""
        predictor, relaxation = s["acceleration"].split("/")
        # the knobs are those of the force test (rtol of ‖R‖/‖R₀‖, the stress floor, reuse)
        spec = from_flat({
            **problem, "material": "dem", "confining": self.scale.confining,
            "axial_strain": self.scale.axial_strain, "rve": rve, "particles": s["discs"],
            "seed": self.scale.seeds[0], **tangent_settings(s["tangent"]),
            "reuse_tol": s["reuse_tol"], "convergence": "force", "max_iterations": 25,
            "rtol": s["rtol"], "predictor": predictor, "relaxation": relaxation,
            "stress_tol": s["stress_floor"] * self.scale.confining, "device": self.device})
        started = time.perf_counter()
        outcome = run_spec(spec)
        result = outcome.result
        wall = time.perf_counter() - started
        if result.interrupt is not None:  # not a measurement: stop the study here
            raise result.interrupt
        done = result.steps[result.steps["step"] > 0]
        particle_steps = int(done["particle_steps"].sum())
        extra = {"cost_particle_steps": _dem_equivalent(particle_steps, outcome.timing)}
        if result.problem.setup.n_points > 4:
            band = band_summary(result, [self.scale.axial_strain], 1.0)
            extra["band_inclination_deg"] = band.get("shear_band_final", {}).get(
                "inclination_deg", math.nan)
        return RunResult(result.steps, wall, particle_steps, int(done["iterations"].sum()),
                         result.error, extra)

    def _element(self, s: dict[str, Any]) -> RunResult:
        return self._fem(s, {"test": "single-element", "steps": self.scale.element_steps},
                         self.single(s["discs"], s.get("noise", 0.0)))

    def _specimen(self, s: dict[str, Any]) -> RunResult:
        nx, ny = (int(v) for v in s["mesh"].split("x"))
        problem = {"test": "biaxial", "elements": (nx, ny), "steps": self.scale.mesh_steps}
        return self._fem(s, problem,
                         self.single(s["discs"]) if self.scale.mesh_replicate else None)


def _jiggled(data: RVEData, noise: float) -> RVEData:
    """``data`` with every disc moved by ``noise`` × its radius in a random direction
    (seed 0), its fractional positions (which the engine resumes from) moved alike;
    ``data`` itself when ``noise`` is 0."""
    if not noise:
        return data
    rng = np.random.default_rng(0)
    step = noise * data.radius[..., None] * rng.standard_normal(data.position.shape)
    if "fractional_position" not in data.extra:
        return replace(data, position=data.position + step)
    frac = data.extra["fractional_position"] + np.einsum("bij,bnj->bni",
                                                         np.linalg.inv(data.cell), step)
    frac -= np.floor(frac)
    return replace(data, position=np.einsum("bij,bnj->bni", data.cell, frac),
                   extra={**data.extra, "fractional_position": frac})


# -- measuring -------------------------------------------------------------------------------
def _errors(row: PlannedRow, curve: pd.DataFrame, reference: pd.DataFrame) -> dict[str, float]:
    """The row's errors: its curve against its reference's (see the module docstring)."""
    if "rve" not in curve:
        return curve_errors(curve, reference)
    seeds = sorted(curve["rve"].unique())
    mean_ref = mean_curve([g for _, g in reference.groupby("rve")])
    per_seed = [curve_errors(curve[curve["rve"] == k],
                             reference[reference["rve"] == k] if row.per_seed else mean_ref)
                for k in seeds]
    errors = {c: float(np.mean([abs(e[c]) for e in per_seed])) for c in ERROR_COLUMNS}
    peaks = [curve[curve["rve"] == k]["stress_ratio"].max() for k in seeds]
    errors["seed_scatter_pct"] = (100.0 * float(np.std(peaks, ddof=1) / np.mean(peaks))
                                  if len(peaks) > 1 else math.nan)
    return errors


def _row(row: PlannedRow, result: RunResult, reference: pd.DataFrame, device: str,
         commit: str) -> dict[str, Any]:
    errors = _errors(row, result.curve, reference)
    return {"knob": row.knob, "value": str(row.value), "test": row.settings["test"],
            "run": run_key(row.settings), "reference_run": run_key(row.reference),
            "is_reference": run_key(row.settings) == run_key(row.reference), **errors,
            "wall_s": result.wall_s, "particle_steps": result.particle_steps,
            "newton_iterations": result.iterations, **result.extra,
            "error": result.error or "", "device": device, "commit": commit}


def accuracy(rows: pd.DataFrame) -> pd.Series:
    """The error a row is judged by [%]: |peak σ1/σ3 error| against the reference. The RMS
    differences of whole curves are reported beside it but not used: past the peak, runs of
    the same packing that differ by round-off already part by several per cent (DEM is
    chaotic; the ``noise`` rows measure it)."""
    return rows["peak_error_pct"].abs()


#: the three recommended settings: their error budget [%] for :func:`accuracy` (None: the
#: reference settings themselves)
PRESETS: dict[str, float | None] = {"quick": 10.0, "engineering": 3.0, "publication": None}

#: the knobs a preset sets: what the FEM commands take as options (the mesh, the test and
#: the physics stay the user's; float32 is measured but the DEM material runs float64)
PRESET_KNOBS = ("discs", "strain_per_step", "rtol", "stress_floor", "tangent",
                "acceleration", "reuse_tol")


def recommend(table: pd.DataFrame, scale: StudyScale) -> dict[str, dict[str, Any]]:
    """The presets' values from the measured rows. Rule: for each knob of
    :data:`PRESET_KNOBS`, the value with the least cost in DEM particle-steps, the tangent's
    work included (:func:`_dem_equivalent`: a cost that does not depend on the machine's
    load; wall time on a shared machine does), among those that ran without error and whose
    :func:`accuracy` is within the preset's budget. Costs within the scatter that round-off
    alone gives the test's reference run (:func:`_cost_scatter`, the ``noise`` row: a FEM
    run's Newton path, and so its particle-steps, is chaotic) are a tie, which the reference
    value wins, else the least cost among them. The reference value when none is within
    the budget, and for ``publication``."""
    ref = _reference(scale) | {"discs": max(scale.discs)}
    chosen: dict[str, dict[str, Any]] = {}
    for name, budget in PRESETS.items():
        values: dict[str, Any] = {}
        for knob in knobs(scale):
            if knob.name not in PRESET_KNOBS:
                continue
            values[knob.name] = ref[knob.name]
            rows = table[(table["knob"] == knob.name) & (table["error"] == "")]
            if budget is None or rows.empty:
                continue
            fine = rows[accuracy(rows) <= budget]
            fine = fine.assign(not_reference=fine["value"] != str(ref[knob.name]))
            if not fine.empty:
                fine = fine.assign(cost=_cost(fine))
                scatter = _cost_scatter(table, knob.test)
                tied = fine[fine["cost"] <= fine["cost"].min() * (1.0 + scatter)]
                best = tied.sort_values(["not_reference", "cost"]).iloc[0]["value"]
                values[knob.name] = _typed(best, knob)
        chosen[name] = values
    return chosen


def _cost(rows: pd.DataFrame) -> pd.Series:
    """The rows' cost [particle-steps], the tangent's work included (the particle-steps
    alone in a table of an older study)."""
    return rows["cost_particle_steps"] if "cost_particle_steps" in rows else rows["particle_steps"]


def _cost_scatter(table: pd.DataFrame, test: str) -> float:
    """How far round-off alone moves the cost of ``test``'s reference run [-]: the
    ``noise`` row's cost against the reference's (0 where either is missing, or the cost
    does not depend on the run's path, as a pure-DEM run's)."""
    if not {"test", "run", "reference_run"} <= set(table.columns):
        return 0.0
    rows = table[(table["test"] == test) & (table["error"] == "")]
    noise = rows[rows["knob"] == "noise"]
    if noise.empty:
        return 0.0
    reference = rows[rows["run"] == noise["reference_run"].iloc[0]]
    if reference.empty:
        return 0.0
    base = float(_cost(reference).iloc[0])
    return abs(float(_cost(noise).iloc[0]) - base) / base if base > 0 else 0.0


def _typed(text: str, knob: Knob) -> Any:
    """A ``trade.csv`` value back as the knob's own type."""
    for value in knob.values:
        if str(value) == str(text):
            return value
    raise ValueError(f"{text!r} is not a value of the knob {knob.name}")


def _preset_rows(presets: dict[str, dict[str, Any]], scale: StudyScale) -> list[PlannedRow]:
    """The presets measured: a pure-DEM run and a single-element run of each."""
    rows = []
    for name, values in presets.items():
        dem = {k: values[k] for k in ("discs", "strain_per_step")}
        element = {k: values[k] for k in ("rtol", "stress_floor", "tangent", "acceleration",
                                          "reuse_tol")}
        rows.append(PlannedRow("preset", name, _settings(scale, "dem", **dem),
                               _settings(scale, "dem", discs=max(scale.discs)),
                               per_seed=False))
        rows.append(PlannedRow("preset", name, _settings(scale, "element", **element),
                               _settings(scale, "element")))
    return rows


# -- the study -------------------------------------------------------------------------------
def _load_curve(out: Path, key: str) -> pd.DataFrame:
    return pd.read_csv(out / "curves" / f"{key}.csv")


def _measure(rows: list[PlannedRow], runner: _Runner, out: Path, device: str, commit: str,
             progress: bool, log: Callable[[str], None]) -> None:
    """Run what the rows need that is not done yet (a run is done once its curve is under
    ``curves/``), and append each row to ``trade.csv`` as soon as its run and its
    reference run are done; rows already in ``trade.csv`` are skipped."""
    table_path = out / "trade.csv"
    written: set[tuple[str, str, str]] = set()
    if table_path.exists():
        old = read_trade_table(table_path)
        written = set(zip(old["knob"], old["value"], old["run"], strict=True))
    pending = [r for r in rows if (r.knob, str(r.value), run_key(r.settings)) not in written]
    needed: dict[str, dict[str, Any]] = {}
    for row in pending:
        needed.setdefault(run_key(row.reference), row.reference)
        needed.setdefault(run_key(row.settings), row.settings)

    def curve_path(key: str) -> Path:
        return out / "curves" / f"{key}.csv"

    with progress_bar(len(needed), f"trade study ({runner.scale.name})", progress,
                      unit="run") as bar:
        for key, settings in needed.items():
            if not curve_path(key).exists():
                bar.set_postfix_str(" ".join(f"{k}={v}" for k, v in settings.items()))
                result = runner.run(settings)
                meta = {"wall_s": result.wall_s, "particle_steps": result.particle_steps,
                        "iterations": result.iterations, "error": result.error,
                        **result.extra}
                curve_path(key).parent.mkdir(parents=True, exist_ok=True)
                curve_path(key).with_suffix(".json").write_text(json.dumps(meta))
                write_csv(result.curve, curve_path(key))  # whole or not at all: the commit point
                log(f"{key}: {result.wall_s:.1f} s"
                    + (f" ({result.error})" if result.error else ""))
            bar.update(1)
            ready = [r for r in pending if curve_path(run_key(r.settings)).exists()
                     and curve_path(run_key(r.reference)).exists()]
            if ready:
                _append(table_path, [_row(r, _load_run(out, run_key(r.settings)),
                                          _load_curve(out, run_key(r.reference)), device,
                                          commit) for r in ready])
                pending = [r for r in pending if r not in ready]


def read_trade_table(path: str | Path) -> pd.DataFrame:
    """``trade.csv`` as a table: ``value`` and ``error`` as text, "" where a run had no
    error (pandas would read an all-empty column as floats)."""
    table = pd.read_csv(path, dtype={"value": str, "error": str})
    return table.assign(error=table["error"].fillna(""))


def _load_run(out: Path, key: str) -> RunResult:
    meta = json.loads((out / "curves" / f"{key}.json").read_text())
    return RunResult(_load_curve(out, key), meta.pop("wall_s"), meta.pop("particle_steps"),
                     meta.pop("iterations"), meta.pop("error"), meta)


def _drop_rows(path: Path, stale: Callable[[pd.DataFrame], pd.Series]) -> None:
    """Rows of the table at ``path`` that ``stale`` marks removed (rows of an earlier plan
    or rule: a study run again with other sizes or presets keeps only its own)."""
    if not path.exists():
        return
    table = read_trade_table(path)
    marked = stale(table)
    if marked.any():
        write_csv(table[~marked], path)


def _append(path: Path, rows: list[dict[str, Any]]) -> None:
    """``rows`` added to the table at ``path``, which is replaced whole."""
    frame = pd.DataFrame(rows)
    if path.exists():
        frame = pd.concat([read_trade_table(path), frame], ignore_index=True)
    write_csv(frame, path)


def run_trade_study(scale: str | StudyScale, out: str | Path, device: str = "cpu",
                    progress: bool = False,
                    log: Callable[[str], None] = lambda _: None) -> pd.DataFrame:
    """Run (or finish) the study ``scale`` into ``out``; returns ``trade.csv`` as a table.

    Writes ``trade.csv``, ``curves/``, ``rves/``, ``pareto.png``, ``knob_<name>.png``,
    ``presets.json`` and ``report.md`` (see the module docstring).
    """
    from granular_material.results.trade_plots import plot_knob, plot_pareto

    study = SCALES[scale] if isinstance(scale, str) else scale
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    runner = _Runner(study, out, device)
    commit = code_commit()
    planned = plan_runs(study)
    _drop_rows(out / "trade.csv", lambda t: (t["knob"] != "preset") & ~pd.Series(
        list(zip(t["knob"], t["value"], t["run"], strict=True)), index=t.index).isin(
        {(r.knob, str(r.value), run_key(r.settings)) for r in planned}))
    _measure(planned, runner, out, device, commit, progress, log)
    table = read_trade_table(out / "trade.csv")
    presets = recommend(table[table["knob"] != "preset"], study)
    preset_rows = _preset_rows(presets, study)
    _drop_rows(out / "trade.csv", lambda t: (t["knob"] == "preset") & ~t["run"].isin(
        {run_key(r.settings) for r in preset_rows}))
    _measure(preset_rows, runner, out, device, commit, progress, log)
    table = read_trade_table(out / "trade.csv")
    (out / "presets.json").write_text(json.dumps(presets, indent=2) + "\n")
    plot_pareto(table, accuracy(table), out / "pareto.png")
    for name in dict.fromkeys(k.name for k in knobs(study)):
        plot_knob(table[table["knob"] == name], name, out / f"knob_{name}.png")
    (out / "report.md").write_text(report(table, presets, study, device, commit))
    return table


def report(table: pd.DataFrame, presets: dict[str, dict[str, Any]], scale: StudyScale,
           device: str, commit: str) -> str:
    """``report.md``: the reference, a table per knob, the presets measured."""
    ref = _reference(scale)
    lines = [
        f"# Speed against accuracy: trade study ({scale.name})", "",
        f"Device {device}; report written at commit {commit} (the commit each row was "
        "measured at is its `commit` in trade.csv). Drained biaxial tests to axial strain "
        f"{scale.axial_strain:g} at p0 = {scale.confining:g} Pa; seeds "
        f"{', '.join(map(str, scale.seeds))}.", "",
        "Reference settings: " + ", ".join(f"{k} = {v}" for k, v in ref.items())
        + f"; pure DEM: {scale.base_discs} discs (discs knob: {max(scale.discs)} discs, "
        f"mean of the seeds); single element: {scale.element_discs} discs, "
        f"{scale.element_steps} load steps; specimens: {scale.mesh_discs} discs, "
        f"{scale.mesh_steps} load steps, Newton's force test looser than the reference's "
        f"({', '.join(f'{k} = {v:g}' for k, v in SPECIMEN_NEWTON.items())}), reference mesh "
        "the finest. Every run's wall time was measured on a machine shared with other work: "
        "the DEM particle-steps are the cost that does not depend on its load. `cost` adds "
        "the tangent's own work in the same unit: a FEM run's particle-steps times its "
        "material's seconds (DEM, homogenisation, tangent) over its DEM seconds, both timed "
        "in that run.", "",
        "Errors (%, relative to the reference's peak σ1/σ3): `peak` = |peak σ1/σ3 − "
        "reference|, `rms` = RMS of the σ1/σ3 difference, `εv rms` relative to the "
        "reference's largest |εv|; pure-DEM errors are means over the seeds of each seed "
        "against the same seed at the reference (discs: against the seeds' mean curve at "
        "the largest size). `accuracy` = |peak|, the measure the presets use; the `noise` rows "
        f"(disc positions moved by {NOISE:g} of a radius, nothing else changed) show how far "
        "round-off alone carries a run: RMS differences at that level are chaos, not the "
        "knob.", "",
        "![Pareto](pareto.png)", "",
    ]
    columns = {"value": "value", "peak_error_pct": "peak %", "stress_ratio_rms_pct": "rms %",
               "volumetric_strain_rms_pct": "εv rms %", "peak_strain_error_pct": "Δε peak %",
               "seed_scatter_pct": "seed scatter %", "inertial_number": "I",
               "band_inclination_deg": "band °", "wall_s": "wall s",
               "particle_steps": "particle-steps",
               "cost_particle_steps": "cost (particle-steps)", "newton_iterations": "iterations",
               "error": "error"}
    shown_knobs = {k.name: k for k in knobs(scale)}  # one section per name
    for knob in [*shown_knobs.values(), Knob("preset", "", tuple(PRESETS), "publication")]:
        rows = table[table["knob"] == knob.name]
        if rows.empty:
            continue
        shown = rows.assign(accuracy=accuracy(rows))
        keep = ["test", *[c for c in columns if c in shown and shown[c].notna().any()
                          and (c != "error" or (shown[c].fillna("") != "").any())],
                "accuracy"]
        lines += [f"## {knob.name}" + (f" (reference {knob.reference})"
                                       if knob.name != "preset" else ""), "",
                  markdown_table(shown[keep].rename(columns=columns))]
        if knob.name != "preset":
            lines += [f"![{knob.name}](knob_{knob.name}.png)", ""]
    lines += ["## Recommended settings", "",
              "Rule: per knob, the value of the least `cost` (DEM particle-steps, the "
              "tangent's work included) whose accuracy is within the budget (the reference on "
              "a tie) "
              f"({', '.join(f'{k}: {v:g} %' for k, v in PRESETS.items() if v is not None)}); "
              "publication is the reference. Each preset then ran itself (rows `preset` "
              "above: pure DEM and single element).", ""]
    preset_rows = []
    for name, values in presets.items():
        measured = table[(table["knob"] == "preset") & (table["value"] == name)]
        cost = {t: measured[measured["test"] == t] for t in ("dem", "element")}
        preset_rows.append({"preset": name, **{k: str(v) for k, v in values.items()},
                            **{f"{t} accuracy %": float(accuracy(c).iloc[0]) if len(c)
                               else math.nan for t, c in cost.items()},
                            **{f"{t} wall s": float(c["wall_s"].iloc[0]) if len(c)
                               else math.nan for t, c in cost.items()}})
    lines.append(markdown_table(pd.DataFrame(preset_rows)))
    return "\n".join(lines)
