"""Batched periodic 2D DEM on warp: many RVEs of discs advanced together."""

from granular_material.dem.rve_file import (
    FORMAT_VERSION,
    RVEData,
    RVEFileError,
    RVEMeta,
    load_rve,
    save_rve,
)

__all__ = ["FORMAT_VERSION", "RVEData", "RVEFileError", "RVEMeta", "load_rve", "save_rve"]
