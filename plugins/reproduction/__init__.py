"""Reproduction package of Wu, Fu & Zhou (2025): their study rerun by one command
(``granular-material reproduce wu2025``), each claim of the paper beside our measurement."""

from .scales import SCALES, ReproductionScale
from .study import run_reproduction

__all__ = ["SCALES", "ReproductionScale", "run_reproduction"]
