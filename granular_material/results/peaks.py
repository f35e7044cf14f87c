"""The peak of a stress-ratio curve, found once for the commands, the summaries and the
validation suite."""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["find_peak"]


def _smooth(values: np.ndarray, window: int) -> np.ndarray:
    if window <= 1:
        return values
    return pd.Series(values).rolling(window, center=True, min_periods=1).median().to_numpy()


def find_peak(strain: np.ndarray, ratio: np.ndarray, window: int = 1) -> tuple[int, float]:
    """Index and value of the peak of ``ratio`` along ``strain`` (both shape (n,)).

    With ``window`` > 1 the index is located on a centred running median of that many points
    (DEM curves are noisy); the value returned is the raw ratio there. ``window`` = 1 is the
    plain largest value (NaNs skipped). Returns (-1, nan) if the ratio is all NaN.
    """
    ratio = np.asarray(ratio, dtype=np.float64)
    if len(strain) != len(ratio):
        raise ValueError(f"strain and ratio lengths differ: {len(strain)} != {len(ratio)}")
    if window < 1:
        raise ValueError(f"window must be >= 1, got {window}")
    smooth = _smooth(ratio, window)
    if np.isnan(smooth).all():
        return -1, float("nan")
    i = int(np.nanargmax(smooth))
    return i, float(ratio[i])
