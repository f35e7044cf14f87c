"""The headline table of a reproduction's ``report.md``: one row per figure of Wu et al.
(2025), the paper's claim, our measurement in numbers and words, and the rule that says
whether they agree."""

from __future__ import annotations

import math
from typing import Any

import pandas as pd

from .scales import ReproductionScale

__all__ = ["Results", "claim_size", "headline"]

Results = dict[str, dict[str, Any]]


def _num(value: Any, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value:.{digits}g}" if isinstance(value, float) else str(value)


def _verdict(ok: bool | str | None) -> str:
    """A headline verdict: True, False, None (the paper's setting not measured) or a word."""
    return ok if isinstance(ok, str) else {True: "agrees", False: "differs",
                                           None: "not comparable"}[ok]


def _fit(results: Results, role: str, index: str) -> dict[str, Any]:
    for row in results["specimen"]["fits"]:
        if row["role"] == role and row["index"] == index:
            return row
    raise KeyError((role, index))


def claim_size(scale: ReproductionScale) -> int:
    """The RVE size of Fig. 5's claim: 400 discs, or at a scale without it the middle size
    of the biaxial tests."""
    sizes = sorted(scale.biaxial_sizes)
    return 400 if 400 in sizes[:-1] else sizes[(len(sizes) - 1) // 2]


def _size_verdict(agreement: dict[str, Any], size: int) -> bool | str:
    """Fig. 5: agrees when ``size`` responds as the larger sizes and some smaller size does
    not; partly when the smaller sizes are not told apart either (their scatter too wide)."""
    if not agreement[str(size)]["peak"]["agrees"]:
        return False
    smaller = [a["peak"]["agrees"] for d, a in agreement.items() if int(d) < size]
    if smaller and all(smaller):
        return "partly (smaller sizes not told apart)"
    return True


def headline(scale: ReproductionScale, results: Results) -> pd.DataFrame:
    """One row per claim: figure, the paper's claim, ours, agrees or not (rows only for the
    parts done)."""
    rows = []
    if "rve-size" in results:
        r = results["rve-size"]
        settle = r["settle"]
        physical = r.get("settle_physical")
        rows.append({
            "figure": "3", "claim": "pore space multifractal: q–D_q decreasing, α–f(α) "
            "convex", "ours": f"D_q decreasing in {r['dq_decreasing']} of {r['rves']} RVEs"
            + (f" (cell rule), {r['dq_decreasing_physical']} of {r['rves']} (physical rule)"
               if "dq_decreasing_physical" in r else ""),
            "verdict": _verdict(_dq_verdict(r))})
        rows.append({
            "figure": "4", "claim": "α0/D0 scatters below 400 discs, settles from 400 on",
            "ours": (f"physical rule: {_settle_words(physical)}; cell rule: "
                     if physical is not None else "") + _settle_words(settle),
            "verdict": _verdict(_settle_verdict(physical or settle))})
    if "size-biaxial" in results:
        agreement = results["size-biaxial"]["agreement"]
        size = claim_size(scale)
        at = agreement.get(str(size), {}).get("peak")
        if at is not None:
            rows.append({
                "figure": "5", "claim": "400 discs respond as 676 and 900",
                "ours": f"peak σ1/σ3 at {size} discs {_num(at['difference_pct'])} % from the "
                        f"larger sizes (2 SE: {_num(at['two_se_pct'])} %)"
                        + "".join(f"; {d} discs: {_num(a['peak']['difference_pct'])} % (2 SE "
                                  f"{_num(a['peak']['two_se_pct'])} %)"
                                  for d, a in agreement.items() if int(d) < size),
                "verdict": _verdict(_size_verdict(agreement, size))})
    if "element" in results:
        r = results["element"]
        err = r["comparison"]["peak_error_pct"]
        scatter = r["seed_scatter_pct"]
        ok = (None if scatter is None else abs(err) <= scatter) if r["error"] is None else False
        rows.append({
            "figure": "6", "claim": "single element = pure DEM; softening and dilatancy",
            "ours": f"peak {_num(err)} % from pure DEM (seed scatter {_num(scatter)} %); "
                    f"softening {_num(r['fem']['softening_pct'])} %",
            "verdict": _verdict(ok and r["fem"]["softening_pct"] > 0
                                and r["fem"]["dilation_after_minimum"] > 0
                                if ok is not None else None)})
    if "specimen" in results:
        r = results["specimen"]
        c = r["comparison"]
        rows.append({
            "figure": "7", "claim": "specimen's global curve = pure DEM",
            "ours": f"peak {_num(c['peak_error_pct'])} % from the pure-DEM mean (their "
                    f"scatter {_num(c['dem_peak_scatter_pct'])} %)",
            "verdict": _verdict(c["dem_peak_scatter_pct"] is not None
                                and abs(c["peak_error_pct"]) <= c["dem_peak_scatter_pct"])})
        band = r["band"]
        rows.append({
            "figure": "8", "claim": "a through-going shear band at 2 %, no imperfection",
            "ours": f"{'through-going' if band['through_going'] else 'not through-going'} "
                    f"at {_num(100 * band['axial_strain'])} % (inclination "
                    f"{_num(band['inclination_deg'])}°, localisation "
                    f"{_num(band['localization'])}); "
                    f"{'through-going' if r['band_last']['through_going'] else 'not yet'} at "
                    f"{_num(100 * r['band_last']['axial_strain'])} % (localisation "
                    f"{_num(r['band_last']['localization'])})",
            "verdict": _verdict(band["through_going"])})
        signs = [(_fit(results, role, index)["slope"] or 0.0) < 0 for role in r["chosen"]
                 for index in ("D0", "alpha0")]
        rows.append({
            "figure": "9", "claim": "D0, α0 fall under contraction, rise under dilation",
            "ours": f"slope against contraction negative in {sum(signs)} of {len(signs)} fits",
            "verdict": _verdict(all(signs))})
        r2 = [value for role in r["chosen"] for index in ("D0", "alpha0")
              if (value := _fit(results, role, index)["r2"]) is not None]
        if not r2:  # a run too short for any line
            r2 = [math.nan]
        differ = r["slopes"]["D0"]
        out_word = "differ" if differ["inside_vs_outside"]["differ"] else "do not differ"
        edge_word = "differ" if differ["inside_vs_edge"]["differ"] else "agree"
        rows.append({
            "figure": "10", "claim": "D0, α0 linear in εv; band slopes differ from outside",
            "ours": f"R² {_num(min(r2), 2)}–{_num(max(r2), 2)}; D0 slopes inside vs outside "
                    f"{out_word}, inside vs edge {edge_word}",
            "verdict": _verdict(min(r2) >= 0.9 and differ["inside_vs_outside"]["differ"]
                                and not differ["inside_vs_edge"]["differ"])})
    if "speedup" in results:
        r = results["speedup"]
        best = r["best"]
        gpu = str(best["device"]).startswith("cuda")
        yade = r["yade_particle_steps_per_s"]
        rows.append({
            "figure": "11", "claim": "about 150× over serial (RTX 3080)",
            "ours": f"{_num(best['speed_up'])}× on {best['device']} ({int(best['rves'])} RVEs "
                    f"of {int(best['discs'])} discs)"
                    + (f"; {_num(r['ours_batched_best_rate'] / yade)}× one YADE core"
                       if yade and r["ours_batched_best_rate"] else ""),
            "verdict": _verdict(best["speed_up"] >= 100 if gpu else None)})
    return pd.DataFrame(rows)


def _settle_verdict(settle: dict[str, Any]) -> bool | str:
    """Fig. 4: agrees when α0/D0 settles at 400 discs; partly when it has settled already
    below 400 (no fluctuation there beyond the seed scatter); differs when only above."""
    if settle["settle_discs"] > 400:
        return False
    if settle["settle_discs"] < 400:
        return f"partly (settled from {settle['settle_discs']} discs)"
    return True


def _settle_words(settle: dict[str, Any]) -> str:
    """One settling result in words: the 2 SE size, the 1 % size, the seed scatter."""
    return (f"within 2 SE of the largest from {settle['settle_discs']} discs, within 1 % "
            f"from {settle['within_1pct_from']}; seed scatter "
            f"{_num(settle['scatter_pct_smallest'])} % at the smallest size, "
            f"{_num(settle['scatter_pct_largest'])} % at the largest")


def _dq_verdict(r: dict[str, Any]) -> bool | str:
    """Fig. 3: agrees when D_q decreases in every RVE; partly when it does from 400 discs
    on (the RVE size the paper settles on). Under the physical box rule where measured."""
    suffix = "_physical" if "dq_decreasing_physical" in r else ""
    if r[f"dq_decreasing{suffix}"] == r["rves"]:
        return True
    large = [row for row in r[f"per_size{suffix}"] if row["discs"] >= 400]
    if large and all(row["dq_decreasing_count"] == row["rves"] for row in large):
        return "partly (from 400 discs)"
    return False

