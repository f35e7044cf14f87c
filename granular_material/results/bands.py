"""Straight shear bands in a Gauss-point field of shear strain γ: how many, and each one's
inclination, position, width in metres and shear strain.

A field is read at one load step of a ``points`` table (step, axial_strain, x, y [m],
shear_strain), in three passes:

1. **Lines.** Each point weighs its excess max(γ − γ_b, 0) over the median γ_b of the
   points. For every direction (0.5° apart) the excess is summed along lines
   of that direction (a Hough transform: the points' weights binned by their distance along
   the normal, smoothed over one point spacing h = √(bounding-box area / points)), which
   gives the line integral of the excess [m]. Its largest value is the strongest line (its
   angle and offset refined between the grid's values by parabolas); the points within
   1.5 of that line's half-width are then taken out and the next line is searched, up to
   ``max_bands`` lines and while a line keeps at least :data:`MIN_STRENGTH` of the first's.
   The background γ_b is then the median γ of the points away from every line (farther than
   2.5 half-widths), where at least a tenth of the points are (otherwise that of all), and
   each line is moved onto its band's ridge (a weighted straight-line fit of the points'
   distance to it against their position along it, of the points whose mirror image across
   it also lies inside the specimen and away from the other lines).
2. **Profiles.** Across each line, the points (less those near the other lines, so that a
   crossing band does not count) are projected onto its normal, binned h/2 apart, and their
   mean γ read as a profile of the distance d to the line (a bin counts where it holds at
   least 3 points and 0.3 of the median bin's count). The band's **width** is the full
   width at half maximum (FWHM) of that profile above the background: the distance between
   the two points, one on each side of the peak, where the profile falls to
   γ_b + (γ_peak − γ_b)/2, each read between the bins around it (so the width is not a
   multiple of the element size) on the parabola through the logarithm of the excess
   γ − γ_b of those two bins and of the next one towards the peak h/2 or more from them
   (exact for a Gaussian profile, where a straight line would widen a band sampled by two
   or three points), or linearly where an excess there is not positive (a sharp-edged
   band). The peak is the largest bin's mean, refined likewise by the parabola through the
   logarithm of its excess and that of the nearest bins h/2 or more from it on each side
   (at most 20 % above the largest bin). A Gaussian band
   γ_b + A exp(−d²/2s²) has a width of 2√(2 ln 2) s ≈ 2.3548 s.
3. **Bands.** A line is a band when its profile peak is at least :data:`MIN_CONTRAST` times
   the background, the profile falls to half its peak on both sides inside the specimen,
   and the band is at least :data:`MIN_ASPECT` times longer than wide (its length is that
   of the stretch of its axis, in bins of h, along which the mean γ of the points within
   half a width of it, away from the other lines, stays above the background by half its
   largest excess or more).
   A uniform field, a smooth gradient or a round hot spot gives no band, nor does a profile
   narrower than the point spacing h (not resolved).

One straight band gives one; a symmetric cross (X) of two gives two at ±θ; several reflected
bands give several. The strongest band (the largest line integral of the excess, the first
of :func:`find_bands`) gives :func:`band_width`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

__all__ = ["MAX_BANDS", "MIN_ASPECT", "MIN_CONTRAST", "MIN_STRENGTH", "Band", "band_width",
           "find_bands", "step_points"]

#: the most bands :func:`find_bands` looks for by default
MAX_BANDS = 4
#: a band's profile peak over the background γ it needs at least [-]
MIN_CONTRAST = 1.5
#: a band's length over its width it needs at least [-]
MIN_ASPECT = 3.0
#: a further line's integral of excess γ over the strongest line's it needs at least [-]
MIN_STRENGTH = 0.25

#: the directions searched [°]: −90 to 89.5 by 0.5, so many at a time
_ANGLES_DEG = np.arange(-90.0, 90.0, 0.5)
_CHUNK = 30
#: the points within this many half-widths (half the search's FWHM) of a found line are taken
#: out of the next search, and within _EXCLUDE of the other lines' profiles and fits
_STRIP = 1.5
_EXCLUDE = 2.5
#: the least share of the points away from every line that gives the background instead of
#: all the points' median
_AWAY = 0.1
#: the ridge fits of a found line, and the most one may turn it [°]
_REFINE = 4
_REFINE_LIMIT_DEG = 10.0
#: the half-width of the strip fitted, in the search's half-widths
_FIT_WINDOW = 3.0
#: a profile bin counts where it holds at least this many points and this share of the
#: median bin's
_FEWEST = 3
_SHARE = 0.3
#: the largest factor by which the refined peak may exceed the largest bin's mean excess
_PEAK_CAP = 1.2
#: the Hough accumulator's smoothing along the offset: its standard deviation, in bins, and
#: how far the kernel reaches, in standard deviations
_SMOOTH_BINS = 4.0
_SMOOTH_REACH = 4.0


@dataclass(frozen=True)
class Band:
    """One straight shear band at one load step.

    Attributes:
        step: load step of the points.
        axial_strain: axial strain of that step [-], compression +.
        inclination_deg: angle of the band's axis to the x axis [°], in (−90, 90]; positive
            when the band rises to the right (``/``).
        offset: signed distance of the axis from the origin along its normal
            (−sin θ, cos θ) [m]: the axis is −x sin θ + y cos θ = offset.
        centre_x, centre_y: the point of the axis nearest the band's centre of excess
            γ [m].
        width: full width at half maximum of the band's γ profile above the background [m].
        length: how far along its axis the band's γ stays above the background by half its
            largest excess or more, to the point spacing [m].
        peak_shear_strain: the profile's peak γ [-].
        mean_shear_strain: mean γ of the points within half a width of the axis [-].
        background_shear_strain: the median γ of the points away from the bands [-].
        strength: line integral along the axis of γ above the background [m]; the bands are
            listed strongest first.
    """

    step: int
    axial_strain: float
    inclination_deg: float
    offset: float
    centre_x: float
    centre_y: float
    width: float
    length: float
    peak_shear_strain: float
    mean_shear_strain: float
    background_shear_strain: float
    strength: float

    def as_dict(self) -> dict[str, float]:
        """The measures as a plain dict (for JSON)."""
        return asdict(self)


@dataclass(frozen=True)
class _Line:
    angle: float  # direction of the axis [rad]
    offset: float  # [m], along the normal (−sin, cos)
    half_width: float  # half the accumulator's FWHM [m]
    strength: float  # [m]


def _normal(angle: float) -> np.ndarray:
    return np.array([-math.sin(angle), math.cos(angle)])


def _crossing(d0: float, m0: float, d1: float, m1: float, level: float) -> float:
    """Where the segment (d0, m0)–(d1, m1) reaches ``level`` (linear)."""
    return d0 if m1 == m0 else d0 + (level - m0) / (m1 - m0) * (d1 - d0)


def _fwhm(d: np.ndarray, m: np.ndarray, i: int, level: float,
          base: float | None = None, gap: float = 0.0) -> tuple[float, float]:
    """The distances left and right of index ``i`` where ``m`` (sampled at increasing ``d``)
    first falls to ``level`` or below; NaN on a side where it never does. With ``base``,
    each crossing is read on the parabola through the logarithm of ``m − base`` at the two
    samples around it and the next one towards ``i`` at least ``gap`` from the inner one
    (exact for a Gaussian, whose tails a straight line would widen), where those are
    positive and the parabola crosses between the two; linearly otherwise."""
    left = right = math.nan
    below = np.flatnonzero(m[:i] <= level)
    if below.size:
        j = int(below[-1])
        left = _crossing(d[j], m[j], d[j + 1], m[j + 1], level)
        third = np.flatnonzero(d[j + 2:i + 1] >= d[j + 1] + gap)
        if base is not None and third.size:
            k = j + 2 + int(third[0])
            left = _log_crossing(d[[j, j + 1, k]], m[[j, j + 1, k]], level, base, left)
    below = np.flatnonzero(m[i + 1:] <= level)
    if below.size:
        j = i + 1 + int(below[0])
        right = _crossing(d[j - 1], m[j - 1], d[j], m[j], level)
        third = np.flatnonzero(d[i:j - 1] <= d[j - 1] - gap)
        if base is not None and third.size:
            k = i + int(third[-1])
            right = _log_crossing(d[[k, j - 1, j]], m[[k, j - 1, j]], level, base, right)
    return left, right


def _log_crossing(d: np.ndarray, m: np.ndarray, level: float, base: float,
                  linear: float) -> float:
    """Where the parabola through (d, log(m − base)) at three samples reaches
    log(level − base) between the two samples that bracket ``level`` (the outer pair: the
    first two on the left, the last two on the right); ``linear`` where it does not."""
    excess = m - base
    if not (excess.min() > 0 and level > base):
        return linear
    a, b, c = np.polyfit(d - d[1], np.log(excess), 2)
    c -= math.log(level - base)
    if a == 0:
        return linear
    root = b * b - 4 * a * c
    if root < 0:
        return linear
    lo, hi = (d[0], d[1]) if m[0] <= level else (d[1], d[2])
    for x in ((-b - math.sqrt(root)) / (2 * a), (-b + math.sqrt(root)) / (2 * a)):
        if lo <= x + d[1] <= hi:
            return float(x + d[1])
    return linear


def _parabola_vertex(y0: float, y1: float, y2: float) -> tuple[float, float]:
    """Vertex (shift in samples from the middle one, value) of the parabola through three
    equally spaced samples; (0, y1) where they are not a peak."""
    curvature = y0 - 2 * y1 + y2
    if curvature >= 0:
        return 0.0, y1
    shift = 0.5 * (y0 - y2) / curvature
    shift = min(max(shift, -0.5), 0.5)
    return shift, y1 - 0.25 * (y0 - y2) * shift


def _smoothed(rows: np.ndarray, sigma: float = _SMOOTH_BINS) -> np.ndarray:
    """Each row of ``rows`` convolved with a normalised Gaussian kernel of standard
    deviation ``sigma`` [bins] cut at :data:`_SMOOTH_REACH` of them, zero beyond the row's
    ends. The kernel's terms are added in pairs from its tails inwards, which gives
    ``scipy.ndimage.gaussian_filter1d(rows, sigma, axis=1, mode="constant")`` to the last bit
    without importing ``scipy.ndimage`` (about 0.3 s of every run's start)."""
    radius = int(_SMOOTH_REACH * sigma + 0.5)
    offsets = np.arange(-radius, radius + 1)
    kernel = np.exp(-0.5 / (sigma * sigma) * offsets ** 2)
    kernel = kernel / kernel.sum()
    n = rows.shape[1]
    padded = np.zeros((rows.shape[0], n + 2 * radius))
    padded[:, radius:radius + n] = rows
    out = padded[:, radius:radius + n] * kernel[radius]
    for k in range(radius, 0, -1):
        out = out + (padded[:, radius + k:radius + k + n]
                     + padded[:, radius - k:radius - k + n]) * kernel[radius + k]
    return out


def _strongest_line(xy: np.ndarray, weight: np.ndarray, spacing: float,
                    reach: float) -> _Line:
    """The line of the largest integral of ``weight`` (each point standing for spacing²),
    with the points centred on the origin, within ``reach`` of it."""
    angles = np.radians(_ANGLES_DEG)
    bin_size = spacing / 4
    bins = math.ceil(2 * reach / bin_size) + 1
    accumulator = np.empty((angles.size, bins))
    for start in range(0, angles.size, _CHUNK):  # a few directions at a time: bounded memory
        chunk = angles[start:start + _CHUNK]
        distance = xy[:, 0:1] * -np.sin(chunk) + xy[:, 1:2] * np.cos(chunk)
        index = np.clip(np.floor((distance + reach) / bin_size).astype(int), 0, bins - 1)
        index = index + bins * np.arange(chunk.size)
        accumulator[start:start + chunk.size] = np.bincount(
            index.ravel(), weights=np.repeat(weight[:, None] * spacing ** 2, chunk.size, axis=1)
            .ravel(), minlength=bins * chunk.size).reshape(chunk.size, bins)
    accumulator = _smoothed(accumulator / bin_size)
    k, j = np.unravel_index(int(np.argmax(accumulator)), accumulator.shape)
    ridge = accumulator.max(axis=1)
    shift, _ = _parabola_vertex(ridge[k - 1], ridge[k], ridge[(k + 1) % angles.size])
    angle = angles[k] + shift * math.radians(_ANGLES_DEG[1] - _ANGLES_DEG[0])
    row = accumulator[k]
    if 0 < j < bins - 1:
        shift_p, strength = _parabola_vertex(row[j - 1], row[j], row[j + 1])
    else:
        shift_p, strength = 0.0, float(row[j])
    offset = (j + 0.5 + shift_p) * bin_size - reach
    left, right = _fwhm(np.arange(bins) * bin_size, row, j, row[j] / 2)
    half = [abs(s - j * bin_size) for s in (left, right) if math.isfinite(s)]
    half_width = max(max(half) if half else 4 * spacing, 2 * spacing)
    return _Line(angle=float(angle), offset=float(offset), half_width=float(half_width),
                 strength=float(strength))


def _near(xy: np.ndarray, lines: list[_Line], reach: float) -> np.ndarray:
    """Whether each point lies within ``reach`` half-widths of any of ``lines``."""
    near = np.zeros(len(xy), dtype=bool)
    for line in lines:
        near |= np.abs(xy @ _normal(line.angle) - line.offset) < reach * line.half_width
    return near


def _refined(line: _Line, xy: np.ndarray, excess: np.ndarray, others: list[_Line]) -> _Line:
    """``line`` moved onto the band's ridge: the distance d of the points near it to it,
    weighted by their excess, fitted linearly against their position t along it (a few
    times, each about the line found before). A point counts only where its mirror image
    across the line also lies inside the points' bounding box and away from the ``others``:
    where a side or another band cuts the band, its mass no longer lies evenly about the
    axis, and the Hough search (which also favours the longer lines of a tall specimen) or
    a principal axis would be turned by a degree or two."""
    low, high = xy.min(axis=0), xy.max(axis=0)
    for _ in range(_REFINE):
        normal = _normal(line.angle)
        along = np.array([normal[1], -normal[0]])
        d = xy @ normal - line.offset
        t = xy @ along
        mirror = xy - 2 * d[:, None] * normal
        near = ((np.abs(d) < _FIT_WINDOW * line.half_width)
                & ((mirror >= low) & (mirror <= high)).all(axis=1)
                & ~_near(xy, others, _EXCLUDE) & ~_near(mirror, others, _EXCLUDE))
        weight = excess[near]
        if near.sum() < 3 or not weight.sum() > 0:
            break
        t_mean = float(weight @ t[near] / weight.sum())
        d_mean = float(weight @ d[near] / weight.sum())
        var = float(weight @ (t[near] - t_mean) ** 2)
        if not var > 0:
            break
        slope = float(weight @ ((t[near] - t_mean) * (d[near] - d_mean))) / var
        turn = math.atan(slope)
        if abs(turn) > math.radians(_REFINE_LIMIT_DEG):
            break  # not a line-like ridge about this line: keep the search's
        point = (line.offset + d_mean) * normal + t_mean * along
        angle = line.angle + turn
        line = _Line(angle=angle, offset=float(point @ _normal(angle)),
                     half_width=line.half_width, strength=line.strength)
    return line


def step_points(points: pd.DataFrame, step: int | None) -> tuple[int, float, pd.DataFrame]:
    """The step (None: the last), its axial strain [-] and its rows of a Gauss-point table;
    ValueError for a table without the columns a band search reads, without that step, or
    whose shear strain there is not finite."""
    missing = {"step", "axial_strain", "x", "y", "shear_strain"} - set(points.columns)
    if missing:
        raise ValueError(f"points table lacks columns {sorted(missing)}")
    step = int(points["step"].max()) if step is None else int(step)
    at = points[points["step"] == step]
    if at.empty:
        raise ValueError(f"points table has no step {step}")
    if not np.isfinite(at["shear_strain"].to_numpy(dtype=float)).all():
        raise ValueError(f"shear strain at step {step} is not finite")
    return step, float(at["axial_strain"].iloc[0]), at


def find_bands(points: pd.DataFrame, step: int | None = None, max_bands: int = MAX_BANDS,
               contrast: float = MIN_CONTRAST, aspect: float = MIN_ASPECT) -> list[Band]:
    """The straight shear bands of ``points``' ``shear_strain`` at ``step`` (see the module
    docstring), strongest first; an empty list where there is none.

    Args:
        points: Gauss-point table with columns step, axial_strain, x, y [m], shear_strain.
        step: load step to measure; None: the last one.
        max_bands: the most bands looked for (≥ 1).
        contrast: the profile peak over the background γ a band needs at least [-].
        aspect: the length over the width a band needs at least [-].
    """
    if max_bands < 1:
        raise ValueError(f"max_bands must be at least 1, got {max_bands!r}")
    step, strain, at = step_points(points, step)
    xy = at[["x", "y"]].to_numpy(dtype=float)
    gamma = at["shear_strain"].to_numpy(dtype=float)
    extent = xy.max(axis=0) - xy.min(axis=0) if len(xy) else np.zeros(2)
    if gamma.size < 8 or extent.min() <= 0:
        return []
    spacing = math.sqrt(float(extent.prod()) / gamma.size)
    background = float(np.median(gamma))
    excess = np.maximum(gamma - background, 0.0)
    if not excess.max() > 0:
        return []
    origin = 0.5 * (xy.max(axis=0) + xy.min(axis=0))
    centred = xy - origin
    reach = 0.5 * float(np.hypot(*extent)) + 4 * spacing
    lines: list[_Line] = []
    weight = excess.copy()
    while len(lines) < max_bands and weight.max() > 0:
        line = _strongest_line(centred, weight, spacing, reach)
        if lines and line.strength < MIN_STRENGTH * lines[0].strength:
            break
        lines.append(line)
        weight[_near(centred, [line], _STRIP)] = 0.0
    away = ~_near(centred, lines, _EXCLUDE)
    if away.sum() >= max(8, _AWAY * gamma.size):
        # bands that cover much of the specimen lift the median: the background is that of
        # the points away from them
        background = float(np.median(gamma[away]))
        excess = np.maximum(gamma - background, 0.0)
    bands = []
    for k, line in enumerate(lines):
        others = lines[:k] + lines[k + 1:]
        line = _refined(line, centred, excess, others)
        keep = ~_near(centred, others, _EXCLUDE)
        band = _measure(centred, gamma, keep, line, spacing, background, contrast, aspect)
        if band is not None:
            bands.append(_placed(band, origin, step, strain))
    return bands


def _measure(xy: np.ndarray, gamma: np.ndarray, keep: np.ndarray, line: _Line,
             spacing: float, background: float, contrast: float,
             aspect: float) -> dict[str, float] | None:
    """The band along ``line`` from the profile of the ``keep`` points (coordinates centred);
    None where it is no band."""
    normal = _normal(line.angle)
    distance = xy @ normal - line.offset
    d, g = distance[keep], gamma[keep]
    if d.size < 8:
        return None
    bin_size = spacing / 2
    index = np.floor((d - d.min()) / bin_size).astype(int)
    count = np.bincount(index)
    # a bin with a few points only (where a row of points is split between two bins) stands
    # for a part of the band's length, not for all of it
    full = count >= max(_FEWEST, _SHARE * float(np.median(count[count > 0])))
    centre_d = (np.bincount(index, weights=d)[full] / count[full])
    mean = (np.bincount(index, weights=g)[full] / count[full])
    close = np.flatnonzero(np.abs(centre_d) <= max(line.half_width, 2 * spacing))
    if close.size == 0:
        return None
    i = int(close[np.argmax(mean[close])])
    peak = float(mean[i])
    lower = np.flatnonzero(centre_d <= centre_d[i] - bin_size)
    upper = np.flatnonzero(centre_d >= centre_d[i] + bin_size)
    if lower.size and upper.size:
        # the log of a Gaussian is a parabola: refine the peak between the bins around it
        around = [int(lower[-1]), i, int(upper[0])]
        excess = mean[around] - background
        if excess.min() > 0:
            spread = centre_d[around] - centre_d[i]
            coefficients = np.polyfit(spread, np.log(excess), 2)
            if coefficients[0] < 0:
                top = -coefficients[1] / (2 * coefficients[0])
                if spread[0] <= top <= spread[2]:
                    refined = background + math.exp(np.polyval(coefficients, top))
                    peak = min(max(refined, peak),
                               background + _PEAK_CAP * (peak - background))
    if not (peak > background and peak >= contrast * background):
        return None
    level = background + 0.5 * (peak - background)
    left, right = _fwhm(centre_d, mean, i, level, background, spacing / 2)
    if not (math.isfinite(left) and math.isfinite(right)) or right <= left:
        return None
    width = float(right - left)
    if width < spacing:
        return None  # narrower than the points' spacing: not resolved
    middle = 0.5 * (left + right)
    inside = np.abs(distance - middle) <= 0.5 * width
    own = inside & keep  # a stronger band crossing this one would set its level
    length = (_length(xy[own] @ np.array([normal[1], -normal[0]]), gamma[own], background,
                      spacing) if own.any() else 0.0)
    if length < aspect * width:
        return None
    excess = np.maximum(gamma - background, 0.0) * inside
    along = np.array([normal[1], -normal[0]])
    position = float(excess @ (xy @ along) / excess.sum()) if excess.sum() > 0 else 0.0
    return {"angle": line.angle, "offset": line.offset + middle, "along": position,
            "width": float(width), "length": length, "peak": peak,
            "mean": float(gamma[inside].mean()), "background": background,
            "strength": line.strength}


def _length(t: np.ndarray, gamma: np.ndarray, background: float, spacing: float) -> float:
    """How long [m] a band is whose points lie at ``t`` along its axis: the length, in bins
    of the point spacing, over which their mean γ stays above the background by half its
    largest excess or more."""
    index = np.floor((t - t.min()) / spacing).astype(int)
    count = np.bincount(index)
    mean = np.bincount(index, weights=gamma)[count > 0] / count[count > 0]
    level = background + 0.5 * (mean.max() - background)
    return float(np.count_nonzero(mean >= level)) * spacing


def _placed(band: dict[str, float], origin: np.ndarray, step: int, strain: float) -> Band:
    """``band`` (measured on coordinates centred on ``origin``) in the table's coordinates,
    its inclination in (−90, 90]."""
    angle = band["angle"]
    normal, along = _normal(angle), np.array([math.cos(angle), math.sin(angle)])
    centre = origin + band["offset"] * normal + band["along"] * along
    degrees = math.degrees(angle)
    degrees = degrees - 180.0 if degrees > 90 else degrees + 180.0 if degrees <= -90 else degrees
    offset = float(centre @ _normal(math.radians(degrees)))
    return Band(step=step, axial_strain=strain, inclination_deg=degrees, offset=offset,
                centre_x=float(centre[0]), centre_y=float(centre[1]), width=band["width"],
                length=band["length"], peak_shear_strain=band["peak"],
                mean_shear_strain=band["mean"], background_shear_strain=band["background"],
                strength=band["strength"])


def band_width(points: pd.DataFrame, step: int | None = None) -> float:
    """The width [m] of the strongest shear band of ``points`` at ``step`` (None: the last),
    the full width at half maximum of its γ profile above the background (see
    :func:`find_bands`); NaN where there is no band."""
    bands = find_bands(points, step)
    return bands[0].width if bands else math.nan
