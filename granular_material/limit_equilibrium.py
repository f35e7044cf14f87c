"""Bishop's simplified method of slices: the factor of safety of a slope on circular slip
surfaces, the search for the critical circle, and the gravity-increase factor.

A reference for the finite-element collapse loads, not a finite-element method: plane
strain, dry ground (no pore pressure), a ground surface given as a polyline y(x), horizontal
layers each with its Mohr–Coulomb strength (c [Pa], φ [°]) and unit weight γ [N/m³], and
vertical surcharge strips [Pa] on the surface. Units are SI throughout: m, Pa, N/m³, and
forces per metre run of slope [N/m].

The method (Bishop 1955). The sliding mass above a circle (centre (xc, yc), radius R) is cut
into vertical slices of equal width b. Each slice has a weight W (the layers' γ over its column),
the surcharge Q on its top, and a base inclined at α, with the strength c, φ of the layer its
base lies in. Taking moments about the centre and the interslice forces horizontal,

    F = Σ [c b + (W + Q) tan φ] / m_α  /  Σ (W + Q) sin α,   m_α = cos α + sin α tan φ / F,

solved by fixed-point iteration on F, with α at the slice's middle and b taken as l cos α,
l the length of the arc under the slice (the usual b = l cos α, exact for the base's
length where the circle turns steep). α is signed so that the slices that drive the mass
down the slope have α > 0, whichever way the slope faces. F is the factor by which c and
tan φ must be divided for the mass to be at limiting equilibrium: the same factor a
strength-reduction finite-element analysis reports.

Edge cases, each handled one documented way:

- A circle that does not cut the ground (no sliding mass), that leaves the ground through the
  ends of the surface polyline, whose mass would hang over its vertical tangent (centre below
  the surface where the circle leaves it), or that reaches below ``base`` (a firm stratum)
  has no factor of safety: :func:`factor_of_safety` raises a
  :class:`~granular_material.errors.ParameterError` naming ``circle``, and the search skips it.
- A mass nothing drives (Σ (W + Q) sin α ≤ 0) has F = inf.
- m_α ≤ 0.2: near the toe of a steep exit, where α < 0 and tan φ / F is large, m_α tends to 0
  and the slice's resistance (c b + W tan φ)/m_α grows without bound, an artefact of the
  method's assumed interslice forces (Whitman & Bailey 1967 advise distrusting a circle with
  m_α < 0.2); where the circle enters the ground steeply (α near 90°, small φ) m_α tends to
  cos α. The usual guard is applied: m_α is held at ``m_alpha_min`` (0.2 by default), which
  caps such a slice's resistance (conservative); :class:`BishopResult` counts the slices held.
- Tension cracks are ignored (the slip surface is the circle up to the ground surface), as is
  any tension at a slice's base (a negative normal force is used as it comes).

Validated (tests/test_limit_equilibrium.py) against published factors of safety:
Griffiths & Lane (1999, Géotechnique 49(3) 387–403) Example 1, a 2:1 slope with φ' = 20°,
c'/(γH) = 0.05, F = 1.380 from Bishop & Morgenstern's charts (here 1.369); code_aster's
validation slope SSNP006 (4.5 m at 1:2, c = 5 kPa, φ = 20°, γ = 16 kN/m³), F = 1.534 by
Bishop's method (here 1.542); Griffiths & Lane's clay slope on a foundation as code_aster's
SSNP507 reports it, F = 2.032 on circles for a stronger foundation (here 2.023) and 1.448 for
one soil (here 1.471, the exact circle of that geometry); and the closed form of a quarter
circle through a vertical cut in clay (φ = 0).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from granular_material.errors import ParameterError

__all__ = ["BishopResult", "CriticalCircle", "Ground", "Layer", "Surcharge", "critical_circle",
           "factor_of_safety", "gravity_increase_factor"]

#: the usual floor of m_α (Whitman & Bailey 1967)
M_ALPHA_MIN = 0.2
#: a circle the search skips: this factor of safety stands in for it (Nelder–Mead needs a
#: finite value)
_INVALID = 1e6
#: grid circles of distinct centres the search refines
_STARTS = 3
#: the best circles of the first grid every later search of the gravity factor starts from
_KEPT = 48
#: full searches that confirm the gravity factor's bracket
_CHECKS = 3


def _finite(name: str, value: float) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ParameterError(name, f"must be a number, got {value!r}") from None
    if not math.isfinite(value):
        raise ParameterError(name, f"must be finite, got {value!r}")
    return value


@dataclass(frozen=True)
class Layer:
    """A horizontal layer: the ground between ``bottom`` and the next layer up (or the
    surface).

    Attributes:
        bottom: y of the layer's base [m]; -inf for the lowest layer reaching down without
            end.
        cohesion: c [Pa], >= 0.
        friction_angle: φ [°], in [0, 90).
        unit_weight: γ [N/m³], >= 0.
    """

    bottom: float
    cohesion: float
    friction_angle: float
    unit_weight: float

    def __post_init__(self) -> None:
        bottom = float(self.bottom)
        if math.isnan(bottom) or bottom == math.inf:
            raise ParameterError("bottom", f"must be a level [m] or -inf, got {self.bottom!r}")
        object.__setattr__(self, "bottom", bottom)
        for name in ("cohesion", "friction_angle", "unit_weight"):
            object.__setattr__(self, name, _finite(name, getattr(self, name)))
        if self.cohesion < 0:
            raise ParameterError("cohesion", f"must be >= 0 Pa, got {self.cohesion!r}")
        if not 0 <= self.friction_angle < 90:
            raise ParameterError("friction_angle", "must lie in [0, 90) degrees, got "
                                                   f"{self.friction_angle!r}")
        if self.unit_weight < 0:
            raise ParameterError("unit_weight", f"must be >= 0 N/m³, got {self.unit_weight!r}")


@dataclass(frozen=True)
class Surcharge:
    """A vertical pressure ``pressure`` [Pa] on the ground between x = ``start`` and ``end``
    [m] (per horizontal metre; a load on a sloping part acts vertically)."""

    start: float
    end: float
    pressure: float

    def __post_init__(self) -> None:
        for name in ("start", "end", "pressure"):
            object.__setattr__(self, name, _finite(name, getattr(self, name)))
        if not self.end > self.start:
            raise ParameterError("end", f"must lie right of start ({self.start} m), got "
                                        f"{self.end}")
        if self.pressure < 0:
            raise ParameterError("pressure", f"must be >= 0 Pa, got {self.pressure!r}")


@dataclass(frozen=True)
class Ground:
    """The ground of a slope.

    Attributes:
        surface: the ground surface as points (x, y) [m], x strictly increasing; slip circles
            must leave the ground within its x-range.
        layers: horizontal layers from the top down, each ``bottom`` below the one above;
            the lowest reaches down to the last ``bottom`` (circles reaching below it, or
            below ``base``, are not admitted).
        surcharges: vertical pressure strips on the surface.
        base: y of a firm base [m] no circle may reach below; None: the lowest layer's
            bottom.
    """

    surface: tuple[tuple[float, float], ...]
    layers: tuple[Layer, ...]
    surcharges: tuple[Surcharge, ...] = ()
    base: float | None = None

    def __post_init__(self) -> None:
        try:
            points = np.asarray(self.surface, dtype=float)
        except (TypeError, ValueError):
            raise ParameterError("surface", "must be points (x, y) [m]") from None
        if points.ndim != 2 or points.shape[1] != 2 or points.shape[0] < 2:
            raise ParameterError("surface", f"must be at least two points (x, y), got shape "
                                            f"{points.shape}")
        if not np.isfinite(points).all():
            raise ParameterError("surface", "must be finite coordinates [m]")
        if not np.all(np.diff(points[:, 0]) > 0):
            raise ParameterError("surface", "must have x strictly increasing (a ground "
                                            "surface y(x); no overhangs)")
        object.__setattr__(self, "surface", tuple(map(tuple, points.tolist())))
        layers = tuple(self.layers)
        if not layers or not all(isinstance(layer, Layer) for layer in layers):
            raise ParameterError("layers", "must be at least one Layer, from the top down")
        bottoms = [layer.bottom for layer in layers]
        if any(b2 >= b1 for b1, b2 in itertools.pairwise(bottoms)):
            raise ParameterError("layers", f"must run from the top down, each bottom below "
                                           f"the one above, got bottoms {bottoms}")
        object.__setattr__(self, "layers", layers)
        surcharges = tuple(self.surcharges)
        if not all(isinstance(s, Surcharge) for s in surcharges):
            raise ParameterError("surcharges", "must be Surcharge strips")
        object.__setattr__(self, "surcharges", surcharges)
        if self.base is not None:
            object.__setattr__(self, "base", _finite("base", self.base))
        if not points[:, 1].min() > self.floor:
            raise ParameterError("base" if self.base is not None else "layers",
                                 f"the floor (y = {self.floor:g} m) must lie below the whole "
                                 f"surface (down to y = {points[:, 1].min():g} m)")

    @property
    def floor(self) -> float:
        """The lowest level [m] a circle may reach: ``base``, else the lowest layer's bottom
        (-inf where it has none)."""
        return max(self.base if self.base is not None else -math.inf, self.layers[-1].bottom)


@dataclass(frozen=True)
class BishopResult:
    """The factor of safety of one circle.

    Attributes:
        factor: F [-] (inf where nothing drives the mass).
        centre: (xc, yc) [m]; radius: R [m].
        entry, exit: x [m] where the circle leaves the ground, left and right.
        iterations: fixed-point iterations on F.
        slices: slices of the sliding mass (columns of zero height left out).
        held: slices whose m_α was held at the floor ``m_alpha_min``.
        weight: the sliding mass's weight [N/m] (γ times the gravity factor).
    """

    factor: float
    centre: tuple[float, float]
    radius: float
    entry: float
    exit: float
    iterations: int
    slices: int
    held: int
    weight: float


@dataclass(frozen=True)
class CriticalCircle:
    """The critical circle a search found: its :class:`BishopResult` and the circles tried
    (``evaluated``: on the grid and in the refinement)."""

    result: BishopResult
    evaluated: int

    @property
    def factor(self) -> float:
        """The least factor of safety found [-]."""
        return self.result.factor


def _slices(ground: Ground, xc: np.ndarray, yc: np.ndarray, r: np.ndarray, n: int,
            gravity: float) -> dict[str, np.ndarray]:
    """Every circle's slices (arrays (circles, n)) and its validity (circles,)."""
    surface = np.asarray(ground.surface)
    sx, sy = surface[:, 0], surface[:, 1]
    # the circle against each segment of the surface: P = P0 + t D, |P - C|² = R²
    p0x, p0y = sx[:-1][None, :] - xc[:, None], sy[:-1][None, :] - yc[:, None]
    dx, dy = np.diff(sx)[None, :], np.diff(sy)[None, :]
    a = dx * dx + dy * dy
    b = 2.0 * (dx * p0x + dy * p0y)
    c = p0x * p0x + p0y * p0y - (r * r)[:, None]
    disc = b * b - 4.0 * a * c
    root = np.sqrt(np.where(disc >= 0, disc, np.nan))
    xs = []
    for t in ((-b - root) / (2 * a), (-b + root) / (2 * a)):
        # on the segment, on the lower arc (its ends at the centre's level included)
        on = (t >= 0) & (t <= 1) & (p0y + t * dy <= 1e-9 * r[:, None])
        xs.append(np.where(on, sx[:-1][None, :] + t * dx, np.nan))
    xs = np.concatenate(xs, axis=1)
    found = np.isfinite(xs)
    count = np.sum(found, axis=1)
    entry = np.min(np.where(found, xs, np.inf), axis=1)
    exit_ = np.max(np.where(found, xs, -np.inf), axis=1)
    valid = (count >= 2) & (exit_ > entry)
    # the ground must not stand above the arc at the ends of the arc's span (the mass would
    # leave through the model's side or hang over the circle's vertical tangent)
    for end in (np.maximum(xc - r, sx[0]), np.minimum(xc + r, sx[-1])):
        arc = yc - np.sqrt(np.maximum(r * r - (end - xc) ** 2, 0.0))
        valid &= np.interp(end, sx, sy) - arc <= 1e-9 * (1.0 + r)
    entry, exit_ = np.where(valid, entry, 0.0), np.where(valid, exit_, 1.0)
    lowest = np.where((xc > entry) & (xc < exit_), yc - r,
                      np.minimum(*(yc - np.sqrt(np.maximum(r * r - (e - xc) ** 2, 0.0))
                                   for e in (entry, exit_))))
    valid &= lowest >= ground.floor - 1e-9 * (1.0 + r)
    width = (exit_ - entry) / n
    left = entry[:, None] + width[:, None] * np.arange(n)[None, :]
    xm = left + 0.5 * width[:, None]
    top = np.interp(xm, sx, sy)
    base = yc[:, None] - np.sqrt(np.maximum(r[:, None] ** 2 - (xm - xc[:, None]) ** 2, 0.0))
    active = top > base
    # the column's weight per width, layer by layer, and the strength at the base
    column = np.zeros_like(xm)
    cohesion, tan_phi = np.zeros_like(xm), np.zeros_like(xm)
    upper = np.inf
    for layer in ground.layers:
        column += layer.unit_weight * np.clip(np.minimum(top, upper)
                                              - np.maximum(base, layer.bottom), 0.0, None)
        here = (base < upper) & (base >= layer.bottom)
        cohesion = np.where(here, layer.cohesion, cohesion)
        tan_phi = np.where(here, math.tan(math.radians(layer.friction_angle)), tan_phi)
        upper = layer.bottom
    weight = np.where(active, gravity * column * width[:, None], 0.0)
    load = np.zeros_like(xm)
    for strip in ground.surcharges:
        overlap = np.clip(np.minimum(left + width[:, None], strip.end)
                          - np.maximum(left, strip.start), 0.0, None)
        load += strip.pressure * overlap
    load = np.where(active, load, 0.0)
    # the base's length: the arc over the slice (b / cos α at the midpoint errs where the
    # circle turns steep)
    ends = [np.arcsin(np.clip((x - xc[:, None]) / r[:, None], -1.0, 1.0))
            for x in (left, left + width[:, None])]
    length = r[:, None] * (ends[1] - ends[0])
    sin_a = (xm - xc[:, None]) / r[:, None]
    cos_a = np.sqrt(np.maximum(1.0 - sin_a * sin_a, 0.0))
    # α > 0 on the slices that drive: the mass moves the way its weight turns it
    turn = np.sign(np.sum((weight + load) * sin_a, axis=1))
    sin_a = sin_a * np.where(turn == 0, 1.0, turn)[:, None]
    return {"valid": valid, "entry": entry, "exit": exit_, "width": width, "active": active,
            "weight": weight, "load": load, "cohesion": cohesion, "tan_phi": tan_phi,
            "sin": sin_a, "cos": cos_a, "length": length}


def _bishop(s: dict[str, np.ndarray], m_alpha_min: float, tol: float = 1e-10,
            max_iterations: int = 200) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F of every circle of the slices ``s`` (inf where nothing drives, nan where invalid),
    with its iterations and the slices whose m_α was held."""
    active = s["active"]
    push = s["weight"] + s["load"]
    # c b with b = l cos α, l the arc's length over the slice
    resist = np.where(active, s["cohesion"] * s["length"] * s["cos"] + push * s["tan_phi"],
                      0.0)
    drive = np.sum(push * s["sin"], axis=1)
    driven = s["valid"] & (drive > 0)
    safe_drive = np.where(driven, drive, 1.0)
    factor = np.ones_like(drive)
    iterations = np.zeros(drive.shape, dtype=int)
    held = np.zeros(drive.shape, dtype=int)
    going = driven.copy()
    for k in range(1, max_iterations + 1):
        m = s["cos"] + s["sin"] * s["tan_phi"] / factor[:, None]
        low = active & (m < m_alpha_min)
        new = np.sum(resist / np.maximum(m, m_alpha_min), axis=1) / safe_drive
        change = np.abs(new - factor)
        factor = np.where(going, new, factor)
        held = np.where(going, np.sum(low, axis=1), held)
        iterations = np.where(going, k, iterations)
        going &= change > tol * np.maximum(np.abs(new), 1.0)
        if not going.any():
            break
    factor = np.where(driven, factor, np.where(s["valid"], np.inf, np.nan))
    return factor, iterations, held


def _check_options(slices: int, m_alpha_min: float, gravity: float) -> None:
    if isinstance(slices, bool) or not isinstance(slices, int) or slices < 4:
        raise ParameterError("slices", f"must be an integer >= 4, got {slices!r}")
    if not 0 < m_alpha_min < 1:
        raise ParameterError("m_alpha_min", f"must lie in (0, 1), got {m_alpha_min!r}")
    if not (math.isfinite(gravity) and gravity > 0):
        raise ParameterError("gravity", f"must be a factor > 0, got {gravity!r}")


def _evaluate(ground: Ground, circles: np.ndarray, slices: int, m_alpha_min: float,
              gravity: float) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray,
                                       np.ndarray]:
    circles = np.atleast_2d(np.asarray(circles, dtype=float))
    s = _slices(ground, circles[:, 0], circles[:, 1], circles[:, 2], slices, gravity)
    factor, iterations, held = _bishop(s, m_alpha_min)
    return factor, s, iterations, held


def factor_of_safety(ground: Ground, centre: tuple[float, float], radius: float,
                     slices: int = 100, m_alpha_min: float = M_ALPHA_MIN,
                     gravity: float = 1.0) -> BishopResult:
    """Bishop's simplified factor of safety of one circle (centre (xc, yc) [m], ``radius``
    [m]) on ``ground``, with ``slices`` slices of equal width, m_α held at ``m_alpha_min``
    at least, and every unit weight multiplied by ``gravity``.

    Raises a ParameterError naming ``circle`` for a circle that does not cut the ground, leaves
    it through the ends of its surface, hangs over its vertical tangent or reaches below the
    floor (see the module docstring)."""
    _check_options(slices, m_alpha_min, gravity)
    xc, yc = (_finite("centre", v) for v in centre)
    radius = _finite("radius", radius)
    if radius <= 0:
        raise ParameterError("radius", f"must be > 0 m, got {radius!r}")
    factor, s, iterations, held = _evaluate(ground, np.array([[xc, yc, radius]]), slices,
                                            m_alpha_min, gravity)
    if not s["valid"][0]:
        raise ParameterError("circle", f"centre ({xc:g}, {yc:g}) m, radius {radius:g} m "
                                       "cuts no admissible sliding mass from the ground (it "
                                       "misses the ground, leaves it through the ends of its "
                                       "surface, hangs over the circle's side or reaches below "
                                       "the floor)")
    return BishopResult(factor=float(factor[0]), centre=(xc, yc), radius=radius,
                        entry=float(s["entry"][0]), exit=float(s["exit"][0]),
                        iterations=int(iterations[0]), slices=int(s["active"][0].sum()),
                        held=int(held[0]), weight=float(s["weight"][0].sum()))


def _default_grid(ground: Ground, n: int) -> np.ndarray:
    """Circles (xc, yc, R) over centres above the ground and tangent levels from the floor
    (or one slope height below the lowest surface point) up to the highest surface point."""
    surface = np.asarray(ground.surface)
    x0, x1 = surface[0, 0], surface[-1, 0]
    low, high = surface[:, 1].min(), surface[:, 1].max()
    height = max(high - low, 1e-3 * (x1 - x0))
    deepest = max(ground.floor, low - 2.0 * height)
    xs = np.linspace(x0, x1, n)
    ys = np.linspace(high + 0.05 * height, high + 2.5 * height, n)
    tangents = np.linspace(deepest, high, n + 1)[:-1]
    xc, yc, yt = np.meshgrid(xs, ys, tangents, indexing="ij")
    circles = np.column_stack([xc.ravel(), yc.ravel(), (yc - yt).ravel()])
    return circles[circles[:, 2] > 0]


def _grid_circles(ground: Ground, grid: np.ndarray | int) -> np.ndarray:
    """The circles (k, 3) of ``grid``: an array of (xc, yc, R) [m], or n for the default
    grid; a ParameterError naming ``grid`` for anything else."""
    if isinstance(grid, int) and not isinstance(grid, bool):
        if grid < 2:
            raise ParameterError("grid", f"must be >= 2 points a direction, got {grid}")
        return _default_grid(ground, grid)
    try:
        circles = np.asarray(grid, dtype=float)
    except (TypeError, ValueError):
        circles = np.empty(0)
    if circles.ndim != 2 or circles.shape[1] != 3 or not np.isfinite(circles).all():
        raise ParameterError("grid", "must be circles (xc, yc, R) [m], an array (k, 3), or "
                                     "a number of grid points a direction")
    return circles


def critical_circle(ground: Ground, grid: np.ndarray | int = 16, slices: int = 100,
                    m_alpha_min: float = M_ALPHA_MIN, gravity: float = 1.0,
                    refine: bool = True) -> CriticalCircle:
    """The circle of least Bishop factor of safety on ``ground``.

    ``grid``: the circles to try first, an array (k, 3) of (xc, yc, R) [m], or n for the
    default grid of n × n centres (over the surface's x-range, from just above its highest
    point to 2.5 slope heights above) times n tangent levels (from the floor, or two slope
    heights below the lowest surface point, up to the highest). The best of them, from up to
    three distinct centres, are then refined by Nelder–Mead over (xc, yc, yc − R)
    (``refine``). ``slices``, ``m_alpha_min``,
    ``gravity``: as :func:`factor_of_safety`. A ParameterError naming ``grid`` if no circle
    of the grid is admissible."""
    _check_options(slices, m_alpha_min, gravity)
    return _search(ground, _grid_circles(ground, grid), slices, m_alpha_min, gravity,
                   _STARTS if refine else 0, 2)


def _search(ground: Ground, circles: np.ndarray, slices: int, m_alpha_min: float,
            gravity: float, starts: int, restarts: int) -> CriticalCircle:
    """The least factor of safety of ``circles``, refined by Nelder–Mead from the best
    ``starts`` of distinct centres, each run ``restarts`` times."""
    factor, _, _, _ = _evaluate(ground, circles, slices, m_alpha_min, gravity)
    factor = np.where(np.isfinite(factor), factor, np.inf)
    evaluated = len(circles)
    if not np.isfinite(factor).any():
        raise ParameterError("grid", "holds no circle that cuts an admissible sliding mass "
                                     "that anything drives; give circles nearer the slope")
    order = np.argsort(factor)
    best = circles[order[0]]
    least = float(factor[order[0]])

    # Nelder–Mead over (xc, yc, y_t), y_t = yc − R the circle's lowest level (so that a
    # circle held tangent to a layer boundary or the floor slides along it)
    def objective(v: np.ndarray) -> float:
        f, _, _, _ = _evaluate(ground, np.array([[v[0], v[1], v[1] - v[2]]]), slices,
                               m_alpha_min, gravity)
        return float(f[0]) if np.isfinite(f[0]) else _INVALID

    chosen: list[np.ndarray] = []
    spacing = 0.05 * max(float(np.ptp(circles[:, 0])), float(np.ptp(circles[:, 1])), 1e-3)
    for k in order[:200]:
        if not np.isfinite(factor[k]) or len(chosen) == starts:
            break
        if all(np.hypot(*(circles[k, :2] - c[:2])) > spacing for c in chosen):
            chosen.append(circles[k])
    for start in chosen:
        point = np.array([start[0], start[1], start[1] - start[2]])
        scale = max(start[2], 1e-3)
        for _ in range(restarts):  # a restart: Nelder–Mead's simplex may collapse
            simplex = point + np.vstack([np.zeros(3), 0.05 * scale * np.eye(3)])
            found = minimize(objective, point, method="Nelder-Mead",
                             options={"initial_simplex": simplex, "xatol": 1e-3 * scale,
                                      "fatol": 1e-6, "maxiter": 1500})
            evaluated += found.nfev
            point = found.x
        if found.fun < least:
            least = float(found.fun)
            best = np.array([point[0], point[1], point[1] - point[2]])
    xc, yc, r = (float(v) for v in best)
    return CriticalCircle(factor_of_safety(ground, (xc, yc), r, slices, m_alpha_min, gravity),
                          evaluated)


def _bracketed(least, low: float, high: float, standing: CriticalCircle,
               failing: CriticalCircle, tol: float) -> tuple[float, float, CriticalCircle]:
    """Narrow [low, high] (F(low) > 1 >= F(high)) around F(g) = 1 to ``tol`` relative:
    bisection sped up by the Illinois false position (each step keeps the root bracketed);
    returns the bracket and the critical circle at its failing end."""
    f_low, f_high = standing.factor - 1.0, failing.factor - 1.0
    side = 0
    while high - low > tol * high:
        g = high - f_high * (high - low) / (f_high - f_low)
        # keep clear of the ends: a plain bisection step where false position stalls
        if not low + 0.05 * (high - low) < g < high - 0.05 * (high - low):
            g = 0.5 * (low + high)
        at = least(g)
        if at.factor > 1:
            low, f_low = g, at.factor - 1.0
            if side == 1:
                f_high *= 0.5
            side = 1
        else:
            high, f_high, failing = g, at.factor - 1.0, at
            if side == -1:
                f_low *= 0.5
            side = -1
        if abs(at.factor - 1.0) < 0.1 * tol:
            return g, g, at
    return low, high, failing


def gravity_increase_factor(ground: Ground, grid: np.ndarray | int = 16, slices: int = 100,
                            m_alpha_min: float = M_ALPHA_MIN, tol: float = 1e-3,
                            upper: float = 100.0) -> tuple[float, CriticalCircle]:
    """The factor g by which every unit weight must be multiplied for the critical circle's
    factor of safety to be 1 (surcharges unchanged), by bisection on g (sped up by false
position, the root always bracketed) to ``tol`` relative; with the
    critical circle at that g. The first search (at g = 1) tries ``grid`` (as
    :func:`critical_circle`, with ``slices`` and ``m_alpha_min``); each bisection step then
    searches the critical circle at its g afresh, refining from the best circles of that
    grid and the last step's critical circle.

    A ParameterError naming ``gravity`` if the slope stands at every g up to ``upper`` (a
    cohesionless slope whose F does not depend on its weight) or fails already at g → 0."""
    if not (math.isfinite(upper) and upper > 1):
        raise ParameterError("upper", f"must be a factor > 1, got {upper!r}")
    if not 0 < tol < 0.1:
        raise ParameterError("tol", f"must be a relative tolerance in (0, 0.1), got {tol!r}")

    first = critical_circle(ground, grid, slices, m_alpha_min)
    # the later searches start from the best circles of the first grid and the last answer
    circles = _grid_circles(ground, grid)
    factor, _, _, _ = _evaluate(ground, circles, slices, m_alpha_min, 1.0)
    ranked = circles[np.argsort(np.where(np.isfinite(factor), factor, np.inf))[:_KEPT]]
    last = [first.result]

    def least(g: float) -> CriticalCircle:
        if g == 1.0:
            return first
        previous = np.array([[*last[0].centre, last[0].radius]])
        found = _search(ground, np.vstack([previous, ranked]), slices, m_alpha_min, g,
                        starts=2, restarts=1)
        last[0] = found.result
        return found

    low, high = 1.0, 1.0
    at = first
    if at.factor > 1:
        while at.factor > 1:
            low, high, standing = high, min(2.0 * high, upper), at
            at = least(high)
            if at.factor > 1 and high >= upper:
                raise ParameterError("gravity", f"the slope stands (F = {at.factor:.3f}) with "
                                                f"its weight multiplied by {upper:g}: no "
                                                "gravity-increase factor below it")
        failing = at
    else:
        while at.factor <= 1:
            high, low, failing = low, low / 2.0, at
            if low < 1e-6:
                raise ParameterError("gravity", "the slope fails under a vanishing weight "
                                                "(its surcharges alone bring F below 1)")
            at = least(low)
        standing = at
    for _ in range(_CHECKS):
        low, high, failing = _bracketed(least, low, high, standing, failing, tol)
        # the steps' searches start from few circles: a full search at the highest g found
        # standing confirms it stands, or the bracket moves down and is narrowed again
        standing = critical_circle(ground, grid, slices, m_alpha_min, gravity=low)
        if standing.factor > 1:
            break
        high, failing, last[0] = low, standing, standing.result
        while standing.factor <= 1 and low > 1e-6:
            low *= 1.0 - 4.0 * tol
            standing = least(low)
    return 0.5 * (low + high), failing
