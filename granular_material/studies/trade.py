"""The speed/accuracy trade study: each knob a user can turn, measured against a
high-fidelity reference run from the same RVEs, in one run on one machine.

Three tests carry the knobs:

- ``dem``: the drained biaxial test of pure-DEM RVEs (one per seed, batched): discs per RVE,
  strain per DEM step, time-step safety factor, local damping, float32 against float64;
- ``element``: the FEM × DEM single element (one RVE copied to its 4 Gauss points): Newton
  tolerance, stress floor, tangent, predictor and relaxation, reuse of undisturbed RVEs;
- ``specimen``: the biaxial specimen: the mesh;
- the band rows (:mod:`~granular_material.studies.band`): the commands' reduced specimen on
  several sets of RVEs, scored past its peak (when and where its shear band forms, σ1/σ3
  and εv at 5 and 10 %) against the commands' defaults: Newton's test and tolerance, the
  relaxation, the drive, the tangent, the strain per DEM step, the load steps, the mesh,
  the discs;
- the footing rows (:mod:`~granular_material.studies.footing_rows`): Guo & Zhao's reduced
  strip footing under the scene's settings, another packing, the force test, reuse, the
  presets, and the Mohr–Coulomb twin, scored by the bearing pressure at s/B = 0.05 and 0.1,
  the peak and the mechanism.

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
(:func:`recommend`: the peak for the DEM knobs, the band for Newton's) and then run and
measured themselves, the band rows' presets against their band budget.

The study is in five modules: :mod:`~granular_material.studies.plan` (scales, knobs, rows),
:mod:`~granular_material.studies.running` (one run), :mod:`~granular_material.studies.scoring`
(errors, accuracy, the presets' rule), :mod:`~granular_material.studies.measure`
(``trade.csv``) and :mod:`~granular_material.studies.report` (``report.md``); this module runs
them in order (:func:`run_trade_study`) and gives their public names.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pandas as pd

from granular_material.filesafe import write_whole
from granular_material.provenance import code_commit
from granular_material.results import write_csv
from granular_material.studies.band import (
    BAND_SCALES,
    band_rows,
    run_band_rows,
)
from granular_material.studies.band_report import band_figures, band_section
from granular_material.studies.band_scoring import (
    band_table,
    run_measures,
)
from granular_material.studies.footing_report import footing_section, plot_footing_pareto
from granular_material.studies.footing_rows import (
    FOOTING_SCALES,
    footing_rows,
    footing_table,
    half_width,
    run_footing_rows,
)
from granular_material.studies.measure import _drop_rows, _measure, read_trade_table
from granular_material.studies.plan import (
    NOISE,
    REFERENCE,
    SCALES,
    SPECIMEN_NEWTON,
    Knob,
    PlannedRow,
    StudyScale,
    _preset_rows,
    knobs,
    plan_runs,
    run_key,
    tangent_settings,
)
from granular_material.studies.preset_check import check_presets
from granular_material.studies.report import presets_file, report
from granular_material.studies.running import RunResult, _Runner
from granular_material.studies.running import _dem_equivalent as _dem_equivalent
from granular_material.studies.scoring import (
    PRESET_KNOBS,
    PRESETS,
    accuracy,
    band_scale_name,
    recommend,
)

__all__ = ["NOISE", "PRESETS", "PRESET_KNOBS", "REFERENCE", "SCALES", "SPECIMEN_NEWTON", "Knob",
           "PlannedRow", "RunResult", "StudyScale", "accuracy", "knobs", "plan_runs",
           "presets_file", "read_trade_table", "recommend", "report", "run_key",
           "run_trade_study", "tangent_settings"]


def run_trade_study(scale: str | StudyScale, out: str | Path, device: str = "cpu",
                    progress: bool = False,
                    log: Callable[[str], None] = lambda _: None,
                    jobs: int = 1) -> pd.DataFrame:
    """Run (or finish) the study ``scale`` into ``out``; returns ``trade.csv`` as a table.

    Writes ``trade.csv``, ``curves/``, ``rves/``, ``band/`` (the band rows' runs,
    ``band.csv``), ``pareto.png``, ``knob_<name>.png``, ``band_pareto.png``,
    ``band_histories.png``, ``footing/`` (the footing rows' runs, ``footing.csv``),
    ``footing_pareto.png``, ``presets.json`` and ``report.md`` (see the module docstring);
    ``jobs``: band rows run at once, each in its own process.
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
    band_scale = BAND_SCALES[band_scale_name(study)]
    footing_scale = FOOTING_SCALES[band_scale_name(study)]
    rows = band_rows(band_scale)
    run_band_rows(rows, band_scale, out, device, jobs, progress, log)
    footing = footing_rows()
    run_footing_rows(footing, footing_scale, out, log)
    presets = recommend(table[table["knob"] != "preset"], study,
                        band_table(run_measures(out, rows, band_scale), band_scale),
                        footing_table(footing, out, half_width()))
    presets, rows, footing = check_presets(presets, rows, footing, band_scale, footing_scale,
                                           out, device, jobs, progress, log)
    band = band_table(run_measures(out, rows, band_scale), band_scale)
    write_csv(band, out / "band.csv")
    footing_results = footing_table(footing, out, half_width())
    write_csv(footing_results, out / "footing.csv")
    preset_rows = _preset_rows(presets, study)
    _drop_rows(out / "trade.csv", lambda t: (t["knob"] == "preset") & ~t["run"].isin(
        {run_key(r.settings) for r in preset_rows}))
    _measure(preset_rows, runner, out, device, commit, progress, log)
    table = read_trade_table(out / "trade.csv")
    _write_text(out / "presets.json", presets_file(presets))
    plot_pareto(table, accuracy(table), out / "pareto.png")
    for name in dict.fromkeys(k.name for k in knobs(study)):
        plot_knob(table[table["knob"] == name], name, out / f"knob_{name}.png")
    band_figures(out, band, rows, band_scale)
    plot_footing_pareto(footing_results, out / "footing_pareto.png")
    _write_text(out / "report.md", "\n".join([
        report(table, presets, study, device, commit), "",
        *band_section(band, presets, band_scale),
        *footing_section(footing_results, footing_scale)]))
    return table


def _write_text(path: Path, text: str) -> None:
    """``text`` to ``path`` whole or not at all (UTF-8)."""
    write_whole(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
