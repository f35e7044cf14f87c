"""The reproduction, part by part, resumable.

Each part (:data:`PARTS`) writes its tables and figures into its own folder under the
output folder and, last, its ``result.json``: a part with a ``result.json`` is done, and a
rerun skips it (``--redo PART`` runs it again from its caches, and times the speed-up
again). Inside a part, what is expensive is cached
as soon as it is made (packings, spectra, each size's curves, the FEM runs' checkpoints),
so an interrupted part restarts where it stopped; a FEM run checkpointed with other
settings (older defaults) is set aside and run afresh. ``report.md`` is written from the
``result.json`` files of the parts done.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pandas as pd

from granular_material.cli.signals import Terminated
from granular_material.dem import load_rve, save_rve
from granular_material.results import read_points, write_csv, write_json

from . import coupling, plots, rve_size, speedup
from .report import write_report
from .scales import SCALES, ReproductionScale

__all__ = ["PARTS", "run_reproduction"]

#: the parts, in order: name → the figures of the paper it reproduces
PARTS = {
    "rve-size": "Figs. 3–4",
    "size-biaxial": "Fig. 5",
    "element": "Fig. 6",
    "specimen": "Figs. 7–10",
    "speedup": "Fig. 11",
}

#: what a part's result.json holds; a part whose result.json has another is redone (from its
#: cached packings, curves and FEM checkpoints), so a report never mixes two layouts
RESULT_VERSION = 4

#: files a ``--redo`` of a part removes besides its result.json: measurements a rerun is
#: meant to take again (timings), not the caches of runs that would come out the same
_REDO_REMOVES = {"speedup": ("speedup.csv",)}

Log = Callable[[str], None]


def _json_ready(value: Any) -> Any:
    """``value`` with NaN and infinities as None and NumPy scalars as Python ones."""
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_ready(v) for v in value]
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _per_size(indices: pd.DataFrame) -> pd.DataFrame:
    """The seeds' means and scatter of the indices per number of discs (one box rule)."""
    per_size = indices.groupby("discs").agg(
        ratio_mean=("alpha0_over_D0", "mean"), ratio_std=("alpha0_over_D0", "std"),
        D0_mean=("D0", "mean"), alpha0_mean=("alpha0", "mean"),
        void_ratio_mean=("void_ratio", "mean"), min_r2=("min_r2", "min"),
        r2_q0=("r2_q0", "min"), ratio_fit_se=("alpha0_over_D0_se", "mean"),
        image_px=("image_size", "first"), box_min_mm=("box_min_m", "mean"),
        box_max_mm=("box_max_m", "mean"), rves=("seed", "count"),
        dq_decreasing_count=("dq_decreasing", "sum")).reset_index()
    per_size["box_min_mm"] *= 1e3
    per_size["box_max_mm"] *= 1e3
    per_size["ratio_scatter_pct"] = 100 * per_size["ratio_std"] / per_size["ratio_mean"]
    return per_size


def _part_rve_size(scale: ReproductionScale, folder: Path, device: str,
                   progress: bool) -> dict[str, Any]:
    spectra, indices = rve_size.size_spectra(scale, folder, device, progress)
    by_rule = {rule: indices[indices["box_rule"] == rule] for rule in ("cell", "physical")}
    settle = {rule: rve_size.settle_size(table) for rule, table in by_rule.items()}
    per_size = {rule: _per_size(table) for rule, table in by_rule.items()}
    cell = by_rule["cell"]
    plots.plot_spectra(spectra, scale.biaxial_sizes, folder / "fig3_spectra.png")
    plots.plot_ratio_by_size(indices, {rule: s["settle_discs"] for rule, s in settle.items()},
                             folder / "fig4_ratio.png")
    resolution = rve_size.resolution_study(scale, folder, device, progress)
    changes = rve_size.resolution_changes(resolution)
    write_csv(changes, folder / "resolution_summary.csv")
    plots.plot_resolution(resolution, folder / "fig4_resolution.png")
    return {"settle": settle["cell"], "settle_physical": settle["physical"],
            "per_size": per_size["cell"].to_dict("records"),
            "per_size_physical": per_size["physical"].to_dict("records"),
            "resolution_discs": scale.resolution_discs,
            "resolution": changes.to_dict("records"),
            "rves": len(cell), "dq_decreasing": int(cell["dq_decreasing"].sum()),
            "dq_decreasing_physical": int(by_rule["physical"]["dq_decreasing"].sum()),
            "void_ratio_range": [float(cell["void_ratio"].min()),
                                 float(cell["void_ratio"].max())]}


def _part_size_biaxial(scale: ReproductionScale, folder: Path, device: str,
                       progress: bool, root: Path) -> dict[str, Any]:
    curves = rve_size.size_tests(scale, root / "rve-size", device, progress)
    responses = rve_size.size_responses(curves)
    write_csv(responses, folder / "responses.csv")
    stats = responses.groupby("discs").agg(
        peak_mean=("peak_stress_ratio", "mean"), peak_std=("peak_stress_ratio", "std"),
        final_mean=("final_stress_ratio", "mean"), final_std=("final_stress_ratio", "std"),
        ev_final_mean=("final_volumetric_strain", "mean")).reset_index()
    agreement = {int(d): {"peak": rve_size.response_agreement(responses, int(d)),
                          "final": rve_size.response_agreement(responses, int(d),
                                                               "final_stress_ratio")}
                 for d in stats["discs"][:-1]}
    plots.plot_size_curves(curves, folder / "fig5_curves.png")
    return {"per_size": stats.to_dict("records"), "agreement": agreement}


def _first_rve(scale: ReproductionScale, root: Path, discs: int, device: str,
               path: Path) -> Path:
    """The first seed's packing of ``discs`` discs (of the RVE-size part) alone, as the RVE
    file ``path``; written once."""
    if not path.exists():
        packed = rve_size.packings(scale, discs, root / "rve-size", device)
        save_rve(path, load_rve(packed).take([0]))
    return path


def _fem_status(code: int, summary: dict[str, Any], what: str) -> str | None:
    """The run's error to report (Newton stopped: exit 1), or ``FEMRunError``."""
    if code == 0:
        return None
    if code == 1 and summary.get("error"):
        return str(summary["error"])
    if code == 143:
        raise Terminated(f"the {what} run was terminated")
    if code == 130:
        raise KeyboardInterrupt(f"the {what} run was interrupted")
    raise coupling.FEMRunError(f"the {what} run exited with code {code}; see its run.log")


def _part_element(scale: ReproductionScale, folder: Path, device: str, progress: bool,
                  root: Path) -> dict[str, Any]:
    rve = _first_rve(scale, root, scale.element_discs, device, folder / "rve.npz")
    code = coupling.run_element(scale, rve, folder, device)
    steps, summary = coupling.read_run(folder / "run")
    error = _fem_status(code, summary, "single-element")
    if not (folder / "run" / "pure_dem.csv").exists():
        raise coupling.FEMRunError(f"the single-element run wrote no pure_dem.csv "
                                   f"({error or 'see its run.log'})")
    dem = pd.read_csv(folder / "run" / "pure_dem.csv")
    comparison = coupling.compare_with_dem(steps, dem)
    seeds = pd.read_csv(root / "size-biaxial" / "responses.csv") \
        if (root / "size-biaxial" / "responses.csv").exists() else None
    scatter = math.nan
    if seeds is not None and (seeds["discs"] == scale.element_discs).any():
        peaks = seeds[seeds["discs"] == scale.element_discs]["peak_stress_ratio"]
        scatter = 100.0 * float(peaks.std(ddof=1) / peaks.mean())
    plots.plot_coupled(steps[steps["step"] >= 0], dem, "single element (4 Gauss points)",
                       folder / "fig6_element.png")
    return {"comparison": comparison, "seed_scatter_pct": scatter,
            "fem": coupling.softening_and_dilation(steps),
            "dem": coupling.softening_and_dilation(dem[dem["rve"] == 0]),
            "error": error, "wall_time_s": float(steps["wall_time"].sum()),
            "newton_iterations_mean": float(steps[steps["step"] > 0]["iterations"].mean()),
            "final_axial_strain": summary.get("final_axial_strain")}


def _part_specimen(scale: ReproductionScale, folder: Path, device: str, progress: bool,
                   root: Path) -> dict[str, Any]:
    rves = coupling.specimen_rves(scale, folder, device)
    code = coupling.run_specimen(scale, rves, folder, device)
    run = folder / "run"
    steps, summary = coupling.read_run(run)
    error = _fem_status(code, summary, "biaxial")
    points = read_points(run)
    tracked = pd.read_csv(run / "tracked.csv")
    dem = coupling.dem_reference(scale, rves, folder, device)
    comparison = coupling.compare_with_dem(steps, dem)
    band = coupling.band_at(points, scale.map_strain, scale.specimen_elements)
    band_last = coupling.band_at(points, float(points["axial_strain"].max()),
                                 scale.specimen_elements)
    last = int(tracked["step"].max())
    chosen = coupling.choose_points(points, last)
    histories = coupling.point_histories(points, tracked, chosen)
    write_csv(histories, folder / "chosen_rves.csv")
    fits = coupling.fractal_fits(histories)
    write_csv(fits, folder / "fits.csv")
    differ = {index: {"inside_vs_outside": coupling.slopes_differ(fits, index, "inside",
                                                                  "outside"),
                      "inside_vs_edge": coupling.slopes_differ(fits, index, "inside", "edge")}
              for index in ("D0", "alpha0")}
    element_steps = root / "element" / "run" / "steps.csv"
    roughness = {"specimen": coupling.post_peak_roughness(steps),
                 "element": coupling.post_peak_roughness(pd.read_csv(element_steps))
                 if element_steps.exists() else math.nan}
    plots.plot_coupled(steps, dem, f"specimen {scale.specimen_elements[0]} × "
                       f"{scale.specimen_elements[1]} elements", folder / "fig7_specimen.png")
    if (run / "maps.png").exists():
        shutil.copyfile(run / "maps.png", folder / "fig8_maps.png")
    plots.plot_histories(histories, folder / "fig9_histories.png")
    plots.plot_fits(histories, fits, folder / "fig10_fits.png")
    return {"comparison": comparison, "band": band, "band_last": band_last, "chosen": chosen,
            "chosen_at_step": last,
            "chosen_at_strain": float(points[points["step"] == last]["axial_strain"].iloc[0]),
            "fits": fits.to_dict("records"), "slopes": differ, "error": error,
            "post_peak_roughness_pct": roughness,
            "final_axial_strain": summary.get("final_axial_strain"),
            "steps_completed": summary.get("steps_completed"),
            "wall_time_s": float(steps["wall_time"].sum()),
            "newton_iterations_mean": float(steps[steps["step"] > 0]["iterations"].mean()),
            "gauss_points": int(points["point"].nunique()),
            "fractal_seconds": float(tracked["seconds"].sum())}


def _part_speedup(scale: ReproductionScale, folder: Path, device: str, progress: bool,
                  root: Path) -> dict[str, Any]:
    files = {discs: rve_size.packings(scale, discs, root / "rve-size", device)
             for discs in scale.speedup_sizes}
    table_path = folder / "speedup.csv"
    if table_path.exists():
        table = pd.read_csv(table_path)
    else:
        table = speedup.speedup_table(scale, files, device, progress)
        write_csv(table, table_path)  # a cache: whole or not at all
    yade_discs = 400 if 400 in scale.sizes else max(scale.speedup_sizes)
    one = _first_rve(scale, root, yade_discs, device,
                     root / "rve-size" / "rves" / f"discs{yade_discs}_seed{scale.seeds[0]}.npz")
    yade = speedup.yade_rate(one, scale.yade_steps)
    plots.plot_speedup(table, folder / "fig11_speedup.png")
    best = table.loc[table["speed_up"].idxmax()]
    at_yade = table[table["discs"] == yade_discs]
    return {"best": best.to_dict(), "largest_batch": table.groupby("discs")["speed_up"].last()
            .to_dict(), "yade_particle_steps_per_s": yade, "yade_discs": yade_discs,
            "ours_batched_best_rate": float(at_yade["particle_steps_per_s"].max())
            if len(at_yade) else None,
            "ours_serial_rate": float(at_yade["serial_particle_steps_per_s"].iloc[0])
            if len(at_yade) else None,
            "table": table.to_dict("records")}


_RUNNERS = {"rve-size": lambda s, f, d, p, r: _part_rve_size(s, f, d, p),
            "size-biaxial": _part_size_biaxial, "element": _part_element,
            "specimen": _part_specimen, "speedup": _part_speedup}


def run_reproduction(scale: str | ReproductionScale, out: str | Path, device: str = "cpu",
                     progress: bool = False, redo: tuple[str, ...] = (),
                     log: Log = lambda _: None,
                     parts: tuple[str, ...] = tuple(PARTS)) -> dict[str, dict[str, Any]]:
    """Run (or finish) the reproduction at ``scale`` into ``out``: every part of ``parts``
    not done yet (and those of ``redo`` again), then ``report.md``. Returns each part's
    result."""
    study = SCALES[scale] if isinstance(scale, str) else scale
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    unknown = (set(redo) | set(parts)) - set(PARTS)
    if unknown:
        raise ValueError(f"unknown part(s) {sorted(unknown)}; the parts are {list(PARTS)}")
    _check_scale(root, study)
    results: dict[str, dict[str, Any]] = {}
    for name, figures in PARTS.items():
        if name not in parts:
            continue
        folder = root / name
        done = folder / "result.json"
        if name in redo:
            for file in (done, *(folder / f for f in _REDO_REMOVES.get(name, ()))):
                file.unlink(missing_ok=True)
        previous = json.loads(done.read_text()) if done.exists() else None
        computed_wall_s = None
        if previous is not None and previous.get("version") != RESULT_VERSION:
            log(f"{name} ({figures}): done by an older version of this code, redone from "
                "its cached runs")
            computed_wall_s = previous.get("computed_wall_s", previous.get("part_wall_s"))
            previous = None
        if previous is not None:
            log(f"{name} ({figures}): done before, skipped")
            results[name] = previous
        else:
            folder.mkdir(parents=True, exist_ok=True)
            log(f"{name} ({figures}): running")
            started = time.perf_counter()
            result = _RUNNERS[name](study, folder, device, progress, root)
            result["part_wall_s"] = time.perf_counter() - started
            result["computed_wall_s"] = computed_wall_s or result["part_wall_s"]
            result["device"] = device
            result["version"] = RESULT_VERSION
            write_json(_json_ready(result), done, indent=1)  # the part's commit point
            log(f"{name}: done in {result['part_wall_s']:.0f} s")
            results[name] = json.loads(done.read_text())  # as a later run reads it
    write_report(study, results, root)
    return results


def _check_scale(root: Path, scale: ReproductionScale) -> None:
    """Refuse to mix two scales in one folder (``scale.json`` records the first)."""
    record = root / "scale.json"
    mine = {"scale": scale.name} if scale.name in SCALES else {"scale": scale.name,
                                                                 "sizes": asdict(scale)}
    mine = json.loads(json.dumps(mine))  # as read back: tuples become lists
    if record.exists():
        saved = json.loads(record.read_text())
        if saved != mine:
            what = ("other sizes" if saved.get("scale") == scale.name
                    else f"scale {saved.get('scale')!r}")
            raise ValueError(f"{root} holds a study at {what}; use another --out for this "
                             "one")
    else:
        record.write_text(json.dumps(mine) + "\n")
