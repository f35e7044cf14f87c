"""The trade study's runs: the RVE files a study prepares once, and one run of a row's
settings (pure DEM, single element or specimen) with what it measured and cost."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.dem import DEMBatch, RVEData, critical_timestep, load_rve, save_rve
from granular_material.procedures import biaxial_test, prepare_packing
from granular_material.procedures.element_tests import biaxial_steps
from granular_material.results import band_summary
from granular_material.runs import from_flat
from granular_material.runs import run as run_spec
from granular_material.studies.plan import StudyScale, tangent_settings

__all__ = ["RunResult"]


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
        # the knobs are those of the force test (rtol of ‖R‖/‖R₀‖, the stress floor, reuse),
        # but for a preset whose Newton test is a displacement test
        spec = from_flat({
            **problem, "material": "dem", "confining": self.scale.confining,
            "axial_strain": self.scale.axial_strain, "rve": rve,
            # the file carries its discs; only prepared packings are told how many
            "particles": None if rve is not None else s["discs"],
            "seed": self.scale.seeds[0], **tangent_settings(s["tangent"]),
            "reuse_tol": s["reuse_tol"], "rtol": s["rtol"], "predictor": predictor,
            "relaxation": relaxation, "drive": s.get("drive", "restart"),
            **({"convergence": "force", "max_iterations": 25,
                "stress_tol": s["stress_floor"] * self.scale.confining}
               if s.get("convergence", "force") == "force"
               else {"convergence": s["convergence"]}),
            "device": self.device})
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
