"""Figs. 3–5 of Wu et al. (2025): how large an RVE must be.

RVEs of 10², 12², …, 30² discs × seeds are compacted to e0 and consolidated at p0, the
multifractal spectrum of each one's pore space is taken (q–D_q, α–f(α)), and α0/D0 is
followed against the number of discs (:func:`settle_size` says from which size on it no
longer moves); the drained biaxial tests of a few sizes say the same from the stress–strain
side (:func:`size_responses`). Everything is cached under the part's folder as it is made.

Every spectrum is taken under both box rules of the pore fractal plugin: ``cell`` (the
paper's ε = 2⁻ᵏL, on a window of m·256 pixels) and ``physical`` (boxes of 2.4–38.4 mm at
the requested pixel, the same for every size); :func:`resolution_study` takes the indices of
one size's RVEs at pixels from 0.6 to 0.075 mm under both.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
from granular_material_pore_fractal.boxes import BOX_RULES
from granular_material_pore_fractal.postprocess import analyse_rve

from granular_material.dem import DEMBatch, load_rve, save_rve, void_ratio
from granular_material.procedures import biaxial_test, prepare_packing, progress_bar
from granular_material.results import write_csv
from granular_material.results.peaks import find_peak

from .scales import ReproductionScale

#: tolerances [%] of the practical settling sizes :func:`settle_size` reports beside the
#: statistical one
SETTLE_TOLERANCES_PCT = (2.0, 1.0, 0.5)

#: requested pixels [m] of the resolution study, coarse to fine
RESOLUTION_PIXELS = (0.6e-3, 0.3e-3, 0.15e-3, 0.075e-3)

__all__ = ["RESOLUTION_PIXELS", "SETTLE_TOLERANCES_PCT", "packings", "resolution_changes",
           "resolution_study", "response_agreement", "settle_size", "size_responses",
           "size_spectra", "size_tests"]


def packings(scale: ReproductionScale, discs: int, folder: Path, device: str) -> Path:
    """The seeds' packings of ``discs`` discs, compacted to e0 and consolidated at p0; an
    RVE file of one RVE per seed (RVE b: seed ``seeds[0] + b``), prepared once."""
    path = folder / "rves" / f"discs{discs}.npz"
    if not path.exists():
        seeds = scale.seeds
        if list(seeds) != list(range(seeds[0], seeds[0] + len(seeds))):
            raise ValueError(f"seeds must be consecutive, got {seeds}")
        batch = prepare_packing(n_disc=discs, n_rve=len(seeds), seed=seeds[0],
                                pressure=scale.pressure, target_void_ratio=scale.void_ratio,
                                device=device)
        path.parent.mkdir(parents=True, exist_ok=True)
        save_rve(path, batch.to_data())
    return path


#: the columns of ``indices.csv``
INDEX_COLUMNS = ("discs", "seed", "box_rule", "void_ratio", "D0", "alpha0", "alpha0_over_D0",
                 "D0_se", "alpha0_se", "alpha0_over_D0_se", "min_r2", "r2_q0",
                 "dq_decreasing", "pixel_size", "image_size", "box_min_m", "box_max_m")


def _index_row(image, spectrum) -> dict[str, float]:
    """The indices, their standard errors, fit quality and boxes of one spectrum."""
    return {"D0": float(spectrum.D0), "alpha0": float(spectrum.alpha0),
            "alpha0_over_D0": float(spectrum.alpha0_over_D0),
            "D0_se": float(spectrum.D0_se), "alpha0_se": float(spectrum.alpha0_se),
            "alpha0_over_D0_se": float(spectrum.alpha0_over_D0_se),
            "min_r2": float(np.min(spectrum.r2)), "r2_q0": float(spectrum.r2_q0),
            "dq_decreasing": bool(np.all(np.diff(spectrum.Dq) <= 1e-9)),
            "pixel_size": image.pixel_size, "image_size": image.n_pixels,
            "box_min_m": float(spectrum.box_px.min() * image.pixel_size),
            "box_max_m": float(spectrum.box_px.max() * image.pixel_size)}


def size_spectra(scale: ReproductionScale, folder: Path, device: str,
                 progress: bool = False) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The spectra of every RVE of Figs. 3–4 under both box rules (``spectra.csv``: discs,
    seed, box_rule, q, Dq, alpha, f) and their indices (``indices.csv``: discs, seed,
    box_rule, void_ratio, D0, alpha0, alpha0_over_D0 and their standard errors (_se),
    min_r2 (the smallest R² of its fits), r2_q0 (the smallest R² of the fits at q = 0, which
    give D0 and α0), dq_decreasing (D_q never rises with q), pixel_size [m], image_size [px],
    box_min_m and box_max_m (the fit range) [m]); read back when written."""
    spectra_path, indices_path = folder / "spectra.csv", folder / "indices.csv"
    if spectra_path.exists() and indices_path.exists():
        indices = pd.read_csv(indices_path)
        if set(INDEX_COLUMNS) <= set(indices.columns):  # else: of an older version, redone
            return pd.read_csv(spectra_path), indices
    spectra, indices = [], []
    with progress_bar(len(scale.sizes), "RVE sizes: packings and spectra", progress,
                      unit="size") as bar:
        for discs in scale.sizes:
            data = load_rve(packings(scale, discs, folder, device))
            void = void_ratio(data.radius, data.cell)
            for b, seed in enumerate(scale.seeds):
                for rule in BOX_RULES:
                    image, spectrum = analyse_rve(data, b, box_rule=rule)
                    spectra.append(pd.DataFrame({"discs": discs, "seed": seed,
                                                 "box_rule": rule, "q": spectrum.q,
                                                 "Dq": spectrum.Dq, "alpha": spectrum.alpha,
                                                 "f": spectrum.f}))
                    indices.append({"discs": discs, "seed": seed, "box_rule": rule,
                                    "void_ratio": float(void[b]),
                                    **_index_row(image, spectrum)})
            bar.update(1)
    write_csv(pd.concat(spectra, ignore_index=True), spectra_path)
    write_csv(pd.DataFrame(indices), indices_path)
    return pd.read_csv(spectra_path), pd.read_csv(indices_path)


#: the columns of ``resolution.csv``
RESOLUTION_COLUMNS = ("discs", "seed", "box_rule", "pixel_request", *INDEX_COLUMNS[4:])


def resolution_study(scale: ReproductionScale, folder: Path, device: str,
                     progress: bool = False) -> pd.DataFrame:
    """The indices of the seeds' RVEs of ``scale.resolution_discs`` discs at every pixel of
    :data:`RESOLUTION_PIXELS` under both box rules (``resolution.csv``: discs, seed,
    box_rule, pixel_request [m] and the columns of ``indices.csv`` from D0 on); read back
    when written."""
    path = folder / "resolution.csv"
    if path.exists():
        table = pd.read_csv(path)
        if set(RESOLUTION_COLUMNS) <= set(table.columns):
            return table
    discs = scale.resolution_discs
    data = load_rve(packings(scale, discs, folder, device))
    rows = []
    with progress_bar(len(RESOLUTION_PIXELS), f"RVE sizes: resolution study ({discs} discs)",
                      progress, unit="pixel") as bar:
        for pixel in RESOLUTION_PIXELS:
            for b, seed in enumerate(scale.seeds):
                for rule in BOX_RULES:
                    image, spectrum = analyse_rve(data, b, pixel, box_rule=rule)
                    rows.append({"discs": discs, "seed": seed, "box_rule": rule,
                                 "pixel_request": pixel, **_index_row(image, spectrum)})
            bar.update(1)
    write_csv(pd.DataFrame(rows), path)
    return pd.read_csv(path)


def resolution_changes(table: pd.DataFrame) -> pd.DataFrame:
    """Per box rule and pixel: the seeds' mean and standard deviation of D0, α0 and α0/D0,
    the image side [px], and the change [%] of the means of D0 and α0/D0 from the next
    coarser pixel."""
    stats = table.groupby(["box_rule", "pixel_request"]).agg(
        image_px=("image_size", "mean"), D0_mean=("D0", "mean"), D0_std=("D0", "std"),
        alpha0_mean=("alpha0", "mean"), ratio_mean=("alpha0_over_D0", "mean"),
        ratio_std=("alpha0_over_D0", "std"), D0_se=("D0_se", "mean"),
        r2_q0=("r2_q0", "min"), box_min_m=("box_min_m", "mean"),
        box_max_m=("box_max_m", "mean")).reset_index()
    stats = stats.sort_values(["box_rule", "pixel_request"], ascending=[True, False])
    for column, name in (("D0_mean", "D0_change_pct"), ("ratio_mean", "ratio_change_pct")):
        stats[name] = 100.0 * stats.groupby("box_rule")[column].pct_change()
    return stats.reset_index(drop=True)


def _stats(table: pd.DataFrame, column: str) -> pd.DataFrame:
    """Mean, seed standard deviation and standard error of ``column`` per number of discs."""
    grouped = table.groupby("discs")[column]
    stats = pd.DataFrame({"mean": grouped.mean(), "std": grouped.std(ddof=1),
                          "n": grouped.count()})
    stats["se"] = stats["std"] / np.sqrt(stats["n"])
    stats["scatter_pct"] = 100.0 * stats["std"] / stats["mean"].abs()
    return stats


def settle_size(indices: pd.DataFrame, column: str = "alpha0_over_D0") -> dict[str, float]:
    """From which size on ``column`` has settled, by the rule: the smallest number of discs
    n such that at every size m ≥ n the seeds' mean lies within two standard errors
    (√(SE_m² + SE_max²)) of the largest size's mean. Returns that size, the seed scatter
    (standard deviation over the seeds, and as % of the mean) there and at every size, and
    how far the means move above and below it; and, for each tolerance of
    :data:`SETTLE_TOLERANCES_PCT`, the smallest size from which every mean lies within it of
    the largest size's mean (``within_<t>pct_from``)."""
    stats = _stats(indices, column)
    sizes = list(stats.index)
    largest = stats.loc[sizes[-1]]

    def agrees(m: int) -> bool:
        band = 2.0 * math.hypot(stats.loc[m, "se"], largest["se"])
        return abs(stats.loc[m, "mean"] - largest["mean"]) <= band

    settled = sizes[-1]
    for n in sizes:
        if all(agrees(m) for m in sizes if m >= n):
            settled = n
            break
    def within(tolerance: float) -> int:
        """The smallest size from which every mean is within ``tolerance`` (relative) of
        the largest size's."""
        for n in sizes:
            if all(abs(stats.loc[m, "mean"] / largest["mean"] - 1.0) <= tolerance
                   for m in sizes if m >= n):
                return int(n)
        return int(sizes[-1])

    above = stats.loc[[m for m in sizes if m >= settled], "mean"]
    below = stats.loc[[m for m in sizes if m < settled], "mean"]
    return {
        "settle_discs": int(settled),
        "scatter_at_settle": float(stats.loc[settled, "std"]),
        "scatter_pct_at_settle": float(stats.loc[settled, "scatter_pct"]),
        "scatter_pct_smallest": float(stats.loc[sizes[0], "scatter_pct"]),
        "scatter_pct_largest": float(largest["scatter_pct"]),
        "range_above": float(above.max() - above.min()),
        "range_below": float(below.max() - below.min()) if len(below) > 1 else math.nan,
        "mean_largest": float(largest["mean"]),
        **{f"within_{pct:g}pct_from": within(pct / 100.0) for pct in SETTLE_TOLERANCES_PCT},
    }


def size_tests(scale: ReproductionScale, folder: Path, device: str,
               progress: bool = False) -> pd.DataFrame:
    """Fig. 5: the drained biaxial test of every seed's RVE of each size of
    ``biaxial_sizes``, confined at p0 (``curves.csv``: discs, seed and the rows of
    :func:`~granular_material.procedures.biaxial_test`); each size's curves are written as
    soon as they are done, and read back on a rerun."""
    curves = []
    with progress_bar(len(scale.biaxial_sizes), "RVE sizes: biaxial tests", progress,
                      unit="size") as bar:
        for discs in scale.biaxial_sizes:
            path = folder / "curves" / f"discs{discs}.csv"
            if not path.exists():
                data = load_rve(packings(scale, discs, folder, device))
                steps = scale.dem_axial_strain / scale.dem_strain_per_step
                curve = biaxial_test(DEMBatch(data, device=device),
                                     axial_strain=scale.dem_axial_strain,
                                     confining=scale.pressure,
                                     strain_per_step=scale.dem_strain_per_step,
                                     record_every=max(1, round(steps / 200)))
                curve.insert(0, "seed", [scale.seeds[int(r)] for r in curve["rve"]])
                curve.insert(0, "discs", discs)
                path.parent.mkdir(parents=True, exist_ok=True)
                write_csv(curve, path)
            curves.append(pd.read_csv(path))
            bar.update(1)
    return pd.concat(curves, ignore_index=True)


def size_responses(curves: pd.DataFrame) -> pd.DataFrame:
    """Per size and seed: peak σ1/σ3, the axial strain at it, σ1/σ3 and εv at the last
    strain (the residual state)."""
    rows = []
    for (discs, seed), curve in curves.groupby(["discs", "seed"]):
        strain = curve["axial_strain"].to_numpy()
        ratio = curve["stress_ratio"].to_numpy()
        peak, peak_ratio = find_peak(strain, ratio)
        rows.append({"discs": int(discs), "seed": int(seed), "peak_stress_ratio": peak_ratio,
                     "strain_at_peak": float(strain[peak]),
                     "final_stress_ratio": float(ratio[-1]),
                     "final_volumetric_strain": float(curve["volumetric_strain"].iloc[-1])})
    return pd.DataFrame(rows)


def response_agreement(responses: pd.DataFrame, discs: int,
                       column: str = "peak_stress_ratio") -> dict[str, float]:
    """How far the seeds' mean ``column`` at ``discs`` lies from that of every larger size
    pooled, against two standard errors of the difference (the seed scatter's share)."""
    at = responses[responses["discs"] == discs][column]
    larger = responses[responses["discs"] > discs][column]
    if at.empty or len(larger) < 2:
        return {"difference_pct": math.nan, "two_se_pct": math.nan, "agrees": False}
    base = float(larger.mean())
    two_se = 2.0 * math.hypot(at.std(ddof=1) / math.sqrt(len(at)),
                              larger.std(ddof=1) / math.sqrt(len(larger)))
    return {"difference_pct": 100.0 * (float(at.mean()) / base - 1.0),
            "two_se_pct": 100.0 * two_se / base,
            "agrees": bool(abs(float(at.mean()) - base) <= two_se)}
