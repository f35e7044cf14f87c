"""Figs. 6–10 of Wu et al. (2025): the FEM × DEM runs and what is read from them.

The single element (Fig. 6) and the 50 × 100 mm specimen (Figs. 7–10) are run
specifications run in this process (:func:`granular_material.runs.run`), resumed from their
own folder's checkpoint: an interrupted reproduction continues them from their last
checkpoint. Every Gauss point's RVE of the specimen has its pore space analysed every few
load steps (``--track all``), so the three RVEs of Figs. 9–10 can be chosen afterwards from
the run's own strain field (:func:`choose_points`).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy import ndimage, stats

from granular_material.cli.options import as_flags
from granular_material.dem import DEMBatch, load_rve, save_rve
from granular_material.procedures import biaxial_test, prepare_packing
from granular_material.results import shear_band, write_csv
from granular_material.results.compare import curve_errors, mean_curve
from granular_material.runs import (
    MaterialSpec,
    OutputSpec,
    ProblemSpec,
    RunSpec,
    differences_from_saved,
    run,
    save,
)

from .scales import ReproductionScale

__all__ = ["FEMRunError", "band_crossing", "choose_points", "fractal_fits",
           "point_histories", "run_spec", "specimen_rves"]


class FEMRunError(RuntimeError):
    """A FEM command of the reproduction could not run (not a Newton failure, which the
    command records and the report states)."""


def run_spec(spec: RunSpec, log_path: Path) -> int:
    """Run ``spec`` in this process, continuing from the checkpoint in its output folder
    where a run of this spec was started. A run started there with other settings (older
    code's defaults, another scale) cannot be continued: its folder is set aside whole as
    ``run.before-<time>`` beside it and the run starts afresh (said on stderr and in the
    log). The spec (``run.toml`` beside the log) and the run's summary are
    appended to ``log_path``. Returns the command's exit code (0, or 1 when Newton stopped
    the run short); an interrupt (Ctrl-C, SIGTERM) that stopped the run is raised again
    after its outputs are written (the checkpoint is kept)."""
    log_path.parent.mkdir(parents=True, exist_ok=True)
    spec_path = log_path.with_name("run.toml")
    save(spec, spec_path)
    with open(log_path, "a") as log:
        log.write(f"# granular-material {spec.problem.test}, in this process: {spec_path}\n")
    started = (spec.output.out / "checkpoint" / "options.json").is_file()
    differ = differences_from_saved(spec)
    if differ:
        aside = _set_aside(spec.output.out)
        note = (f"{spec.output.out} held a run started with other settings "
                f"({as_flags('; '.join(differ))}); set aside as {aside.name}, started afresh")
        print(f"granular-material reproduce: {note}", file=sys.stderr)
        with open(log_path, "a") as log:
            log.write(f"# {note}\n")
        started = False
    outcome = run(spec, resume=started)
    with open(log_path, "a") as log:
        log.write(json.dumps(outcome.summary, indent=1, default=str) + "\n")
    if outcome.interrupt is not None:
        raise outcome.interrupt
    return 1 if outcome.summary["error"] else 0


def _set_aside(folder: Path) -> Path:
    """``folder`` renamed to ``<name>.before-<UTC time>`` beside it (nothing removed)."""
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    aside = folder.with_name(f"{folder.name}.before-{stamp}")
    count = 1
    while aside.exists():
        count += 1
        aside = folder.with_name(f"{folder.name}.before-{stamp}-{count}")
    folder.rename(aside)
    return aside


def _spec(scale: ReproductionScale, device: str, folder: Path, problem: dict[str, Any],
          material: dict[str, Any], **output: Any) -> RunSpec:
    """A FEM run of the reproduction at ``scale`` into ``folder/run``."""
    return RunSpec(problem=ProblemSpec(axial_strain=scale.fem_axial_strain,
                                       confining=scale.pressure, **problem),
                   material=MaterialSpec(name="dem", parameters=material),
                   output=OutputSpec(out=folder / "run", **output), device=device)


def run_element(scale: ReproductionScale, rve: Path, folder: Path, device: str) -> int:
    """Fig. 6: the single element (4 Gauss points, one RVE copied to each) beside the pure
    DEM test of the same RVE, into ``folder/run``; the run's exit code."""
    spec = _spec(scale, device, folder,
                 {"test": "single-element", "steps": scale.element_steps},
                 {"rve": rve, "compare_dem": True})
    return run_spec(spec, folder / "run.log")


def specimen_rves(scale: ReproductionScale, folder: Path, device: str) -> Path:
    """One packing per Gauss point of the specimen (seeds 1, 2, …), compacted to e0 and
    consolidated at p0 as the RVEs of Figs. 3–4; prepared once."""
    path = folder / "rves.npz"
    if not path.exists():
        nx, ny = scale.specimen_elements
        batch = prepare_packing(n_disc=scale.specimen_discs, n_rve=4 * nx * ny, seed=1,
                                pressure=scale.pressure, target_void_ratio=scale.void_ratio,
                                device=device)
        save_rve(path, batch.to_data())
    return path


def run_specimen(scale: ReproductionScale, rves: Path, folder: Path, device: str) -> int:
    """Figs. 7–10: the biaxial specimen with smooth platens, every point's pore space
    analysed every ``track_every`` steps, into ``folder/run``; the run's exit code."""
    spec = _spec(scale, device, folder,
                 {"test": "biaxial", "elements": scale.specimen_elements,
                  "steps": scale.specimen_steps, "platens": "smooth"},
                 {"rve": rves}, map_strain=(scale.map_strain,), track=("all",),
                 every=scale.track_every, postprocess=("pore-fractal",))
    return run_spec(spec, folder / "run.log")


def read_run(run: Path) -> tuple[pd.DataFrame, dict]:
    """The ``steps`` table and ``summary.json`` of a FEM run folder."""
    summary_path = run / "summary.json"
    if not summary_path.exists():
        raise FEMRunError(f"{run} has no summary.json: the run did not start (see its log)")
    return pd.read_csv(run / "steps.csv"), json.loads(summary_path.read_text())


def dem_reference(scale: ReproductionScale, rves: Path, folder: Path,
                  device: str) -> pd.DataFrame:
    """Pure-DEM drained biaxial tests of the first len(seeds) RVEs of ``rves`` (the
    specimen's own packings), to the FEM runs' final strain; cached as ``pure_dem.csv``."""
    path = folder / "pure_dem.csv"
    if not path.exists():
        data = load_rve(rves).take(list(range(len(scale.seeds))))
        steps = scale.fem_axial_strain / scale.dem_strain_per_step
        curve = biaxial_test(DEMBatch(data, device=device), axial_strain=scale.fem_axial_strain,
                             confining=scale.pressure, strain_per_step=scale.dem_strain_per_step,
                             record_every=max(1, round(steps / 200)))
        write_csv(curve, path)
    return pd.read_csv(path)


def compare_with_dem(fem: pd.DataFrame, dem: pd.DataFrame) -> dict[str, float]:
    """The FEM curve against the pure-DEM tests: errors against their mean curve (see
    :func:`~granular_material.results.compare.curve_errors`) and the DEM seeds' scatter of
    the peak σ1/σ3 [%]."""
    per_rve = [g for _, g in dem.groupby("rve")]
    errors = curve_errors(fem[fem["step"] > 0], mean_curve(per_rve))
    peaks = [g["stress_ratio"].max() for g in per_rve]
    scatter = (100.0 * float(np.std(peaks, ddof=1) / np.mean(peaks)) if len(peaks) > 1
               else math.nan)
    return {**errors, "dem_peak_scatter_pct": scatter, "dem_rves": len(per_rve)}


def softening_and_dilation(curve: pd.DataFrame) -> dict[str, float]:
    """Fig. 6's features of a σ1/σ3–εa–εv curve: the drop from the peak to the last point
    [% of the peak], and the volumetric strain gained after its minimum (dilation, tension
    positive) [-]."""
    ratio = curve["stress_ratio"].to_numpy()
    ev = curve["volumetric_strain"].to_numpy()
    peak = float(np.nanmax(ratio))
    return {"softening_pct": 100.0 * (1.0 - float(ratio[-1]) / peak),
            "dilation_after_minimum": float(ev[-1] - np.nanmin(ev))}


def post_peak_roughness(curve: pd.DataFrame) -> float:
    """How jagged σ1/σ3 is after its peak [% of the peak]: the RMS of its second differences
    from one load step to the next (0 for a straight or smoothly curved line at this
    sampling); NaN with fewer than three points after the peak."""
    ratio = curve["stress_ratio"].to_numpy()
    after = ratio[int(np.nanargmax(ratio)):]
    if after.size < 3:
        return math.nan
    return 100.0 * float(np.sqrt(np.mean(np.diff(after, 2) ** 2))) / float(after[0])


# -- Figs. 8–10: the band and three RVEs ------------------------------------------------------
def _element_grid(points: pd.DataFrame, elements: tuple[int, int]) -> pd.Series:
    """Each element's (column, row) in the mesh, from its Gauss points' centre."""
    nx, ny = elements
    centres = points.groupby("element")[["x", "y"]].mean()
    width = points["x"].max() + points["x"].min()  # the points sit symmetrically in the mesh
    height = points["y"].max() + points["y"].min()
    col = np.clip((centres["x"] / width * nx).astype(int), 0, nx - 1)
    row = np.clip((centres["y"] / height * ny).astype(int), 0, ny - 1)
    return pd.Series(list(zip(col, row, strict=True)), index=centres.index)


def band_crossing(points: pd.DataFrame, step: int, elements: tuple[int, int],
                  fraction: float = 0.15) -> dict[str, object]:
    """Whether the band (the ``fraction`` of Gauss points of largest shear strain at
    ``step``) runs through the specimen: the elements holding a band point, joined through
    shared edges or corners, connect the two lateral sides or the two platens, or a platen
    to a side while spanning at least half the width and half the height. Returns
    ``through_going`` and the sides the group touches (of a crossing group when there is
    one)."""
    nx, ny = elements
    at = points[points["step"] == step]
    count = max(3, round(fraction * len(at)))
    band = at.nlargest(count, "shear_strain")
    grid = _element_grid(at, elements)
    mask = np.zeros((nx, ny), dtype=bool)
    for element in band["element"].unique():
        mask[grid[element]] = True
    labels, n = ndimage.label(mask, structure=np.ones((3, 3)))
    best: set[str] = set()
    through = False
    for label in range(1, n + 1):
        cols, rows = np.nonzero(labels == label)
        sides = {name for name, touches in (("left", cols.min() == 0),
                                            ("right", cols.max() == nx - 1),
                                            ("bottom", rows.min() == 0),
                                            ("top", rows.max() == ny - 1)) if touches}
        wide = cols.max() - cols.min() + 1 >= nx / 2 and rows.max() - rows.min() + 1 >= ny / 2
        crosses = ({"left", "right"} <= sides or {"top", "bottom"} <= sides
                   or (wide and bool(sides & {"top", "bottom"})
                       and bool(sides & {"left", "right"})))
        if crosses or (not through and len(sides) > len(best)):
            best, through = sides, through or crosses
    return {"through_going": bool(through), "sides": sorted(best)}


def choose_points(points: pd.DataFrame, step: int, fraction: float = 0.15) -> dict[str, int]:
    """The three RVEs of Figs. 9–10, from the shear strain γ at ``step``: ``inside`` the
    band, the point of largest γ; ``outside``, the point of smallest γ; ``edge``, the point
    ranked just below the band (the band being the ``fraction`` of points of largest γ, as in
    :func:`~granular_material.results.shear_band`)."""
    at = points[points["step"] == step].sort_values("shear_strain", ascending=False)
    count = max(3, round(fraction * len(at)))
    return {"outside": int(at["point"].iloc[-1]), "inside": int(at["point"].iloc[0]),
            "edge": int(at["point"].iloc[count])}


def _principal_ratio(frame: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """σ1/σ3 and σ1 − σ3 [Pa] (compression positive) of the stress rows of ``frame``."""
    centre = 0.5 * (frame["sxx"] + frame["syy"]).to_numpy()
    radius = np.hypot(0.5 * (frame["sxx"] - frame["syy"]), frame["sxy"]).to_numpy()
    sigma1, sigma3 = -(centre - radius), -(centre + radius)
    return sigma1 / sigma3, sigma1 - sigma3


def point_histories(points: pd.DataFrame, tracked: pd.DataFrame,
                    chosen: dict[str, int]) -> pd.DataFrame:
    """Per chosen point and tracked step: axial strain, σ1/σ3, σ1 − σ3 [Pa], ``contraction``
    (the volumetric strain, compression positive as in the figures), void ratio, D0, α0."""
    rows = []
    for role, point in chosen.items():
        mine = points[points["point"] == point]
        fractal = tracked[(tracked["point"] == point)
                          & (tracked["postprocessor"] == "pore-fractal")]
        joined = fractal[["step", "D0", "alpha0"]].merge(mine, on="step")
        ratio, deviator = _principal_ratio(joined)
        rows.append(pd.DataFrame({"role": role, "point": point, "step": joined["step"],
                                  "axial_strain": joined["axial_strain"],
                                  "stress_ratio": ratio, "deviator": deviator,
                                  "contraction": -joined["volumetric_strain"],
                                  "void_ratio": joined["void_ratio"], "D0": joined["D0"],
                                  "alpha0": joined["alpha0"]}))
    return pd.concat(rows, ignore_index=True)


def fractal_fits(histories: pd.DataFrame) -> pd.DataFrame:
    """Fig. 10: least-squares lines of D0 and α0 against the volumetric strain (compression
    positive) for each chosen point: slope, its standard error, intercept, R², and the
    range of volumetric strain covered; NaN where fewer than three samples (a run that
    stopped early) or no change of volume leave no line to fit."""
    rows = []
    for (role, point), history in histories.groupby(["role", "point"], sort=False):
        ev = history["contraction"].to_numpy()
        for index in ("D0", "alpha0"):
            line = {"slope": math.nan, "slope_se": math.nan, "intercept": math.nan,
                    "r2": math.nan}
            if len(ev) >= 3 and np.ptp(ev) > 0:
                fit = stats.linregress(ev, history[index].to_numpy())
                line = {"slope": fit.slope, "slope_se": fit.stderr,
                        "intercept": fit.intercept, "r2": fit.rvalue ** 2}
            rows.append({"role": role, "point": int(point), "index": index, **line,
                         "ev_range": float(np.ptp(ev)) if len(ev) else math.nan,
                         "samples": len(ev)})
    return pd.DataFrame(rows)


def slopes_differ(fits: pd.DataFrame, index: str, a: str, b: str) -> dict[str, float]:
    """Whether the slopes of ``index`` at roles ``a`` and ``b`` differ by more than two
    standard errors of their difference."""
    one = fits[(fits["index"] == index) & (fits["role"] == a)].iloc[0]
    two = fits[(fits["index"] == index) & (fits["role"] == b)].iloc[0]
    se = math.hypot(one["slope_se"], two["slope_se"])
    return {"difference": float(one["slope"] - two["slope"]), "two_se": 2.0 * se,
            "differ": bool(abs(one["slope"] - two["slope"]) > 2.0 * se)}


def band_at(points: pd.DataFrame, strain: float, elements: tuple[int, int]) -> dict:
    """The shear-band measures and :func:`band_crossing` at the step nearest ``strain``."""
    steps = points.groupby("step")["axial_strain"].first()
    step = int((steps - strain).abs().idxmin())
    return {**shear_band(points, step).as_dict(), **band_crossing(points, step, elements)}
