"""Results floor: what a biaxial run produces (:class:`BiaxialResult`, its tables), their
writers (CSV, NumPy records, XDMF) and readers, figures, localisation (shear-band)
measures, peak finding and the summaries the commands report. Reads what the procedures
and the FEM produce; imports nothing above it."""

from granular_material.results.active_bands import (
    FittedBand,
    active_bands,
    fit_bands,
    incremental_points,
)
from granular_material.results.band_measures import (
    band_measures,
    band_onset,
    localisation_history,
)
from granular_material.results.bands import Band, band_width, find_bands
from granular_material.results.biaxial import COST_COLUMNS, BiaxialResult
from granular_material.results.localization import (
    ShearBand,
    mohr_coulomb_inclination,
    shear_band,
)
from granular_material.results.peaks import find_peak
from granular_material.results.plots import (
    plot_biaxial_curves,
    plot_maps,
    plot_stress_strain,
    pyplot,
)
from granular_material.results.summary import (
    BiaxialSummary,
    band_summary,
    run_summary,
    summarize_biaxial,
)
from granular_material.results.writers import (
    BiaxialWriter,
    FieldWriter,
    read_points,
    read_run_tables,
    write_csv,
    write_json,
    write_outputs,
    write_points,
    write_tables,
)

__all__ = [
    "COST_COLUMNS",
    "Band",
    "BiaxialResult",
    "BiaxialSummary",
    "BiaxialWriter",
    "FieldWriter",
    "FittedBand",
    "ShearBand",
    "active_bands",
    "band_measures",
    "band_onset",
    "band_summary",
    "band_width",
    "find_bands",
    "find_peak",
    "fit_bands",
    "incremental_points",
    "localisation_history",
    "mohr_coulomb_inclination",
    "plot_biaxial_curves",
    "plot_maps",
    "plot_stress_strain",
    "pyplot",
    "read_points",
    "read_run_tables",
    "run_summary",
    "shear_band",
    "summarize_biaxial",
    "write_csv",
    "write_json",
    "write_outputs",
    "write_points",
    "write_tables",
]
