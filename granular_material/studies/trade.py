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
from granular_material.studies.report import presets_file, report
from granular_material.studies.running import RunResult, _Runner
from granular_material.studies.running import _dem_equivalent as _dem_equivalent
from granular_material.studies.scoring import PRESET_KNOBS, PRESETS, accuracy, recommend

__all__ = ["NOISE", "PRESETS", "PRESET_KNOBS", "REFERENCE", "SCALES", "SPECIMEN_NEWTON", "Knob",
           "PlannedRow", "RunResult", "StudyScale", "accuracy", "knobs", "plan_runs",
           "presets_file", "read_trade_table", "recommend", "report", "run_key",
           "run_trade_study", "tangent_settings"]


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
    _write_text(out / "presets.json", presets_file(presets))
    plot_pareto(table, accuracy(table), out / "pareto.png")
    for name in dict.fromkeys(k.name for k in knobs(study)):
        plot_knob(table[table["knob"] == name], name, out / f"knob_{name}.png")
    _write_text(out / "report.md", report(table, presets, study, device, commit))
    return table


def _write_text(path: Path, text: str) -> None:
    """``text`` to ``path`` whole or not at all (UTF-8)."""
    write_whole(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
