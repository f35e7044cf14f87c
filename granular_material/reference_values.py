"""Published values every layer starts from (docs/design.md#wu-2025): the confining pressure
and the discs per RVE of Wu, Fu & Zhou (2025), also Guo & Zhao's (2014)."""

from __future__ import annotations

__all__ = ["DEFAULT_DISCS", "DEFAULT_PRESSURE"]

#: isotropic consolidation pressure p0 of a packing [Pa] (Wu et al. 2025: 100 kPa), and the
#: confining pressure the RVEs are then tested and run at
DEFAULT_PRESSURE = 100.0e3
#: discs per prepared RVE (Wu et al. 2025, Guo & Zhao 2014: 400)
DEFAULT_DISCS = 400
