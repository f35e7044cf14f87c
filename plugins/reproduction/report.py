"""``report.md`` of a reproduction: for each figure of Wu et al. (2025), the paper's claim,
our measurement, the settings, and whether they agree; a headline table first.

The headline table and its verdicts are :mod:`.report_verdicts`', the sections
:mod:`.report_sections`' (``claim_size`` and ``headline`` importable from here as well)."""

from __future__ import annotations

from pathlib import Path

from granular_material.results.compare import markdown_table

from .report_sections import SECTIONS
from .report_verdicts import Results, claim_size, headline
from .scales import SCALES, ReproductionScale

__all__ = ["claim_size", "headline", "write_report"]


def _settings(scale: ReproductionScale, parts: set[str]) -> list[str]:
    """The settings of the parts run, one bullet each."""
    nx, ny = scale.specimen_elements
    points = 4 * nx * ny
    lines = [
        ("rve-size",
         f"- RVEs: {', '.join(map(str, scale.sizes))} discs × seeds "
         f"{', '.join(map(str, scale.seeds))}; random gas compacted to e0 = "
         f"{scale.void_ratio:g}, then consolidated at p0 = {scale.pressure / 1e3:g} kPa "
         "(Table 1 material: radii 3–7 mm, kn = 3e6 N/m, kt/kn = 0.8, friction 0.5 rad, "
         "damping 0.1)."),
        ("rve-size",
         "- Pore spectra: q = −10…10 step 0.5, pixel 0.3 mm, under two box rules: cell "
         "(ε = 2⁻ᵏL, k = 1…8, window of m·256 pixels, the paper's) and physical (ε = 2.4 to "
         "38.4 mm, capped at half the window, √2 apart, at the pixel nearest 0.3 mm, a box "
         "under 1 % pore counted empty); the resolution study at "
         f"{scale.resolution_discs} discs, pixels 0.6, 0.3, 0.15 and 0.075 mm."),
        ("size-biaxial",
         f"- Pure-DEM biaxial tests: to {100 * scale.dem_axial_strain:g} % axial strain at "
         f"{scale.dem_strain_per_step:g} a DEM step, σ3 = p0 held by a servo."),
        ("element",
         f"- Single element: 4 Gauss points sharing the seed-{scale.seeds[0]} RVE of "
         f"{scale.element_discs} discs, {scale.element_steps} load steps to "
         f"{100 * scale.fem_axial_strain:g} %, Newton at the command's defaults."),
        ("specimen",
         f"- Specimen: 50 × 100 mm, {nx} × {ny} Q4 elements, {points} Gauss points, one "
         f"packing of {scale.specimen_discs} discs each (seeds 1…{points}), smooth "
         f"platens, {scale.specimen_steps} load steps to {100 * scale.fem_axial_strain:g} %; "
         f"every RVE's pore space analysed every {scale.track_every} steps."),
        ("speedup",
         f"- Speed-up: {', '.join(map(str, scale.speedup_sizes))} discs, "
         f"{', '.join(map(str, scale.speedup_batches))} RVEs, {scale.speedup_steps} DEM steps "
         f"timed (scaled to 10⁴), median of {scale.repeats}."),
    ]
    return [line for part, line in lines if part in parts]


def write_report(scale: ReproductionScale, results: Results, root: Path) -> Path:
    """``root/report.md`` from the parts' results."""
    devices = sorted({str(r.get("device")) for r in results.values()})
    wall = sum(float(r.get("computed_wall_s") or r.get("part_wall_s") or 0)
               for r in results.values())
    title = (f"# Wu, Fu & Zhou (2025) reproduced ({scale.name} scale)" if scale.name in SCALES
             else "# RVE size study (Wu, Fu & Zhou 2025, Figs. 3–5)")
    lines = [
        title, "",
        "Wu, Fu & Zhou (2025), simulation of the multiscale mechanical behaviour of granular "
        "materials and pore fractal characterisation (in Chinese): each figure's claim from "
        "the paper's text (its figures are not in our copy), our "
        f"measurement beside it. Device {', '.join(devices)}; the parts took {wall / 60:.1f} "
        "min when they were computed (each part's `computed_wall_s` in its `result.json`).",
        "",
        markdown_table(headline(scale, results)), "",
        "Verdicts follow the rule stated in each section; \"not comparable\" where the "
        "paper's setting (a GPU) is not the one measured.", "",
        "## Settings", "", *_settings(scale, set(results)), ""]
    for name, section in SECTIONS.items():
        if name in results:
            lines += section(results[name])
    path = root / "report.md"
    path.write_text("\n".join(lines))
    return path
