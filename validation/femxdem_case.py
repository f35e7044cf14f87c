"""The ``gz-femxdem`` cases: Guo & Zhao's own FEM × DEM code against ours, same biaxial.

Both codes run the drained biaxial specimen of Guo & Zhao's example (50 mm × 100 mm, smooth
platens, one bottom node pinned, the confining stress on the sides, equal load steps of axial
strain) on the same mesh, every Gauss point starting from the same RVE (their
``prepareRVE.py`` procedure, one RVE copied to every point). Theirs is run as shipped (8-node
quadrilaterals, 2 × 2 Gauss points, Newton ``rtol = 1e-2`` on ‖δu‖/‖Δu‖; see
:mod:`granular_material_validation.guo_zhao_runner`); ours with its defaults (``ours-defaults``:
Q4, finite strain, the condensed tangent held over each increment, Aitken relaxation and Guo &
Zhao's displacement test judged one iterate earlier), as Guo & Zhao (``ours-as-gz``: their
8-node elements and convergence test, our defaults otherwise), and, where the command line
has the options, with 9-node elements (``ours-q9``), in small strain
(``ours-small-strain``) and on a mesh twice as fine (``ours-fine``), so that the band can be
put on the element, the mesh or the kinematics.
The curve judged is ``ours-as-gz`` when it runs, else ``ours-defaults``. Chaos baseline:
their code against itself at 1 % less strain a load step.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from granular_material_validation import engine_runner, guo_zhao_runner, metrics

__all__ = ["AS_GZ", "BAND_STRAINS", "PERTURBATION", "band_measures", "cost_figures",
           "field_comparison", "ours_variants", "run_femxdem_seed", "shear_strain"]

#: our run spec fields (flat names) that reproduce Guo & Zhao's element and convergence test
AS_GZ = {"element": "quad8", "convergence": "displacement", "rtol": 1e-2}
#: the chaos baseline's strain a load step, relative to the case's
PERTURBATION = 0.99


#: axial strains [-] of the band measures: σ1/σ3 (all), σyy spread and γmax/γmean (the
#: second and last), after the issue that measured Guo & Zhao's band
BAND_STRAINS = (0.016, 0.02, 0.022, 0.025)


def ours_variants(elements: tuple[int, int] = (2, 4)) -> dict[str, dict[str, Any]]:
    """Our runs of the case and the run spec fields (flat names) each sets: defaults; as
    Guo & Zhao (their element and convergence test); with 9-node elements; in small strain;
    and on a mesh of twice the ``elements`` each way."""
    fine = [2 * int(elements[0]), 2 * int(elements[1])]
    return {"ours-defaults": {}, "ours-as-gz": dict(AS_GZ), "ours-q9": {"element": "quad9"},
            "ours-small-strain": {**AS_GZ, "formulation": "small-strain"},
            "ours-fine": {**AS_GZ, "elements": fine}}


def band_measures(curve: pd.DataFrame, points: pd.DataFrame,
                  strains: tuple[float, ...] = BAND_STRAINS) -> dict[str, Any]:
    """The shear band of one run: σ1/σ3 of the volume-average stress at ``strains`` [-], and
    at each of them the spread (s.d. over the points, kPa) of σyy and γmax/γmean of the
    Gauss points (None past the run's end); ``curve`` has ``step``, ``axial_strain``,
    ``sxx``, ``syy``, ``sxy``, ``points`` has ``step``, ``syy``, ``exx``, ``eyy``, ``exy``."""
    x = curve["axial_strain"].to_numpy(dtype=np.float64)
    out: dict[str, Any] = {"strains": list(strains), "ratio": [], "syy_sd_kpa": [],
                           "localisation": []}
    for strain in strains:
        out["ratio"].append(_ratio_at(curve, strain))
        k = int(np.argmin(np.abs(x - strain)))
        rows = points[points["step"] == curve["step"].iloc[k]]
        if abs(x[k] - strain) > 1e-6 or rows.empty:
            out["syy_sd_kpa"].append(None)
            out["localisation"].append(None)
            continue
        g = shear_strain(rows["exx"], rows["eyy"], rows["exy"])
        out["syy_sd_kpa"].append(float((rows["syy"].to_numpy(dtype=np.float64) / 1e3).std()))
        out["localisation"].append(float(g.max() / g.mean()) if g.mean() > 0 else None)
    return out


def shear_strain(exx: np.ndarray, eyy: np.ndarray, exy: np.ndarray) -> np.ndarray:
    """Deviatoric shear strain γ = √(2 e:e) of the deviator e of ε (as in Guo & Zhao's
    example), from the components of the symmetric strain [-]."""
    return np.sqrt((np.asarray(exx) - np.asarray(eyy)) ** 2 + 4.0 * np.asarray(exy) ** 2)


def field_comparison(theirs: pd.DataFrame, ours: pd.DataFrame, step: int) -> dict[str, Any]:
    """Gauss-point fields of both codes after load step ``step``.

    ``theirs`` and ``ours`` hold ``step``, ``x``, ``y`` (reference coordinates [m]),
    ``sxx``, ``syy``, ``sxy`` [Pa], ``exx``, ``eyy``, ``exy`` and ``void_ratio`` per point;
    points are matched by their coordinates. Returns, per code, the mean and spread (s.d.
    over the points) of σyy [kPa, compression positive], the mean and largest γ and their
    ratio (a localisation index: 1 for a uniform field), and the differences point by point
    (RMS and largest |Δσyy| [kPa], RMS Δe, correlation of the γ fields).
    """
    a = theirs[theirs["step"] == step].reset_index(drop=True)
    b = ours[ours["step"] == step].reset_index(drop=True)
    if a.empty or b.empty or len(a) != len(b):
        raise ValueError(f"step {step}: {len(a)} points of theirs against {len(b)} of ours")
    xy_a = a[["x", "y"]].to_numpy(dtype=np.float64)
    xy_b = b[["x", "y"]].to_numpy(dtype=np.float64)
    dist = np.linalg.norm(xy_a[:, None, :] - xy_b[None, :, :], axis=2)
    match = dist.argmin(axis=1)
    if len(set(match.tolist())) != len(match):
        raise ValueError(f"step {step}: Gauss points of the two meshes do not match one to one")
    b = b.iloc[match].reset_index(drop=True)
    out: dict[str, Any] = {"step": int(step), "points": len(a),
                           "largest_point_distance_m": float(dist.min(axis=1).max())}
    gammas = {}
    for side, frame in (("theirs", a), ("ours", b)):
        g = shear_strain(frame["exx"], frame["eyy"], frame["exy"])
        gammas[side] = g
        syy = -frame["syy"].to_numpy(dtype=np.float64) / 1e3
        out[side] = {"syy_mean_kpa": float(syy.mean()), "syy_sd_kpa": float(syy.std()),
                     "gamma_mean": float(g.mean()), "gamma_max": float(g.max()),
                     "localisation": float(g.max() / g.mean()) if g.mean() > 0 else None,
                     "void_ratio_sd": float(frame["void_ratio"].std(ddof=0))}
    dsyy = (b["syy"] - a["syy"]).to_numpy(dtype=np.float64) / 1e3
    de = (b["void_ratio"] - a["void_ratio"]).to_numpy(dtype=np.float64)
    ga, gb = gammas["theirs"], gammas["ours"]
    corr = (float(np.corrcoef(ga, gb)[0, 1]) if ga.std() > 0 and gb.std() > 0 else None)
    out["diff"] = {"syy_rms_kpa": float(np.sqrt(np.mean(dsyy ** 2))),
                   "syy_max_kpa": float(np.abs(dsyy).max()),
                   "void_ratio_rms": float(np.sqrt(np.mean(de ** 2))),
                   "gamma_correlation": corr}
    return out


def cost_figures(curve: pd.DataFrame, points: int, particles: int, peak_step: int,
                 wall_s: float, threads: int, theirs: bool, cpu_s: float | None = None,
                 last_step: int | None = None) -> dict[str, Any]:
    """Newton iterations and DEM steps a load step (before and after ``peak_step``, all)
    and the wall time of the load steps (``stepping_s``), over steps 1 to ``last_step``
    (all when None); the whole run's wall time [s], core-seconds (wall × ``threads``) and
    CPU time [s]."""
    rows = curve[curve["step"] > 0]
    if last_step is not None:
        rows = rows[rows["step"] <= last_step]
    if theirs:
        dem = rows["dem_steps"].to_numpy(dtype=np.float64) / points
    else:
        dem = rows["particle_steps"].to_numpy(dtype=np.float64) / (particles * points)
    it = rows["iterations"].to_numpy(dtype=np.float64)
    pre = rows["step"].to_numpy() <= peak_step

    def mean(values: np.ndarray) -> float | None:
        return float(values.mean()) if values.size else None

    return {"iterations_pre_peak": mean(it[pre]), "iterations_post_peak": mean(it[~pre]),
            "iterations_all": mean(it), "dem_steps_per_point_pre_peak": mean(dem[pre]),
            "dem_steps_per_point_post_peak": mean(dem[~pre]),
            "dem_steps_per_point_all": mean(dem), "load_steps": len(rows),
            "stepping_s": float(rows["wall_time"].sum()), "last_step": int(rows["step"].max()),
            "wall_s": float(wall_s), "threads": int(threads),
            "core_s": float(wall_s) * int(threads), "cpu_s": cpu_s}


def _our_threads(summary: dict[str, Any]) -> int:
    for key in ("shards", "threads"):
        if isinstance(summary.get(key), int) and summary[key] > 0:
            return int(summary[key])
    return os.cpu_count() or 1


def _ratio_at(curve: pd.DataFrame, strain: float) -> float | None:
    x = curve["axial_strain"].to_numpy(dtype=np.float64)
    if strain > x[-1] + 1e-12:
        return None
    return float(np.interp(strain, x, metrics.stress_ratio(curve)))


def run_femxdem_seed(case: Any, seed: int, rve: Path, prep: dict[str, Any], work: Path,
                     device: str) -> dict[str, Any]:
    """Run one seed of a ``femxdem`` case in both codes; the pieces of its ``SeedRun``.

    Returns ``yade`` (their curve), ``ours`` (the curve judged), ``baseline`` (their code at
    :data:`PERTURBATION` × the strain a step), ``curves`` (every run of ours), the wall
    times and ``extra`` (comparisons of every run of ours, Gauss-point fields at a third,
    two thirds and the end of the path, the cost table, their patches).
    """
    per_step = case.axial_strain / case.steps
    elements = tuple(case.elements)
    theirs, tsum = guo_zhao_runner.guo_zhao_biaxial(
        rve, work / "guo_zhao", elements=elements, steps=case.steps, strain_per_step=per_step,
        confining=case.pressure, timeout=case.time_limit)
    their_fields = guo_zhao_runner.gauss_fields(work / "guo_zhao")
    points = int(their_fields["point"].nunique())
    runs: dict[str, tuple[pd.DataFrame, pd.DataFrame, dict[str, Any]]] = {}
    for name, options in ours_variants(elements).items():
        runs[name] = engine_runner.ours_femxdem_biaxial(
            rve, work / name, elements=elements, axial_strain=case.axial_strain,
            steps=case.steps, confining=case.pressure, extra=options, device=device)
    judged = "ours-as-gz" if "ours-as-gz" in runs else "ours-defaults"
    slower, bsum = guo_zhao_runner.guo_zhao_biaxial(
        rve, work / "guo_zhao_perturbed", elements=elements, steps=case.steps,
        strain_per_step=PERTURBATION * per_step, confining=case.pressure,
        timeout=case.time_limit)
    ref_cmp = metrics.compare_curves(theirs, theirs)
    peak_step = int(theirs.loc[np.argmin(np.abs(theirs["axial_strain"]
                                                - ref_cmp.strain_at_peak_argmax_ref)), "step"])
    done = int(tsum["steps_done"])
    chosen = sorted({max(1, done // 3), max(1, 2 * done // 3), done})
    cost = {"guo-zhao": cost_figures(theirs, points, case.particles, peak_step,
                                     tsum["wall_s"], tsum["processes"], theirs=True,
                                     cpu_s=tsum.get("cpu_s"))}
    comparisons, fields = {}, {}
    strains = [s for s in (0.01, 0.02, 0.03, 0.05, 0.07) if s <= case.axial_strain + 1e-12]
    ratios = {"guo-zhao": [_ratio_at(theirs, s) for s in strains],
              "guo-zhao-perturbed": [_ratio_at(slower, s) for s in strains]}
    bands = {"guo-zhao": band_measures(theirs, their_fields)}
    for name, (curve, pts, summary) in runs.items():
        bands[name] = band_measures(curve, pts)
        comparisons[name] = metrics.compare_curves(theirs, curve).to_dict()
        cost[name] = cost_figures(curve, points, case.particles, peak_step,
                                  summary["wall_s"], _our_threads(summary), theirs=False,
                                  cpu_s=summary.get("cpu_s"), last_step=done)
        cost[name]["stepping_speedup"] = (cost["guo-zhao"]["stepping_s"]
                                          / cost[name]["stepping_s"])
        cost[name]["speedup_wall"] = tsum["wall_s"] / summary["wall_s"]
        cost[name]["speedup_per_core"] = cost["guo-zhao"]["core_s"] / cost[name]["core_s"]
        if cost["guo-zhao"]["cpu_s"] and cost[name]["cpu_s"]:
            cost[name]["speedup_cpu"] = cost["guo-zhao"]["cpu_s"] / cost[name]["cpu_s"]
        if pts["point"].nunique() == points:  # the same Gauss points as theirs
            fields[name] = [field_comparison(their_fields, pts, k) for k in chosen]
        ratios[name] = [_ratio_at(curve, s) for s in strains]
    extra = {"packing": prep, "judged": judged, "comparisons": comparisons,
             "guo_zhao_perturbed_vs_guo_zhao": {
                 **metrics.compare_curves(theirs, slower).to_dict(),
                 "strain_per_step": PERTURBATION * per_step},
             "fields": fields, "cost": cost, "ratios_at": {"strains": strains, **ratios},
             "bands": bands, "options": ours_variants(elements),
             "points": points, "elements": list(elements), "strain_per_step": per_step,
             "guo_zhao_patches": tsum["patches"], "guo_zhao_rve_state": tsum["rve_state"],
             "baseline_wall_s": bsum["wall_s"], "steps": case.steps,
             "guo_zhao_steps_done": done, "guo_zhao_perturbed_steps_done": bsum["steps_done"],
             "time_limit_s": case.time_limit}
    curve, _, summary = runs[judged]
    for name, (c, _, _) in runs.items():
        c.to_csv(work / f"{name}_curve.csv", index=False)
    theirs.to_csv(work / "guo_zhao_curve.csv", index=False)
    slower.to_csv(work / "guo_zhao_perturbed_curve.csv", index=False)
    return {"yade": theirs, "ours": curve, "baseline": slower,
            "curves": {name: c for name, (c, _, _) in runs.items()},
            "yade_wall_s": tsum["wall_s"], "yade_run_s": tsum["stepping_s"],
            "ours_wall_s": summary["wall_s"], "extra": extra}
