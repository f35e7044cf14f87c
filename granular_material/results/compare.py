"""How far one stress–strain curve lies from a reference curve: the error measures of the
benchmarks and the trade study, and their Markdown tables.

Curves are tables with ``axial_strain`` (compression positive), ``stress_ratio`` σ1/σ3,
``volumetric_strain`` (tension positive) and, where present, ``void_ratio``: the rows of
:func:`~granular_material.procedures.biaxial_test` for one RVE, or the ``steps`` table of a
FEM run. The two curves need not share their strains: the reference is interpolated onto
the compared curve's strains within the range both cover.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from granular_material.results.peaks import find_peak

__all__ = ["ERROR_COLUMNS", "curve_errors", "markdown_table", "mean_curve"]

#: the columns of :func:`curve_errors`, in order
ERROR_COLUMNS = ("peak_error_pct", "peak_strain_error_pct", "stress_ratio_rms_pct",
                 "volumetric_strain_rms_pct", "void_ratio_error")


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(values ** 2))) if len(values) else math.nan


def curve_errors(curve: pd.DataFrame, reference: pd.DataFrame) -> dict[str, float]:
    """Errors of ``curve`` against ``reference``.

    Returns:
        ``peak_error_pct``: peak σ1/σ3 relative to the reference's peak [%] (signed);
        ``peak_strain_error_pct``: axial strain at the peak minus the reference's [% strain];
        ``stress_ratio_rms_pct``: RMS difference of σ1/σ3 over the common strains, relative
        to the reference's peak [%]; ``volumetric_strain_rms_pct``: RMS difference of εv,
        relative to the reference's largest ``|εv|`` [%]; ``void_ratio_error``: final void
        ratio minus the reference's [-] (NaN without ``void_ratio``).
    """
    e, q = curve["axial_strain"].to_numpy(), curve["stress_ratio"].to_numpy()
    e_ref, q_ref = reference["axial_strain"].to_numpy(), reference["stress_ratio"].to_numpy()
    peak, ratio = find_peak(e, q)
    peak_ref, ratio_ref = find_peak(e_ref, q_ref)
    common = (e > 0) & (e <= e_ref.max()) & (e >= e_ref.min())
    order = np.argsort(e_ref)
    at = e[common]
    dq = q[common] - np.interp(at, e_ref[order], q_ref[order])
    ev = curve["volumetric_strain"].to_numpy()[common]
    ev_ref = np.interp(at, e_ref[order], reference["volumetric_strain"].to_numpy()[order])
    ev_scale = float(np.abs(reference["volumetric_strain"].to_numpy()).max())
    void = math.nan
    if "void_ratio" in curve and "void_ratio" in reference:
        void = float(curve["void_ratio"].iloc[-1] - reference["void_ratio"].iloc[-1])
    return {
        "peak_error_pct": 100.0 * (ratio / ratio_ref - 1.0),
        "peak_strain_error_pct": 100.0 * float(e[peak] - e_ref[peak_ref]),
        "stress_ratio_rms_pct": 100.0 * _rms(dq) / abs(ratio_ref),
        "volumetric_strain_rms_pct": (100.0 * _rms(ev - ev_ref) / ev_scale if ev_scale > 0
                                      else math.nan),
        "void_ratio_error": void,
    }


def mean_curve(curves: list[pd.DataFrame]) -> pd.DataFrame:
    """The mean of curves (e.g. one per seed) on the first one's axial strains: σ1/σ3, εv and
    void ratio averaged after interpolating each onto those strains."""
    base = curves[0]["axial_strain"].to_numpy()
    columns = [c for c in ("stress_ratio", "volumetric_strain", "void_ratio")
               if all(c in k for k in curves)]
    mean = {"axial_strain": base}
    for column in columns:
        stack = []
        for k in curves:
            order = np.argsort(k["axial_strain"].to_numpy())
            stack.append(np.interp(base, k["axial_strain"].to_numpy()[order],
                                   k[column].to_numpy()[order]))
        mean[column] = np.mean(stack, axis=0)
    return pd.DataFrame(mean)


def markdown_table(table: pd.DataFrame, digits: int = 4) -> str:
    """``table`` as a Markdown table, floats to ``digits`` significant digits."""
    def cell(value: object) -> str:
        if isinstance(value, float | np.floating):
            return "–" if math.isnan(value) else f"{value:.{digits}g}"
        return str(value)

    lines = ["| " + " | ".join(map(str, table.columns)) + " |",
             "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |"
              for row in table.itertuples(index=False)]
    return "\n".join(lines) + "\n"
