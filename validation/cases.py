"""The cross-validation cases: the same RVE and loading run by YADE and by our engine.

A case names where its packings come from (``yade``: Guo & Zhao's procedure in YADE,
imported into our format; ``ours``: ``granular-material prepare``, exported to YADE), the
seeds, and the loading: the drained biaxial test or a ∇u path applied like Guo & Zhao's
``shear2D`` (n = max(1e5·max|ΔG|, 2) steps an increment). Each seed runs in YADE and in our
engine from the same RVE file; the curves are compared by
:mod:`granular_material_validation.metrics`. For the ∇u paths YADE integrates
L = log(I + ΔG_k) so that its cell is (I + G·k/K)·H0 after increment k, the same loading as
our ``dem-drive``; Guo & Zhao's own L = ΔG/(n·dt) (cell ∝ exp(ΔG)) is run as well and its
distance to the former reported.

Acceptance of a case: the pre-peak, peak-ratio and strain-at-peak rules on every seed; the
post-peak rule (DEM is chaotic after the peak) on the seed-mean curves when there are two or
more seeds, on the one curve otherwise. Every seed's post-peak figure is reported as well.

Chaos baseline: each seed also runs YADE against a perturbed YADE (biaxial: 1 % less strain a
step; ∇u paths: Guo & Zhao's shear2D kinematics and step count) and the same rules are
applied, so a miss of ours can be set against how far YADE moves from itself.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from granular_material_validation import engine_runner, metrics, yade_runner

__all__ = ["CASES", "Case", "SeedRun", "run_case"]


@dataclass(frozen=True)
class Case:
    """One cross-validation case.

    Attributes:
        name: identifier used on the command line and in the report.
        kind: ``"biaxial"`` or ``"drive"``.
        source: ``"yade"`` (Guo & Zhao packing built by YADE) or ``"ours"``.
        seeds: packing seeds.
        particles: discs per RVE.
        pressure: isotropic consolidation stress [Pa] (a magnitude).
        axial_strain: biaxial: final axial strain (engineering, compression positive).
        grad_u: drive: total ∇u as (Gxx, Gxy, Gyx, Gyy).
        increments: drive: number of equal increments K.
        tangent_at: drive: increments at which both tangents are compared.
        description: one line for the report.
    """

    name: str
    kind: str
    source: str
    seeds: tuple[int, ...] = (1, 2, 3)
    particles: int = 400
    pressure: float = 1e5
    axial_strain: float = 0.1
    grad_u: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    increments: int = 1
    tangent_at: tuple[int, ...] = ()
    description: str = ""

    def __post_init__(self) -> None:
        if self.kind not in ("biaxial", "drive"):
            raise ValueError(f"Case.kind must be 'biaxial' or 'drive', got {self.kind!r}")
        if self.source not in ("yade", "ours"):
            raise ValueError(f"Case.source must be 'yade' or 'ours', got {self.source!r}")
        if not self.seeds:
            raise ValueError(f"Case.seeds must not be empty (case {self.name!r})")

    @property
    def strain_label(self) -> str:
        """Name of the strain axis of the comparison."""
        return "axial_strain" if self.kind == "biaxial" else "path_strain"


CASES: dict[str, Case] = {c.name: c for c in (
    Case("smoke", "biaxial", "yade", seeds=(1,), axial_strain=0.03,
         description="Guo & Zhao RVE (YADE, seed 1), drained biaxial to 3 % axial strain"),
    Case("gz-biaxial", "biaxial", "yade",
         description="Guo & Zhao RVE built in YADE, drained biaxial to 10 % at σxx = 100 kPa"),
    Case("ours-biaxial", "biaxial", "ours",
         description="RVE prepared by our engine, run in YADE and ours, biaxial to 10 %"),
    Case("gz-pure-shear", "drive", "yade", grad_u=(0.03, 0.0, 0.0, -0.03), increments=60,
         tangent_at=(0, 1, 30, 60),
         description="Guo & Zhao RVE, pure shear ∇u = diag(+3 %, −3 %) in 60 increments"),
    Case("gz-simple-shear", "drive", "yade", grad_u=(0.0, 0.05, 0.0, 0.0), increments=100,
         tangent_at=(0, 1, 50, 100),
         description="Guo & Zhao RVE, simple shear ∂ux/∂y = 5 % in 100 increments"),
)}


# YADE's own sensitivity: the biaxial test rerun at 1 % less strain a step than 1e-5
PERTURBED_STRAIN_PER_STEP = 0.99e-5


@dataclass
class SeedRun:
    """The results of one seed of a case (curves on both sides, timings, differences)."""

    seed: int
    yade: pd.DataFrame
    ours: pd.DataFrame
    comparison: metrics.CurveComparison
    yade_wall_s: float
    yade_run_s: float
    ours_wall_s: float
    extra: dict[str, Any] = field(default_factory=dict)
    baseline: pd.DataFrame | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures of this seed (curves left out)."""
        return {"seed": self.seed, "comparison": self.comparison.to_dict(),
                "yade_wall_s": self.yade_wall_s, "yade_run_s": self.yade_run_s,
                "ours_wall_s": self.ours_wall_s,
                "wall_ratio_ours_over_yade": self.ours_wall_s / self.yade_wall_s,
                **self.extra}


def _packing(case: Case, seed: int, out: Path, device: str | None) -> tuple[Path, dict]:
    """The RVE file of ``seed`` for ``case`` (cached under ``out/packings``)."""
    folder = out / "packings"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{case.source}_n{case.particles}_seed{seed}.npz"
    info_path = path.with_suffix(".json")
    if path.is_file() and info_path.is_file():
        return path, json.loads(info_path.read_text())
    if case.source == "yade":
        _, info = yade_runner.yade_prepare_guo_zhao(
            path, seed=seed, particles=case.particles, pressure=case.pressure,
            workdir=folder / f"yade_seed{seed}")
    else:
        info = engine_runner.ours_prepare(path, particles=case.particles, seed=seed,
                                          pressure=case.pressure, device=device)
    info_path.write_text(json.dumps(info, indent=1))
    return path, info


def _path_strain(frame: pd.DataFrame, case: Case) -> pd.DataFrame:
    """Add ``path_strain`` = max|G|·k/K and ``volumetric_strain`` = (1 + e)/(1 + e0) − 1."""
    frame = frame.copy()
    scale = float(np.abs(case.grad_u).max())
    frame["path_strain"] = frame["increment"] / case.increments * scale
    e = frame["void_ratio"].to_numpy(dtype=np.float64)
    frame["volumetric_strain"] = (1.0 + e) / (1.0 + e[0]) - 1.0
    return frame


def _run_seed(case: Case, seed: int, out: Path, device: str | None) -> SeedRun:
    rve, prep = _packing(case, seed, out, device)
    work = out / "runs" / case.name / f"seed{seed}"
    work.mkdir(parents=True, exist_ok=True)
    extra: dict[str, Any] = {"packing": prep}
    if case.kind == "biaxial":
        yade, ysum = yade_runner.yade_biaxial(rve, axial_strain=case.axial_strain,
                                              confining=case.pressure, workdir=work / "yade")
        ours, osum = engine_runner.ours_biaxial(rve, work / "ours_biaxial.csv",
                                                axial_strain=case.axial_strain,
                                                confining=case.pressure, device=device)
        for side, frame in (("yade", yade), ("ours", ours)):
            extra[f"servo_error_{side}"] = float(
                np.abs(frame["sxx"] + case.pressure).max() / case.pressure)
        # chaos baseline: YADE against itself with a 1 % slower loading rate
        slower, _ = yade_runner.yade_biaxial(rve, axial_strain=case.axial_strain,
                                             confining=case.pressure,
                                             strain_per_step=PERTURBED_STRAIN_PER_STEP,
                                             workdir=work / "yade_perturbed")
        extra["yade_perturbed_vs_yade"] = {
            **metrics.compare_curves(yade, slower).to_dict(),
            "strain_per_step": PERTURBED_STRAIN_PER_STEP}
        baseline = slower
    else:
        yade, ysum = yade_runner.yade_drive(rve, list(case.grad_u), case.increments,
                                            tangent_at=list(case.tangent_at),
                                            kinematics="exact", workdir=work / "yade")
        ours, osum = engine_runner.ours_drive(rve, work / "ours_drive.csv", list(case.grad_u),
                                              case.increments, device=device)
        yade, ours = _path_strain(yade, case), _path_strain(ours, case)
        # Guo & Zhao's own shear2D kinematics (cell ∝ exp(ΔG) per increment), YADE against
        # YADE: how much the kinematic convention alone moves the curve
        g_z, gsum = yade_runner.yade_drive(rve, list(case.grad_u), case.increments,
                                           kinematics="shear2d", workdir=work / "yade_shear2d")
        g_z = _path_strain(g_z, case)
        baseline = g_z
        extra["shear2d_vs_exact_yade"] = {
            **metrics.compare_curves(yade, g_z, strain=case.strain_label).to_dict(),
            "steps_exact": int(ysum["steps"]), "steps_shear2d": int(gsum["steps"]),
            "steps_ours": int(ours["steps"].iloc[-1])}
        if case.tangent_at:
            extra["tangents"] = _compare_tangents(case, rve, yade, device)
    comparison = metrics.compare_curves(yade, ours, strain=case.strain_label)
    yade.to_csv(work / "yade_curve.csv", index=False)
    ours.to_csv(work / "ours_curve.csv", index=False)
    return SeedRun(seed, yade, ours, comparison, yade_wall_s=float(ysum["wall_s"]),
                   yade_run_s=float(ysum["run_s"]), ours_wall_s=float(osum["wall_s"]),
                   extra=extra, baseline=baseline)


def _compare_tangents(case: Case, rve: Path, yade: pd.DataFrame,
                      device: str | None) -> list[dict[str, Any]]:
    ours = engine_runner.ours_tangents(rve, list(case.grad_u), case.increments,
                                       list(case.tangent_at),
                                       device="cpu" if device is None else device)
    rows = []
    names = [f"D_{a}_{b}" for a in ("xx", "yy", "xy") for b in ("xx", "yy", "xy")]
    for k in case.tangent_at:
        row = yade.loc[yade["increment"] == k, names].to_numpy(dtype=np.float64).reshape(3, 3)
        # YADE fills the upper triangle of its Voigt matrix only
        ref = np.triu(row) + np.triu(row, 1).T
        diff = metrics.tangent_difference(ref, ours[k])
        rows.append({"increment": k, "yade": ref.tolist(), "ours": ours[k].tolist(), **diff})
    return rows


def _case_checks(case: Case, refs: list[pd.DataFrame],
                 others: list[pd.DataFrame]) -> tuple[dict[str, bool], dict[str, Any] | None]:
    """The case's acceptance of ``others`` against ``refs`` (one curve per seed each).

    Pre-peak, peak ratio and strain at peak on every seed; post-peak on the seed means (two
    or more seeds) or on the one curve. Returns the checks and the ensemble comparison.
    """
    x = case.strain_label
    per_seed = [metrics.compare_curves(r, o, strain=x) for r, o in zip(refs, others,
                                                                        strict=True)]
    checks = {rule: all(c.checks()[rule] for c in per_seed)
              for rule in ("pre_peak", "peak_ratio", "strain_at_peak")}
    if len(refs) >= 2:
        ens = metrics.compare_curves(metrics.ensemble_mean(refs, x),
                                     metrics.ensemble_mean(others, x), x)
        checks["post_peak"] = ens.checks()["post_peak"]
        return checks, ens.to_dict()
    checks["post_peak"] = per_seed[0].checks()["post_peak"]
    return checks, None


def run_case(case: Case, out: str | Path, device: str | None = None) -> dict[str, Any]:
    """Run every seed of ``case`` in both codes; the case's JSON entry (plus its curves).

    The returned dict holds ``case``, ``per_seed`` (figures of each seed), ``ensemble``
    (seed-mean comparison, two or more seeds), ``checks``, ``passed`` and, under the key
    ``_runs``, the :class:`SeedRun` objects for the plots.
    """
    out = Path(out)
    runs = [_run_seed(case, seed, out, device) for seed in case.seeds]
    entry: dict[str, Any] = {"case": asdict(case), "per_seed": [r.to_dict() for r in runs]}
    refs = [r.yade for r in runs]
    checks, ensemble = _case_checks(case, refs, [r.ours for r in runs])
    if ensemble is not None:
        entry["ensemble"] = ensemble
        peaks = np.array([r.comparison.peak_ratio_ref for r in runs])
        entry["yade_seed_spread"] = {
            "peak_ratio_mean": float(peaks.mean()), "peak_ratio_std": float(peaks.std(ddof=1)),
            "strain_at_peak": [r.comparison.strain_at_peak_ref for r in runs]}
    if all(r.baseline is not None for r in runs):
        base_checks, base_ensemble = _case_checks(case, refs, [r.baseline for r in runs])
        entry["baseline_checks"] = base_checks
        if base_ensemble is not None:
            entry["baseline_ensemble"] = base_ensemble
    yade_wall = sum(r.yade_wall_s for r in runs)
    ours_wall = sum(r.ours_wall_s for r in runs)
    entry.update({"checks": checks, "passed": all(checks.values()), "yade_wall_s": yade_wall,
                  "ours_wall_s": ours_wall, "wall_ratio_ours_over_yade": ours_wall / yade_wall,
                  "_runs": runs})
    return entry
