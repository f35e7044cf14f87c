"""The shear bands active over an interval of a run: the shear strain of the strain increment
between two load steps, fitted as a sum of straight Gaussian ridges; each band's width in
metres.

The accumulated shear strain γ of a step (what :mod:`granular_material.results.bands`
reads) carries all the deformation before it: the diffuse straining before the band formed,
the platens' dead zones, a band that has stopped. Bands in sand are measured on the
*incremental* field instead, the strain between two states of the test (Desrues & Viggiani
2004, IJNAMG 28:279): the band that is shearing now. :func:`incremental_points` makes that
field from a ``points`` table, the Gauss points' change of strain (exx, eyy, exy) between a
start step and a step, and its shear strain γ = √((Δexx − Δeyy)² + (2Δexy)²).

Where bands are a few elements wide and apart,
:func:`~granular_material.results.bands.find_bands` reads each one's profile on its own. A
band as wide as a third of the specimen (a regularised one) overlaps its neighbours: a
cross's two arms share the specimen's middle, and no part of an arm lies far enough from the
other to be read alone. :func:`fit_bands` therefore describes the whole field at once, as a
background plus straight ridges,

    γ(x) ≈ b + Σ_k A_k exp(−d_k(x)² / 2 s_k²),

d_k the distance of a point to ridge k's axis, fitted by least squares (Levenberg–Marquardt)
to every point (b ≥ 0, A_k ≥ 0). Ridges are added one at a time (matching pursuit), up to
``max_bands``: each new one starts on the line of the largest integral of the residual (the
Hough search of :mod:`~granular_material.results.bands`) and on that line turned by 30°,
60°, …, 150°, and every ridge is refitted together from each start, the best of the six fits
kept. The fit kept is the one of the most ridges whose last ridge explained at least
:data:`MIN_SHARE` of the field's variance about its mean (the squared residual fell by that
much) and whose ridges are each resolved (a width of at least the points' spacing) and fall
to half their height on both sides inside the specimen and hold half their height along at
least :data:`MIN_RUN` of their axis (a round spot is no band). Each band's **width** is its
ridge's full width at half maximum, 2√(2 ln 2) s ≈ 2.3548 s. The rule is the same for every
field: no threshold is set per run.

A uniform field, a smooth gradient or noise gives no band.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from granular_material.results.bands import _Line, _normal, _strongest_line, step_points

__all__ = ["FWHM_PER_SIGMA", "INCREMENT_SHARE", "MAX_RIDGES", "MIN_RUN", "MIN_SHARE", "FittedBand",
           "active_bands", "fit_bands", "incremental_points", "start_step"]

#: a Gaussian ridge's full width at half maximum over its standard deviation [-]
FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))
#: the most ridges :func:`fit_bands` fits by default
MAX_RIDGES = 4
#: the share of the field's variance (about its mean) a further ridge must explain [-]
MIN_SHARE = 0.06
#: the least share of its axis's chord through the points along which a ridge must hold
#: half its height [-]
MIN_RUN = 0.5
#: :func:`active_bands`' interval by default: the last this share of the step's axial
#: strain [-] (the last 1 % of a 5 % run)
INCREMENT_SHARE = 0.2

_STRAIN_COLUMNS = ("exx", "eyy", "exy")
#: the directions a new ridge is started in, 180°/_TURNS apart from the search's line
_TURNS = 6


@dataclass(frozen=True)
class FittedBand:
    """One straight band of a field fitted as Gaussian ridges (:func:`fit_bands`).

    Attributes:
        step: load step of the field.
        axial_strain: that step's axial strain [-].
        start_step: the step the increment starts from (None: the field is not an
            increment).
        start_axial_strain: that step's axial strain [-] (NaN: not an increment).
        inclination_deg: angle of the band's axis to the x axis [°], in (−90, 90], positive
            rising to the right.
        offset: the axis is −x sin θ + y cos θ = offset [m].
        centre_x, centre_y: the point of the axis at the centre of the ridge's γ over the
            points [m].
        width: the ridge's full width at half maximum [m].
        amplitude: the ridge's height above the background [-]; bands are listed highest
            first.
        background: the fit's background γ [-].
        residual: the whole fit's root-mean-square residual over that of γ about its mean
            [-] (0: the ridges describe the field exactly).
    """

    step: int
    axial_strain: float
    start_step: int | None
    start_axial_strain: float
    inclination_deg: float
    offset: float
    centre_x: float
    centre_y: float
    width: float
    amplitude: float
    background: float
    residual: float

    def as_dict(self) -> dict[str, float | int | None]:
        """The measures as a plain dict (for JSON)."""
        return asdict(self)


def _steps(points: pd.DataFrame) -> pd.Series:
    """Each step's axial strain, by step."""
    return points.groupby("step", sort=True)["axial_strain"].first()


def start_step(points: pd.DataFrame, step: int | None = None,
               share: float = INCREMENT_SHARE) -> int:
    """The step an increment ending at ``step`` (None: the last) starts from: the last step
    whose axial strain is at most (1 − ``share``) times that of ``step`` in size (the first
    step where none is).

    Raises:
        ValueError: where ``share`` is not in (0, 1], ``step`` is not in ``points`` or it is
            the first step.
    """
    if not 0.0 < share <= 1.0:
        raise ValueError(f"share must be in (0, 1], got {share!r}")
    strains = _steps(points)
    step = int(strains.index.max()) if step is None else int(step)
    if step not in strains.index:
        raise ValueError(f"points table has no step {step}")
    before = strains[strains.index < step]
    if before.empty:
        raise ValueError(f"step {step} is the first: no increment ends there")
    target = (1.0 - share) * abs(float(strains[step]))
    # a step's strain reads target within rounding (0.8 × 0.05 against 40 × 0.001)
    within = before[(before.abs() <= target * (1 + 1e-9)).to_numpy()]
    return int(within.index.max() if not within.empty else before.index.min())


def incremental_points(points: pd.DataFrame, step: int | None = None,
                       start: int | None = None) -> pd.DataFrame:
    """The Gauss points of ``step`` (None: the last) with ``shear_strain`` the shear strain
    of their change of strain since step ``start`` (None: :func:`start_step`):
    √((Δexx − Δeyy)² + (2Δexy)²) [-]; also the increments ``dexx``, ``deyy``, ``dexy`` and
    the ``start_step`` and ``start_axial_strain``. Points are matched by their ``point``
    column where there is one, by their order otherwise.

    Raises:
        ValueError: where a column is missing, a step is not in the table, ``start`` is not
            before ``step`` or the two steps hold different points.
    """
    missing = {"step", "axial_strain", "x", "y", *_STRAIN_COLUMNS} - set(points.columns)
    if missing:
        raise ValueError(f"points table lacks columns {sorted(missing)}")
    steps = _steps(points)
    step = int(steps.index.max()) if step is None else int(step)
    if step not in steps.index:
        raise ValueError(f"points table has no step {step}")
    start = start_step(points, step) if start is None else int(start)
    if start not in steps.index:
        raise ValueError(f"points table has no step {start}")
    if start >= step:
        raise ValueError(f"the increment must start before step {step}, got {start}")
    end, begin = points[points["step"] == step], points[points["step"] == start]
    if "point" in points.columns:
        begin = begin.set_index("point").reindex(end["point"].to_numpy())
    if len(begin) != len(end) or begin[list(_STRAIN_COLUMNS)].isna().any().any():
        raise ValueError(f"steps {start} and {step} do not hold the same points")
    delta = {c: end[c].to_numpy(dtype=float) - begin[c].to_numpy(dtype=float)
             for c in _STRAIN_COLUMNS}
    out = end[[c for c in ("step", "axial_strain", "point", "element", "x", "y")
               if c in end.columns]].reset_index(drop=True)
    out["start_step"] = start
    out["start_axial_strain"] = float(steps[start])
    for c in _STRAIN_COLUMNS:
        out[f"d{c}"] = delta[c]
    out["shear_strain"] = np.hypot(delta["exx"] - delta["eyy"], 2.0 * delta["exy"])
    return out


def _ridges(p: np.ndarray, xy: np.ndarray, n: int) -> np.ndarray:
    """Each ridge's γ above the background at the points: (n, points)."""
    theta, offset, amplitude, sigma = (p[1:1 + 4 * n].reshape(n, 4).T if n
                                       else (np.zeros(0),) * 4)
    d = (-xy[:, 0:1] * np.sin(theta) + xy[:, 1:2] * np.cos(theta) - offset)
    return (amplitude * np.exp(-0.5 * (d / sigma) ** 2)).T


def _model(p: np.ndarray, xy: np.ndarray, n: int) -> np.ndarray:
    return p[0] + _ridges(p, xy, n).sum(axis=0)


def _jacobian(p: np.ndarray, xy: np.ndarray, n: int) -> np.ndarray:
    """d :func:`_model` / d ``p``: (points, 1 + 4 n)."""
    jac = np.empty((len(xy), 1 + 4 * n))
    jac[:, 0] = 1.0
    for k in range(n):
        theta, offset, amplitude, sigma = p[1 + 4 * k:5 + 4 * k]
        d = -xy[:, 0] * math.sin(theta) + xy[:, 1] * math.cos(theta) - offset
        shape = np.exp(-0.5 * (d / sigma) ** 2)
        slope = amplitude * shape * d / sigma ** 2  # −d ridge / d d
        jac[:, 1 + 4 * k] = slope * (xy[:, 0] * math.cos(theta) + xy[:, 1] * math.sin(theta))
        jac[:, 2 + 4 * k] = slope
        jac[:, 3 + 4 * k] = shape
        jac[:, 4 + 4 * k] = slope * d / sigma
    return jac


def _levenberg_marquardt(residual, jacobian, start: np.ndarray, lower: np.ndarray,
                         upper: np.ndarray, iterations: int = 300) -> np.ndarray:
    """The parameters within [lower, upper] that minimise |residual(p)|², from ``start``:
    Levenberg–Marquardt steps scaled by the diagonal of JᵀJ (so the parameters' units do not
    matter), a parameter held on a bound the descent points out of, each step projected
    onto the bounds. numpy only: scipy.optimize would load
    scipy.spatial into every run that writes a summary."""
    p = np.clip(start, lower, upper)
    r = residual(p)
    cost = float(r @ r)
    damping = 1e-3
    for _ in range(iterations):
        jac = jacobian(p)
        normal = jac.T @ jac
        gradient = jac.T @ r
        diagonal = np.maximum(np.diag(normal), 1e-30 * max(float(np.diag(normal).max()),
                                                            1e-300))
        # a parameter on a bound that the descent would push out of it stays there
        free = ~(((p <= lower) & (gradient > 0)) | ((p >= upper) & (gradient < 0)))
        system = normal[np.ix_(free, free)]
        while True:
            step = np.zeros_like(p)
            try:
                step[free] = np.linalg.solve(system + damping * np.diag(diagonal[free]),
                                             -gradient[free])
            except np.linalg.LinAlgError:
                pass
            trial = np.clip(p + step, lower, upper)
            r_trial = residual(trial)
            cost_trial = float(r_trial @ r_trial)
            if cost_trial < cost:
                break
            damping *= 4.0
            if damping > 1e12:
                return p
        converged = cost - cost_trial <= 1e-12 * cost or np.all(
            np.abs(trial - p) <= 1e-10 * (np.abs(p) + 1e-12))
        p, r, cost = trial, r_trial, cost_trial
        damping = max(damping / 3.0, 1e-12)
        if converged:
            break
    return p


def _best_fit(xy: np.ndarray, gamma: np.ndarray, p: np.ndarray, line: _Line, height: float,
              spacing: float, reach: float) -> np.ndarray:
    """The ridges of ``p`` and one more, fitted together: the new one started on ``line``
    (its height ``height``) and turned by 0, 30, …, 150° about its point nearest the centre;
    the fit of the least residual. (The search's line starts a ridge well where bands are
    narrow; a wide, diffuse zone has shallow minima that one start can miss.)"""
    m = (p.size - 1) // 4 + 1
    lower = np.array([0.0] + [-np.inf, -reach, 0.0, spacing / 8] * m)
    upper = np.array([np.inf] + [np.inf, reach, np.inf, reach] * m)
    point = line.offset * _normal(line.angle)
    sigma = min(max(line.half_width, spacing) / (0.5 * FWHM_PER_SIGMA), reach)
    best, best_cost = p, math.inf
    for turn in range(_TURNS):
        angle = line.angle + turn * math.pi / _TURNS
        start = np.r_[p, angle, float(np.clip(point @ _normal(angle), -reach, reach)),
                      height, max(sigma, spacing / 8)]
        fit = _levenberg_marquardt(lambda q: _model(q, xy, m) - gamma,
                                   lambda q: _jacobian(q, xy, m), start, lower, upper)
        cost = float(np.sum((_model(fit, xy, m) - gamma) ** 2))
        if cost < best_cost:
            best, best_cost = fit, cost
    return best


def _alive(p: np.ndarray, scale: float) -> np.ndarray:
    """``p`` without its ridges of no height (below 10⁻⁶ of the field's spread ``scale``)."""
    keep = [0] + [i for k in range((p.size - 1) // 4) if p[3 + 4 * k] > 1e-6 * scale
                  for i in range(1 + 4 * k, 5 + 4 * k)]
    return p[keep]


def _admissible(p: np.ndarray, xy: np.ndarray, gamma: np.ndarray, n: int,
                spacing: float) -> bool:
    """Whether every ridge of ``p`` is a band: positive, resolved (at least ``spacing``
    wide), falling to half its height on both sides inside the points' extent, and running
    along at least :data:`MIN_RUN` of its axis's chord: the mean γ of the points within half a
    width of the axis, in bins of ``spacing`` along it, at least half the ridge's height
    above the background over that share of the bins (a round spot is no band)."""
    for k in range(n):
        theta, offset, amplitude, sigma = p[1 + 4 * k:5 + 4 * k]
        half = 0.5 * FWHM_PER_SIGMA * sigma
        distance = -xy[:, 0] * math.sin(theta) + xy[:, 1] * math.cos(theta)
        if not (amplitude > 0 and 2 * half >= spacing
                and distance.min() < offset - half and offset + half < distance.max()):
            return False
        inside = np.abs(distance - offset) <= max(half, spacing)
        along = xy[inside] @ np.array([math.cos(theta), math.sin(theta)])
        index = np.floor((along - along.min()) / spacing).astype(int)
        count = np.bincount(index)
        mean = np.bincount(index, weights=gamma[inside])[count > 0] / count[count > 0]
        if np.count_nonzero(mean >= p[0] + 0.5 * amplitude) < MIN_RUN * mean.size:
            return False
    return True


def fit_bands(points: pd.DataFrame, step: int | None = None, max_bands: int = MAX_RIDGES,
              share: float = MIN_SHARE) -> list[FittedBand]:
    """The straight bands of ``points``' ``shear_strain`` at ``step`` (None: the last) as
    Gaussian ridges fitted to the whole field (see the module docstring), highest first; an
    empty list where there is none.

    Args:
        points: Gauss-point table with columns step, axial_strain, x, y [m], shear_strain
            (an :func:`incremental_points` table: the active bands).
        step: load step to fit; None: the last one.
        max_bands: the most ridges fitted (≥ 1).
        share: the share of the field's variance (about its mean) a further ridge must
            explain, in (0, 1).
    """
    if max_bands < 1:
        raise ValueError(f"max_bands must be at least 1, got {max_bands!r}")
    if not 0.0 < share < 1.0:
        raise ValueError(f"share must be in (0, 1), got {share!r}")
    step, _, at = step_points(points, step)
    xy = at[["x", "y"]].to_numpy(dtype=float)
    gamma = at["shear_strain"].to_numpy(dtype=float)
    extent = xy.max(axis=0) - xy.min(axis=0) if len(xy) else np.zeros(2)
    if gamma.size < 8 or extent.min() <= 0:
        return []
    spacing = math.sqrt(float(extent.prod()) / gamma.size)
    origin = 0.5 * (xy.max(axis=0) + xy.min(axis=0))
    centred = xy - origin
    reach = 0.5 * float(np.hypot(*extent)) + 4 * spacing
    scale = float(np.sqrt(np.mean((gamma - gamma.mean()) ** 2)))
    if not scale > 1e-12 * max(float(np.abs(gamma).max()), 1e-300):
        return []
    p, rms = np.array([max(float(gamma.mean()), 0.0)]), scale
    chosen, chosen_rms, n = p, rms, 0
    for _ in range(max_bands):  # the pursuit's path: one more ridge each time
        m = (p.size - 1) // 4 + 1
        if rms ** 2 < share * scale ** 2:
            break  # no further ridge can explain that share
        residual = gamma - _model(p, centred, m - 1)
        excess = np.maximum(residual - np.median(residual), 0.0)
        if not excess.max() > 0:
            break
        line = _strongest_line(centred, excess, spacing, reach)
        fit = _best_fit(centred, gamma, p, line, excess.max(), spacing, reach)
        fit = _alive(fit, scale)
        new = float(np.sqrt(np.mean((_model(fit, centred, (fit.size - 1) // 4) - gamma)
                                    ** 2)))
        if (fit.size == p.size + 4 and rms ** 2 - new ** 2 >= share * scale ** 2
                and _admissible(fit, centred, gamma, m, spacing)):
            chosen, chosen_rms, n = fit, new, m
        p, rms = fit, new
    p, rms = chosen, chosen_rms
    strain = float(at["axial_strain"].iloc[0])
    start_step_ = int(at["start_step"].iloc[0]) if "start_step" in at.columns else None
    start_strain = (float(at["start_axial_strain"].iloc[0])
                    if "start_axial_strain" in at.columns else math.nan)
    ridges = _ridges(p, centred, n)
    bands = []
    for k in range(n):
        theta, offset, amplitude, sigma = p[1 + 4 * k:5 + 4 * k]
        along = np.array([math.cos(theta), math.sin(theta)])
        normal = np.array([-math.sin(theta), math.cos(theta)])
        weight = ridges[k]
        t = float(weight @ (centred @ along) / weight.sum()) if weight.sum() > 0 else 0.0
        centre = origin + offset * normal + t * along
        degrees = (math.degrees(theta) + 90.0) % 180.0 - 90.0
        degrees = 90.0 if degrees == -90.0 else degrees
        bands.append(FittedBand(
            step=step, axial_strain=strain, start_step=start_step_,
            start_axial_strain=start_strain, inclination_deg=degrees,
            offset=float(centre @ np.array([-math.sin(math.radians(degrees)),
                                            math.cos(math.radians(degrees))])),
            centre_x=float(centre[0]), centre_y=float(centre[1]),
            width=float(FWHM_PER_SIGMA * sigma), amplitude=float(amplitude),
            background=float(p[0]), residual=rms / scale))
    return sorted(bands, key=lambda b: -b.amplitude)


def active_bands(points: pd.DataFrame, step: int | None = None, start: int | None = None,
                 max_bands: int = MAX_RIDGES, share: float = MIN_SHARE) -> list[FittedBand]:
    """The bands active at ``step`` (None: the last): :func:`fit_bands` of the shear strain
    of the increment since ``start`` (None: :func:`start_step`, the last
    :data:`INCREMENT_SHARE` of the axial strain), highest first; an empty list where there is
    none or the table has no strain columns or one step only."""
    if not set(_STRAIN_COLUMNS) <= set(points.columns) or points["step"].nunique() < 2:
        return []
    field = incremental_points(points, step, start)
    return fit_bands(field, max_bands=max_bands, share=share)
