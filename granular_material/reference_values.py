"""Published values every layer starts from (docs/design.md#wu-2025): the confining pressure,
the discs per RVE and their radii of Wu, Fu & Zhou (2025), also Guo & Zhao's (2014); and the
library's cap on the DEM steps of one run. Here, below the layers, so that the options and
checks that show them do not load the DEM (warp) for a run of a continuum material."""

from __future__ import annotations

__all__ = ["DEFAULT_DISCS", "DEFAULT_MAX_DEM_STEPS", "DEFAULT_PRESSURE", "DEFAULT_RADIUS_RANGE",
           "DEFAULT_STRAIN_PER_STEP", "STEP_LIMIT", "TWIN_ELASTIC_WINDOW"]

#: isotropic consolidation pressure p0 of a packing [Pa] (Wu et al. 2025: 100 kPa), and the
#: confining pressure the RVEs are then tested and run at
DEFAULT_PRESSURE = 100.0e3
#: discs per prepared RVE (Wu et al. 2025, Guo & Zhao 2014: 400)
DEFAULT_DISCS = 400
#: (r_min, r_max) [m] of the uniform disc radii: Wu et al. (2025) Table 1; Guo & Zhao rMean
#: 5 mm ± 40 %
DEFAULT_RADIUS_RANGE = (3.0e-3, 7.0e-3)

#: default cap on the DEM steps of one run of the DEM (a path, a test): 10⁶ steps is about 100
#: times the default biaxial test (1.05 × 10⁴ steps to 10 % at 1e-5 a step) or a path of
#: ``|∇u|`` = 10 at 1e-5 a step; one 64-disc RVE runs about 4 × 10³ steps/s on one CPU core (a
#: 400-disc one about six times fewer), so the cap is minutes to half an hour of work: far
#: past any run a typo would start on purpose, well short of the 10⁷ – 10³⁰⁰ steps a
#: mistyped strain asks for.
DEFAULT_MAX_DEM_STEPS = 10**6

#: largest strain of one DEM step [-] (Guo & Zhao 2014), the quasi-static criterion of every
#: strain path and element test: an RVE driven along ∇u, the axial strain of a biaxial test
DEFAULT_STRAIN_PER_STEP = 1.0e-5

#: the most DEM steps one path or test may take: beyond it a float64 count is no longer exact
STEP_LIMIT = 10**15

#: the axial strain [-] an adaptive run's Mohr–Coulomb twin reads its E and ν over
#: (``calibrate``'s default is 1e-3): the twin answers where the soil stays nearly elastic,
#: at strains of 1e-4 to a few 1e-4, where the RVE is stiffer than its secant over 1e-3.
#: Measured on Guo & Zhao's reduced footing (E = 26.7 MPa, ν = 0.14 over 2e-4 against
#: 20.4 MPa, 0.24 over 1e-3; its first six steps adaptive, f = 0.7): the bearing force within
#: −1.9 to +2.2 % of the all-DEM run's against −8.0 to +0.2 % (0.82 and 0.71 of its
#: particle-steps)
TWIN_ELASTIC_WINDOW = 2.0e-4
