"""The sections of a reproduction's ``report.md``, one a figure (or group of figures) of
Wu et al. (2025): the paper's claim, our measurement with its tables, the rule of agreement
and the figures, each from its part's results."""

from __future__ import annotations

from typing import Any

import pandas as pd

from granular_material.results.compare import markdown_table

from .report_verdicts import _num, _settle_verdict
from .rve_size import SETTLE_TOLERANCES_PCT

__all__ = ["SECTIONS"]


def _rising_dq(r: dict[str, Any]) -> str:
    """Where D_q does not decrease, which sizes and why (the finest box of one pixel)."""
    rows = pd.DataFrame(r["per_size"])
    if (rows["dq_decreasing_count"] == rows["rves"]).all():
        return ""
    by_image = rows.groupby("image_px")[["dq_decreasing_count", "rves"]].sum()
    counts = "; ".join(f"{int(px)} px images: {int(row['dq_decreasing_count'])} of "
                       f"{int(row['rves'])}" for px, row in by_image.iterrows())
    return (f" (by image size: {counts}). An image of 256 px has boxes of one pixel at "
            "k = 8, where the measure is uniform over the pore pixels, so the fitted D_q "
            "rises with q; with more pixels the finest box holds several and D_q falls as "
            "in the paper")


def _resolution_note(r: dict[str, Any]) -> list[str]:
    """Where α0/D0 moves with the image's size in pixels rather than with the RVE."""
    rows = pd.DataFrame(r["per_size"])
    if rows["image_px"].nunique() < 2:
        return []
    by_image = rows.groupby("image_px")["ratio_mean"].agg(["min", "max", "count"])
    parts = [f"{int(px)} px: {_num(row['min'], 4)}–{_num(row['max'], 4)} ({int(row['count'])} "
             "sizes)" for px, row in by_image.iterrows()]
    return ["The image side is a multiple of 256 pixels (the window is one cell at the "
            "pixel nearest 0.3 mm), so it grows in steps with the RVE; α0/D0 by image size: "
            + "; ".join(parts) + ". Its changes between sizes follow those steps more than "
            "the number of discs.", ""]


def _section_rve_size(r: dict[str, Any]) -> list[str]:
    s = r["settle"]
    table = pd.DataFrame(r["per_size"])[["discs", "ratio_mean", "ratio_std",
                                         "ratio_scatter_pct", "D0_mean", "alpha0_mean",
                                         "void_ratio_mean", "r2_q0", "min_r2", "image_px"]]
    return [
        "## Figs. 3–4: pore multifractal spectra and the RVE size", "",
        "Under the paper's box rule (ε = 2⁻ᵏL) first, then under the physical rule, and the "
        "same RVEs at four pixels.", "",
        "**Claim.** The q–D_q spectra are decreasing sigmoids and α–f(α) convex parabolas "
        "(multifractal pore space); α0/D0 fluctuates strongly with size below 20² discs and "
        "is stable from 20² on, so 400 discs is the smallest RVE.", "",
        f"**Ours.** {r['rves']} RVEs, void ratio {_num(r['void_ratio_range'][0])}–"
        f"{_num(r['void_ratio_range'][1])} after consolidation. D_q decreases with q in "
        f"{r['dq_decreasing']} of {r['rves']}{_rising_dq(r)}. By the rule below, α0/D0 "
        "settles from "
        f"**{s['settle_discs']} discs**: the seeds' standard deviation is "
        f"{_num(s['scatter_at_settle'])} ({_num(s['scatter_pct_at_settle'])} %) there, "
        f"{_num(s['scatter_pct_smallest'])} % at the smallest size and "
        f"{_num(s['scatter_pct_largest'])} % at the largest; the means move by "
        f"{_num(s['range_above'])} over the sizes from there on and by "
        f"{_num(s['range_below'])} below.", "",
        "Rule: the smallest size n such that at every size m ≥ n the seeds' mean α0/D0 lies "
        "within two standard errors (√(SE_m² + SE_largest²)) of the largest size's mean. "
        "Beside it, with a fixed tolerance instead of the seeds' scatter: every mean within "
        + ", ".join(f"{t:g} % from {s[f'within_{t:g}pct_from']} discs"
                    for t in SETTLE_TOLERANCES_PCT) + ".", "",
        *_resolution_note(r),
        f"Fit quality: D0 and α0 come from the fits at q = 0, whose R² is at least "
        f"{_num(min(row['r2_q0'] for row in r['per_size']), 3)} in every RVE; the poorest "
        f"fits of the spectra (R² down to {_num(min(row['min_r2'] for row in r['per_size']))}"
        ", column `min_r2`) are at negative q and, for f, at large q (as checked at 100, "
        "400 and 900 discs).", "",
        markdown_table(table), "",
        *_both_rules(r),
        "![Fig. 3](rve-size/fig3_spectra.png)", "", "![Fig. 4](rve-size/fig4_ratio.png)", "",
        *_resolution_section(r)]


def _both_rules(r: dict[str, Any]) -> list[str]:
    """The physical box rule's settling, table and the verdict it gives on the claim."""
    if "settle_physical" not in r:
        return ["(This part was computed before the physical box rule: rerun it with "
                "`--redo rve-size` for both rules and the resolution study.)", ""]
    s, c = r["settle_physical"], r["settle"]
    table = pd.DataFrame(r["per_size_physical"])[["discs", "ratio_mean", "ratio_std",
                                                  "ratio_scatter_pct", "ratio_fit_se",
                                                  "D0_mean", "alpha0_mean", "r2_q0",
                                                  "image_px", "box_min_mm", "box_max_mm"]]
    verdict = _settle_verdict(s)
    words = ("holds" if verdict is True else "does not hold" if verdict is False
             else "holds in part")
    return [
        "**Under the physical box rule** (boxes 2.4–38.4 mm at every size, so RVEs of "
        "different sizes are measured over the same physical scales and the finest box is "
        "8 pixels, not one): α0/D0 settles, by the same rule, from "
        f"**{s['settle_discs']} discs** (cell rule: {c['settle_discs']}); every mean lies "
        + ", ".join(f"within {t:g} % from {s[f'within_{t:g}pct_from']}"
                    for t in SETTLE_TOLERANCES_PCT)
        + f" discs; the seed scatter (the band of Fig. 4) is "
        f"{_num(s['scatter_pct_smallest'])} % at the smallest size and "
        f"{_num(s['scatter_pct_largest'])} % at the largest, and the means move by "
        f"{_num(s['range_above'])} from there on"
        + (f" and by {_num(s['range_below'])} below. " if s["settle_discs"] > min(
            row["discs"] for row in r["per_size_physical"]) else " (every size). ")
        + f"Verdict on \"α0/D0 settles above 400 discs\": **{words}** once the boxes are "
        f"held fixed in metres: it settles from {s['settle_discs']} discs"
        + ("" if s["settle_discs"] >= 400 else ", so the sizes below 400 do not fluctuate "
           "beyond the seeds' scatter, which narrows with size instead") + ". "
        "`ratio_fit_se` is the mean standard error of α0/D0 from the fits (the log-moments "
        "bend, so it is larger than the seed scatter; it says how much the index depends on "
        "the box range, not how well it is known at a fixed range).", "",
        markdown_table(table), ""]


def _resolution_section(r: dict[str, Any]) -> list[str]:
    """The resolution study: the same RVEs at four pixels under both box rules."""
    if "resolution" not in r:
        return []
    rows = pd.DataFrame(r["resolution"])
    table = rows[["box_rule", "pixel_request", "image_px", "D0_mean", "D0_std", "alpha0_mean",
                  "ratio_mean", "ratio_std", "D0_change_pct", "ratio_change_pct", "r2_q0",
                  "box_min_m", "box_max_m"]].copy()
    table["pixel_request"] *= 1e3
    table[["box_min_m", "box_max_m"]] *= 1e3
    table = table.rename(columns={"pixel_request": "pixel [mm]", "box_min_m": "box min [mm]",
                                  "box_max_m": "box max [mm]"})

    def change(rule: str, pixel: float, column: str) -> str:
        at = rows[(rows["box_rule"] == rule) & (rows["pixel_request"].sub(pixel).abs()
                                                < 1e-9)]
        return _num(float(at[column].iloc[0]), 2) if len(at) else "–"

    return [
        f"### Resolution: the same {r['resolution_discs']}-disc RVEs at four pixels", "",
        "The seeds' RVEs of one size at pixels 0.6, 0.3, 0.15 and 0.075 mm under both box "
        "rules (means and standard deviations over the seeds; changes of the means from the "
        "next coarser pixel). From 0.3 to 0.15 mm, D0 changes by "
        f"{change('cell', 0.15e-3, 'D0_change_pct')} % and α0/D0 by "
        f"{change('cell', 0.15e-3, 'ratio_change_pct')} % under the cell rule, by "
        f"{change('physical', 0.15e-3, 'D0_change_pct')} % and "
        f"{change('physical', 0.15e-3, 'ratio_change_pct')} % under the physical rule. "
        "Under the cell rule the finest box, L/256, is 1 to 10 pixels and the indices climb "
        "as it gains pixels; under the physical rule the boxes are the same lengths at every "
        "pixel, and a box under 1 % pore (a sliver one pixel wide at a contact, which a finer "
        "pixel resolves further) counts as empty. At 0.6 mm the smallest box is 4 pixels, "
        "too few: compare from 0.3 mm down.", "",
        markdown_table(table), "", "![resolution](rve-size/fig4_resolution.png)", ""]


def _section_size_biaxial(r: dict[str, Any]) -> list[str]:
    rows = [{"discs": int(d), "peak Δ %": a["peak"]["difference_pct"],
             "peak 2 SE %": a["peak"]["two_se_pct"], "peak agrees": a["peak"]["agrees"],
             "final Δ %": a["final"]["difference_pct"], "final 2 SE %": a["final"]["two_se_pct"],
             "final agrees": a["final"]["agrees"]} for d, a in r["agreement"].items()]
    return [
        "## Fig. 5: stress–strain of RVEs of different sizes", "",
        "**Claim.** RVEs of 20² discs give essentially the response of 26² and 30²; those "
        "of 10² and 16² do not.", "",
        "**Ours.** Peak and final σ1/σ3 per size (mean and standard deviation over the "
        "seeds), then each size against all larger sizes pooled: Δ = difference of the "
        "means, agreement when |Δ| is within two standard errors of that difference.", "",
        markdown_table(pd.DataFrame(r["per_size"])), "", markdown_table(pd.DataFrame(rows)),
        "", "![Fig. 5](size-biaxial/fig5_curves.png)", ""]


def _section_element(r: dict[str, Any]) -> list[str]:
    c = r["comparison"]
    return [
        "## Fig. 6: single element against pure DEM", "",
        "**Claim.** The FEM × DEM single element (4 Gauss points, 400-disc RVEs) gives "
        "essentially the pure-DEM response, with its nonlinearity, softening and dilatancy.",
        "",
        f"**Ours.** Peak σ1/σ3 {_num(c['peak_error_pct'])} % from the pure-DEM test of the "
        f"same RVE (RMS over the curve {_num(c['stress_ratio_rms_pct'])} % of the peak, εv "
        f"RMS {_num(c['volumetric_strain_rms_pct'])} % of its largest value); the seed "
        f"scatter of the peak at this size is {_num(r['seed_scatter_pct'])} %. Softening "
        f"after the peak {_num(r['fem']['softening_pct'])} % (pure DEM "
        f"{_num(r['dem']['softening_pct'])} %), dilation after the densest state "
        f"{_num(100 * r['fem']['dilation_after_minimum'])} % (pure DEM "
        f"{_num(100 * r['dem']['dilation_after_minimum'])} %). Newton: "
        f"{_num(r['newton_iterations_mean'])} iterations a step; "
        f"{_num(r['wall_time_s'])} s." + (f" The run stopped: {r['error']}." if r["error"]
                                         else ""), "",
        "Agreement: |peak difference| within the seed scatter (another packing changes the "
        "peak more than the coupling does).", "",
        "![Fig. 6](element/fig6_element.png)", ""]


def _section_specimen(r: dict[str, Any]) -> list[str]:
    c, band = r["comparison"], r["band"]
    fits = pd.DataFrame(r["fits"])
    slopes = [{"index": index, "pair": pair.replace("_", " "), **values}
              for index, pairs in r["slopes"].items() for pair, values in pairs.items()]
    stopped = (f" The run stopped at {_num(100 * r['final_axial_strain'])} % axial strain: "
               f"{r['error']}." if r["error"] else "")
    return [
        "## Fig. 7: the specimen against pure DEM", "",
        "**Claim.** The specimen's global stress–strain response agrees with pure DEM; it is "
        "smoother past the peak than the single element's.", "",
        f"**Ours.** {r['gauss_points']} Gauss points, {r['steps_completed']} load steps in "
        f"{_num(r['wall_time_s'])} s ({_num(r['newton_iterations_mean'])} Newton iterations "
        f"a step; {_num(r['fractal_seconds'])} s of pore analyses).{stopped} Peak σ1/σ3 "
        f"{_num(c['peak_error_pct'])} % from the mean of {c['dem_rves']} pure-DEM tests of "
        f"the specimen's own first packings, whose peaks scatter by "
        f"{_num(c['dem_peak_scatter_pct'])} %; RMS over the curve "
        f"{_num(c['stress_ratio_rms_pct'])} %. Agreement: |peak difference| within that "
        "scatter. Past the peak, the RMS of σ1/σ3's second differences between load steps "
        f"is {_num(r['post_peak_roughness_pct']['specimen'])} % of the peak for the specimen "
        f"and {_num(r['post_peak_roughness_pct']['element'])} % for the single element.",
        "", "![Fig. 7](specimen/fig7_specimen.png)", "",
        "## Fig. 8: the shear band", "",
        "**Claim.** At 2 % axial strain the shear strain shows a through-going band, without "
        "any imperfection.", "",
        f"**Ours.** At {_num(100 * band['axial_strain'])} %: the 15 % of Gauss points of "
        f"largest shear strain form a band inclined {_num(band['inclination_deg'])}° to the "
        f"x axis, elongation {_num(band['elongation'])}, mean γ inside / outside "
        f"{_num(band['localization'])}; through-going: **{band['through_going']}** (its "
        f"elements touch: {', '.join(band['sides']) or 'no side'}). At the last step "
        f"({_num(100 * r['band_last']['axial_strain'])} %): inclination "
        f"{_num(r['band_last']['inclination_deg'])}°, elongation "
        f"{_num(r['band_last']['elongation'])}, localisation "
        f"{_num(r['band_last']['localization'])}, through-going: "
        f"{r['band_last']['through_going']} ({', '.join(r['band_last']['sides'])}). "
        "Rule: the band's "
        "elements, joined through edges or corners, connect the two sides or the two "
        "platens, or a platen to a side while spanning half the width and height. No "
        "imperfection: every point has its own random packing.", "",
        "![Fig. 8](specimen/fig8_maps.png)", "",
        "## Figs. 9–10: three RVEs, their pore indices against volumetric strain", "",
        "**Claim.** Outside the band an RVE only contracts and D0, α0 fall; in and at the "
        "edge of the band RVEs contract then dilate, and D0, α0 fall then rise with them; D0 "
        "and α0 are linear in εv, with slopes alike for the two band RVEs and different "
        "outside.", "",
        f"**Ours.** Chosen at load step {r['chosen_at_step']} "
        f"({_num(100 * r['chosen_at_strain'])} %) from the run's own shear strain γ: inside "
        f"= largest γ (point {r['chosen']['inside']}), outside = smallest γ (point "
        f"{r['chosen']['outside']}), edge = the point ranked just below the band's 15 % "
        f"(point {r['chosen']['edge']}). Slopes are per unit of volumetric strain, "
        "compression positive: a negative slope means the index falls under contraction "
        "and rises under dilation. Slopes differ when they are more than two standard errors "
        "of their difference apart.", "",
        markdown_table(fits), "", markdown_table(pd.DataFrame(slopes)), "",
        "![Fig. 9](specimen/fig9_histories.png)", "", "![Fig. 10](specimen/fig10_fits.png)",
        ""]


def _section_speedup(r: dict[str, Any]) -> list[str]:
    table = pd.DataFrame(r["table"])
    yade = r["yade_particle_steps_per_s"]
    yade_line = ("YADE was not measured (not installed, or not at this scale)." if not yade
                 else f"One YADE core steps the {r['yade_discs']}-disc packing at "
                      f"{_num(yade)} particle-steps/s; ours "
                      f"{_num(r['ours_serial_rate'])} one RVE at a time on one thread "
                      f"({_num(r['ours_serial_rate'] / yade)}×) and "
                      f"{_num(r['ours_batched_best_rate'])} batched "
                      f"({_num(r['ours_batched_best_rate'] / yade)}×).")
    return [
        "## Fig. 11: speed-up of the batched DEM", "",
        "**Claim.** On an NVIDIA RTX 3080 (against an AMD 5900X serial run), the GPU DEM "
        "runs about 150× faster than serial; the speed-up grows about linearly with the "
        "number of RVEs for 10² and 20² discs and levels off for 30².", "",
        f"**Ours** on {table['device'].iloc[0]}: at best {_num(r['best']['speed_up'])}× "
        f"({int(r['best']['rves'])} RVEs of {int(r['best']['discs'])} discs). Serial = the "
        "same engine stepping one RVE at a time on one thread. " + yade_line, "",
        markdown_table(table), "", "![Fig. 11](speedup/fig11_speedup.png)", ""]


#: each part's section of the report, in the report's order
SECTIONS = {"rve-size": _section_rve_size, "size-biaxial": _section_size_biaxial,
            "element": _section_element, "specimen": _section_specimen,
            "speedup": _section_speedup}
