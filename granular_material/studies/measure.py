"""``trade.csv``: the rows of a plan measured, each run once (a run is done once its curve
is under ``curves/``), each row appended as soon as its run and its reference run are done,
and the table read back."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pandas as pd

from granular_material.procedures import progress_bar
from granular_material.results import write_csv, write_json
from granular_material.studies.plan import PlannedRow, run_key
from granular_material.studies.running import RunResult, _Runner
from granular_material.studies.scoring import _row

__all__ = ["read_trade_table"]


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
                write_json(meta, curve_path(key).with_suffix(".json"), indent=None)
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
