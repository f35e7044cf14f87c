"""Packing generation: random disc gases in periodic cells, consolidated to a pressure."""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from granular_material.dem.rve.data import RVEData
from granular_material.dem.rve.format import RVEMeta
from granular_material.errors import ParameterError
from granular_material.lazy_names import lazy_names
from granular_material.reference_values import (
    DEFAULT_DISCS,
    DEFAULT_PRESSURE,
    DEFAULT_RADIUS_RANGE,
)

if TYPE_CHECKING:
    from granular_material.dem import DEMBatch

# The DEM model and its batch (warp) are imported where a packing is checked against them or
# made: a run specification reads this module's defaults without loading them (issue 62).
#: names of this module loaded on first use (:func:`__getattr__`), by the module they are in
_LATE = {"DEMBatch": "granular_material.dem", "consolidate": "granular_material.procedures.servo"}


# the names of _LATE, imported on first use and kept as this module's
__getattr__ = lazy_names(__name__, _LATE, globals())[0]

__all__ = ["DEFAULT_DISCS", "DEFAULT_PRESSURE", "DEFAULT_RADIUS_RANGE", "MAX_OVERLAP",
           "MIN_OVERLAP", "PACKING_NAMES", "VOID_RATIO_TOLERANCE", "PackingParameters",
           "check_packing", "check_pressure_for_rves", "check_radius_range", "given_as",
           "max_pressure", "min_discs",
           "min_pressure", "prepare_packing", "random_gas", "smallest_normal_stiffness",
           "typical_normal_stiffness"]


#: solid fraction of the densest consolidated packing :func:`min_discs` allows for (e = 0.11;
#: random frictionless disc packings consolidate to 0.84–0.86, pressure adds a little)
DENSE_SOLID_FRACTION = 0.9
#: largest estimated contact overlap δ/r = 2·p·t/kn a packing is consolidated to
#: (:func:`max_pressure`): the void ratio falls to zero, and the RVE is invalid, near 0.2
MAX_OVERLAP = 0.1
#: smallest estimated overlap δ/r = 2·p·t/kn (of a disc of the mean radius) a packing is
#: consolidated to (:func:`min_pressure`). Closer to the jamming point the frictionless servo
#: does not settle the packing: measured here (constant law, 3 seeds each), 24 and 64 discs
#: failed at 3e-6 for one seed in three, 400 discs at 1e-5 for all three (each after the
#: 400 000 steps of ``consolidate``); 400 discs passed at 3e-5 (3 of 3) and 5e-5 (8 of 8,
#: 10–31 s), 1000 discs at 5e-5 (2 of 2, 103–154 s)
MIN_OVERLAP = 5.0e-5
#: how far above ``target_void_ratio`` a prepared packing may end and still be taken (with a
#: warning by ``prepare``): the compaction stops within 2e-3 of it (checked every 10 steps)
VOID_RATIO_TOLERANCE = 0.005


@dataclass(frozen=True)
class PackingParameters:
    """The material of prepared RVEs and how their discs are drawn and packed (everything of
    :func:`prepare_packing` but the discs, seed and pressure).

    Attributes:
        meta: contact law, friction, damping, density and thickness the RVEs are made of
            (its ``seed`` is set to the packing's own).
        radius_range: (r_min, r_max) [m] of the uniform disc radii, 0 < r_min <= r_max.
        target_void_ratio: 2D void ratio e0 the frictionless gas is first compacted to
            (Wu et al.: 0.18), > 0; None: compacted straight to the pressure.
    """

    meta: RVEMeta = field(default_factory=RVEMeta)
    radius_range: tuple[float, float] = DEFAULT_RADIUS_RANGE
    target_void_ratio: float | None = None

    def __post_init__(self) -> None:
        self.meta.validate()
        check_radius_range(self.radius_range)
        e0 = self.target_void_ratio
        if e0 is not None and not (math.isfinite(e0) and e0 > 0):
            raise ValueError(f"target_void_ratio must be a positive number or None, got {e0!r}")


def min_discs(radius_range: tuple[float, float] = DEFAULT_RADIUS_RANGE) -> int:
    """Fewest discs per RVE whose consolidated cell stays wider than twice the contact
    cut-off ``2·r_max + skin`` [m] (the engine finds each pair in its nearest periodic image
    only, and stops a cell whose half height falls below the cut-off): radii uniform in
    ``radius_range`` [m], solid fraction :data:`DENSE_SOLID_FRACTION`. 12 for 3–7 mm."""
    from granular_material.dem.model import SKIN_FRACTION

    r_min, r_max = radius_range
    mean_square = (r_min**2 + r_min * r_max + r_max**2) / 3.0
    cutoff = 2.0 * r_max + 2.0 * SKIN_FRACTION * 0.5 * (r_min + r_max)
    return math.floor(DENSE_SOLID_FRACTION * (2.0 * cutoff) ** 2 / (math.pi * mean_square)) + 1


def smallest_normal_stiffness(meta: RVEMeta, radius_range: tuple[float, float]) -> float:
    """The normal stiffness [N/m] of the softest contact: kn (constant law), or E·r_min
    (FrictMat, kn = 2E·r1·r2/(r1 + r2), two r_min discs)."""
    stiffness = meta.stiffness
    if stiffness.get("law") == "frictmat":
        return float(stiffness["young"]) * float(radius_range[0])
    return float(stiffness["kn"])


def typical_normal_stiffness(meta: RVEMeta, radius_range: tuple[float, float]) -> float:
    """The normal stiffness [N/m] of two discs of the mean radius r̄: kn (constant law), or
    E·r̄ (FrictMat)."""
    stiffness = meta.stiffness
    if stiffness.get("law") == "frictmat":
        return float(stiffness["young"]) * 0.5 * (radius_range[0] + radius_range[1])
    return float(stiffness["kn"])


def min_pressure(meta: RVEMeta, radius_range: tuple[float, float] = DEFAULT_RADIUS_RANGE,
                 ) -> float:
    """Lowest consolidation pressure [Pa] of the contact law of ``meta``: the estimated
    overlap 2·p·t/kn of a mean disc at least :data:`MIN_OVERLAP` of its radius (750 Pa for
    kn = 3e6 N/m, t = 0.1 m; 2.5 MPa for kn = 1e10 N/m)."""
    return MIN_OVERLAP * typical_normal_stiffness(meta, radius_range) / (2.0 * meta.thickness)


def max_pressure(meta: RVEMeta, radius_range: tuple[float, float] = DEFAULT_RADIUS_RANGE,
                 ) -> float:
    """Highest consolidation pressure [Pa] of the linear contact law of ``meta``: a disc of
    radius r carries about F = 2·p·r·t, so its contacts overlap δ/r ≈ 2·p·t/kn; this keeps
    that at most :data:`MAX_OVERLAP` (1.5 MPa for kn = 3e6 N/m, t = 0.1 m)."""
    return MAX_OVERLAP * smallest_normal_stiffness(meta, radius_range) / (2.0 * meta.thickness)


def check_pressure_for_rves(data: Any, pressure: float, field: str) -> None:
    """``pressure`` [Pa] within what the linear contact law of the RVEs ``data`` (an
    ``RVEData``) holds: at most :func:`max_pressure` over their radii (a contact overlap of
    at most :data:`MAX_OVERLAP` of the smallest radius); a ParameterError on ``field``
    otherwise, for a caller to raise before any DEM step (a pressure beyond it inverts
    cells after the work)."""
    radius = np.asarray(data.radius, dtype=float)
    highest = max_pressure(data.meta, (float(radius.min()), float(radius.max())))
    if pressure > highest:
        raise ParameterError(field, f"{pressure:.4g} Pa is beyond what the RVEs' contact law "
                                    f"holds: at most {highest:.4g} Pa (a contact overlap of "
                                    f"{MAX_OVERLAP:.0%} of the smallest radius)")


#: how the checks of a packing name its values in their messages, by default (a library
#: caller's keywords); the command line names its options instead (:func:`check_packing`)
PACKING_NAMES = {"radius_range": ("r_min", "r_max"), "n_disc": "n_disc",
                 "pressure": "pressure", "stiffness": "kn"}


def given_as(name: str, value: float) -> str:
    """A value as a message names it: ``--option 5`` for a command-line option, else
    ``name = 5`` (a keyword of a library call); integers whole, floats as ``:g``."""
    shown = f"{value:g}" if isinstance(value, float) else str(value)
    return f"{name} {shown}" if name.startswith("-") else f"{name} = {shown}"


def check_radius_range(radius_range: tuple[float, float],
                       names: tuple[str, str] = PACKING_NAMES["radius_range"]) -> None:
    """``ValueError`` unless the radii [m] satisfy 0 < r_min <= r_max, finite; ``names``:
    what sets r_min and r_max, for the message."""
    r_min, r_max = radius_range
    if 0 < r_min <= r_max and math.isfinite(r_max):
        return
    low, high = names
    if math.isfinite(r_max) and 0 < r_max < r_min:
        raise ValueError(f"{given_as(low, r_min)} exceeds {given_as(high, r_max)} [m]")
    raise ValueError(f"the radii must satisfy 0 < {low} <= {high} [m], finite, got "
                     f"{r_min!r}, {r_max!r}")


def check_packing(n_disc: int, pressure: float, meta: RVEMeta,
                  radius_range: tuple[float, float] = DEFAULT_RADIUS_RANGE,
                  dtype: str = "float64", names: dict[str, Any] | None = None) -> None:
    """``ValueError`` before any work when ``n_disc`` discs of ``meta`` with radii in
    ``radius_range`` cannot be consolidated to ``pressure`` [Pa]: the radii, too few discs
    (:func:`min_discs`), a pressure outside [:func:`min_pressure`, :func:`max_pressure`],
    overlaps float32 cannot resolve. The messages name the values as ``names`` does
    (:data:`PACKING_NAMES` where it gives none)."""
    names = {**PACKING_NAMES, **(names or {})}
    check_radius_range(radius_range, names["radius_range"])
    r_min, r_max = radius_range
    if not (math.isfinite(pressure) and pressure > 0):
        raise ValueError(f"{names['pressure']} must be a positive number [Pa], got "
                         f"{pressure!r}")
    fewest = min_discs(radius_range)
    if n_disc < fewest:
        raise ValueError(
            f"{given_as(names['n_disc'], n_disc)} is too few for radii {r_min:g}–{r_max:g} m: "
            f"the consolidated cell must stay wider than twice the contact cut-off "
            f"(2·r_max + skin; the engine sees one periodic image of each pair), which takes "
            f"at least {fewest} discs"
        )
    pressure_given = given_as(names["pressure"], pressure)
    highest = max_pressure(meta, radius_range)
    if pressure > highest:
        overlap = 2 * pressure * meta.thickness / smallest_normal_stiffness(meta, radius_range)
        raise ValueError(
            f"{pressure_given} Pa would press the discs about {100 * overlap:.3g} % of their "
            f"radius into each other (2·p·thickness/kn); the linear contact law holds to "
            f"{MAX_OVERLAP:.0%} (the void space is gone near 20%): at most {highest:.4g} Pa "
            f"with these stiffnesses (or a stiffer {names['stiffness']})"
        )
    lowest = min_pressure(meta, radius_range)
    kn = typical_normal_stiffness(meta, radius_range)
    if pressure < lowest:
        raise ValueError(
            f"{pressure_given} Pa is too low for these stiffnesses: the contacts would "
            f"overlap by about {2 * pressure * meta.thickness / kn:.2g} of their radius "
            f"(2·p·t/kn with kn = {kn:.4g} N/m), below {MIN_OVERLAP:g} of which the "
            f"consolidation servo does not settle a packing (24–400-disc ones stopped after "
            f"400 000 steps): at least {lowest:.4g} Pa (or a softer {names['stiffness']})"
        )
    if dtype == "float32":
        mean_square = (r_min**2 + r_min * r_max + r_max**2) / 3.0
        side = math.sqrt(n_disc * math.pi * mean_square / DENSE_SOLID_FRACTION)
        overlap = pressure * meta.thickness * (r_min + r_max) / kn
        share = 2.0**-24 * side / overlap
        from granular_material.dem.model import FLOAT32_MAX_RESOLUTION

        if share > FLOAT32_MAX_RESOLUTION:
            raise ValueError(
                f"dtype float32 cannot resolve contacts overlapping about {overlap:.3g} m "
                f"({pressure_given} Pa) in a cell about {side:.3g} m across "
                f"({given_as(names['n_disc'], n_disc)}): float32 positions are "
                f"{2.0**-24 * side:.3g} m apart, {share:.2%} of the overlap (at most "
                f"{FLOAT32_MAX_RESOLUTION:.1%}); use float64, a higher pressure or fewer discs"
            )


def _place_discs(radius: np.ndarray, side: float, rng: np.random.Generator) -> np.ndarray:
    """Random sequential addition of non-overlapping discs in a periodic square [m]."""
    placed = np.empty((0, 2))
    placed_r = np.empty(0)
    out = np.empty((radius.size, 2))
    order = np.argsort(-radius, kind="stable")
    for idx in order:
        r = radius[idx]
        for _ in range(100_000):
            x = rng.uniform(0.0, side, size=2)
            d = placed - x
            d -= side * np.round(d / side)
            if placed.size == 0 or (np.einsum("ij,ij->i", d, d) >= (placed_r + r) ** 2).all():
                break
        else:
            raise RuntimeError("could not place the discs: initial solid fraction too high")
        placed = np.vstack([placed, x])
        placed_r = np.append(placed_r, r)
        out[idx] = x
    return out


def random_gas(
    n_disc: int = DEFAULT_DISCS,
    n_rve: int = 1,
    seed: int = 1,
    radius_range: tuple[float, float] = DEFAULT_RADIUS_RANGE,
    solid_fraction: float = 0.4,
    meta: RVEMeta | None = None,
) -> RVEData:
    """B loose random packings of N non-overlapping discs in square periodic cells.

    RVE b draws from ``numpy.random.default_rng(seed + b)``: radii uniform in
    ``radius_range`` [m], positions by random sequential addition at ``solid_fraction``.
    """
    if n_disc < 2:
        raise ValueError(f"n_disc must be >= 2, got {n_disc}")
    if n_rve < 1:
        raise ValueError(f"n_rve must be >= 1, got {n_rve}")
    check_radius_range(radius_range)
    r_min, r_max = radius_range
    if not 0 < solid_fraction <= 0.5:
        raise ValueError(f"solid_fraction must lie in (0, 0.5], got {solid_fraction!r}")
    meta = meta or RVEMeta()
    radius = np.empty((n_rve, n_disc))
    position = np.empty((n_rve, n_disc, 2))
    cell = np.empty((n_rve, 2, 2))
    for b in range(n_rve):
        rng = np.random.default_rng(seed + b)
        radius[b] = rng.uniform(r_min, r_max, size=n_disc)
        side = math.sqrt(np.pi * np.sum(radius[b] ** 2) / solid_fraction)
        position[b] = _place_discs(radius[b], side, rng)
        cell[b] = side * np.eye(2)
    return RVEData(
        radius=radius, position=position, cell=cell,
        velocity=np.zeros((n_rve, n_disc, 2)), angular_velocity=np.zeros((n_rve, n_disc)),
        meta=replace(meta, seed=seed),
    )


def _check_drawn_radii(n_disc: int, n_rve: int, seed: int,
                       radius_range: tuple[float, float]) -> None:
    """``ValueError`` before any work when the radii RVE b draws (as :func:`random_gas`
    does) would not keep its consolidated cell wider than twice the contact cut-off:
    :func:`min_discs` holds for the mean of the radii, a draw of few discs can hold larger
    ones. Only near that limit (below four times it), where a draw can matter."""
    if n_disc >= 4 * min_discs(radius_range):
        return
    from granular_material.dem.model import SKIN_FRACTION

    r_min, r_max = radius_range
    for b in range(n_rve):
        radius = np.random.default_rng(seed + b).uniform(r_min, r_max, size=n_disc)
        side = math.sqrt(np.pi * float(np.sum(radius**2)) / DENSE_SOLID_FRACTION)
        cutoff = 2.0 * float(radius.max()) + 2.0 * SKIN_FRACTION * float(radius.mean())
        if side <= 2.0 * cutoff:
            raise ValueError(
                f"{n_disc} discs of radii {r_min:g}–{r_max:g} m are too few for seed "
                f"{seed + b} (RVE {b}): its discs (largest {radius.max():.4g} m) would "
                f"consolidate to a cell {side:.4g} m wide, not wider than twice the contact "
                f"cut-off ({2 * cutoff:.4g} m); take more discs or a narrower radius range"
            )


def prepare_packing(
    n_disc: int = DEFAULT_DISCS,
    n_rve: int = 1,
    seed: int = 1,
    pressure: float = DEFAULT_PRESSURE,
    meta: RVEMeta | None = None,
    target_void_ratio: float | None = None,
    radius_range: tuple[float, float] = DEFAULT_RADIUS_RANGE,
    device: str | None = None,
    dtype: str = "float64",
    shards: int | None = None,
    progress: bool = False,
) -> DEMBatch:
    """Prepare B RVEs: random gas, frictionless isotropic consolidation to ``pressure`` [Pa],
    then the friction of ``meta`` set and the packing re-equilibrated at that pressure.

    With ``target_void_ratio`` the frictionless gas is first compacted isotropically until it
    reaches that 2D void ratio (or p0), then friction is set and the packing consolidated
    (Wu et al. 2025: e0 = 0.18, then p0 = 100 kPa); the void ratio reached under p0 is a
    little below e0 (reported by :meth:`DEMBatch.homogenize`). A target below what
    frictionless consolidation reaches cannot be held (the caller compares the void ratio).

    ``ValueError`` before any work when ``n_disc`` is below :func:`min_discs`, ``pressure``
    outside [:func:`min_pressure`, :func:`max_pressure`], or, with ``dtype="float32"``, the
    consolidated cell would be too large for float32 to resolve the estimated overlaps
    (:data:`~granular_material.dem.model.FLOAT32_MAX_RESOLUTION`).
    """
    module = sys.modules[__name__]  # the batch and servo as this module holds them
    batch_class, consolidate = module.DEMBatch, module.consolidate
    meta = meta or RVEMeta()
    meta.validate()
    check_packing(n_disc, pressure, meta, radius_range, dtype)
    _check_drawn_radii(n_disc, n_rve, seed, radius_range)
    gas = random_gas(n_disc, n_rve, seed, radius_range, meta=replace(meta, friction_angle=0.0))
    batch = batch_class(gas, device=device, dtype=dtype, shards=shards)
    if target_void_ratio is not None:
        if not (math.isfinite(target_void_ratio) and target_void_ratio > 0):
            raise ValueError(
                f"target_void_ratio must be a positive number, got {target_void_ratio!r}"
            )
        # frictionless compaction toward p0, stopped where e reaches e0 (checked every 10
        # steps: at most 2e-3 in e past it), then friction on so that structure is kept
        consolidate(batch, pressure, stop_void_ratio=target_void_ratio, check_every=10,
                    max_strain=5.0e-5, progress=progress)
    else:
        consolidate(batch, pressure, progress=progress)
    batch.set_friction(meta.friction_angle)
    consolidate(batch, pressure, progress=progress)
    return batch
