"""Mohr–Coulomb parameters read off drained biaxial curves (pure, on a curve table): E and ν,
φ, ψ, φcs and the softening strain of every RVE's curve with their scatter
(:func:`read_parameters`, giving a :class:`Calibration`); the conventions (logarithmic
strains, compression positive, principal stress ratio) are
:mod:`granular_material.procedures.calibration`'s."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from granular_material.errors import ParameterError

__all__ = ["DEFAULT_CRITICAL_FRACTION", "DEFAULT_DILATANCY_WINDOW", "DEFAULT_ELASTIC_WINDOW",
           "PARAMETER_UNITS", "Calibration", "Reading", "principal_ratio", "read_parameters"]

#: axial strain [-] of the window E and ν are read over, from the start of the test
DEFAULT_ELASTIC_WINDOW = 1.0e-3
#: width [-] in axial strain of the window around the peak ψ is read over
DEFAULT_DILATANCY_WINDOW = 1.0e-2
#: the last fraction of the axial strain φcs is read over (its mean stress ratio)
DEFAULT_CRITICAL_FRACTION = 0.2
#: the Mohr–Coulomb run parameters, in the order written, with their units
PARAMETER_UNITS = {"young": "Pa", "poisson": "-", "friction_angle": "deg",
                   "dilation_angle": "deg", "cohesion": "Pa", "critical_friction_angle": "deg",
                   "softening_strain": "-"}


@dataclass(frozen=True)
class Reading:
    """How one parameter was read: ``value`` (the mean over the RVEs, in ``unit``), the
    ``method`` in words, and each RVE's value and axial-strain window [-] (compression
    positive: from, to)."""

    name: str
    value: float
    unit: str
    method: str
    per_rve: tuple[float, ...]
    windows: tuple[tuple[float, float], ...]

    @property
    def std(self) -> float:
        """Standard deviation across the RVEs (0 for one RVE)."""
        return float(np.std(self.per_rve)) if len(self.per_rve) > 1 else 0.0

    @property
    def min(self) -> float:
        """Smallest value across the RVEs."""
        return float(np.min(self.per_rve))

    @property
    def max(self) -> float:
        """Largest value across the RVEs."""
        return float(np.max(self.per_rve))

    def as_dict(self) -> dict[str, Any]:
        """JSON-able: value, unit, std, min, max, method, per-RVE values and windows."""
        return {"value": self.value, "unit": self.unit, "std": self.std, "min": self.min,
                "max": self.max, "method": self.method, "per_rve": list(self.per_rve),
                "windows": [list(w) for w in self.windows]}


@dataclass(frozen=True)
class Calibration:
    """Mohr–Coulomb parameters read from drained biaxial curves.

    Attributes:
        parameters: the run parameters by name (:data:`PARAMETER_UNITS`: ``young`` [Pa],
            ``poisson`` [-], ``friction_angle``, ``dilation_angle``,
            ``critical_friction_angle`` [deg], ``cohesion`` [Pa], ``softening_strain`` [-]).
        readings: how each was read (:class:`Reading`), by the same names.
        curve: the curve table read (one row per record and RVE; columns of
            :func:`~granular_material.procedures.biaxial_test`).
        pressure: the confining pressure P [Pa].
        source: where the curves came from (an RVE file, or words).
        notes: what the reader should know (re-consolidation, a peak at the end, ...).
        settings: the test's settings (axial strain, strain per step, RVEs, ...).
    """

    parameters: dict[str, float]
    readings: dict[str, Reading]
    curve: pd.DataFrame
    pressure: float
    source: str = "curve"
    notes: tuple[str, ...] = ()
    settings: dict[str, Any] = field(default_factory=dict)

    def material_keywords(self) -> dict[str, float]:
        """The keywords of ``MohrCoulomb`` for these parameters at the pressure P
        (``initial_stress`` −P)."""
        p = self.parameters
        softens = (p["softening_strain"] > 0
                   and p["critical_friction_angle"] < p["friction_angle"])
        return {"young": p["young"], "poisson": p["poisson"],
                "friction_angle": p["friction_angle"],
                "dilation_angle": p["dilation_angle"], "cohesion": p["cohesion"],
                "critical_friction_angle": p["critical_friction_angle"] if softens else None,
                "softening_strain": p["softening_strain"] if softens else 0.0,
                "initial_stress": -self.pressure}

    def as_dict(self) -> dict[str, Any]:
        """JSON-able: parameters, readings, pressure, source, settings and notes."""
        return {"parameters": dict(self.parameters), "pressure": self.pressure,
                "source": self.source, "settings": dict(self.settings),
                "readings": {k: r.as_dict() for k, r in self.readings.items()},
                "notes": list(self.notes)}


# -- reading the curves (pure) ---------------------------------------------------------------
def _columns(curve: pd.DataFrame) -> None:
    need = ("axial_strain", "lateral_strain", "volumetric_strain", "sxx", "syy")
    missing = [c for c in need if c not in curve.columns]
    if missing:
        raise ParameterError("curve", f"lacks the column(s) {', '.join(missing)}")


def _phi(ratio: np.ndarray | float) -> np.ndarray:
    """Mobilised friction angle [deg] of σ1/σ3 with c = 0: sin φ = (R − 1)/(R + 1)."""
    r = np.asarray(ratio, dtype=float)
    return np.degrees(np.arcsin(np.clip((r - 1.0) / (r + 1.0), -1.0, 1.0)))


def principal_ratio(curve: pd.DataFrame) -> np.ndarray:
    """σ1/σ3 of the principal stresses of each row (``sxx``, ``syy``, ``sxy`` [Pa], tension
    positive; ``sxy`` 0 where absent); NaN where σ3 is not compressive."""
    sxx, syy = curve["sxx"].to_numpy(float), curve["syy"].to_numpy(float)
    sxy = curve["sxy"].to_numpy(float) if "sxy" in curve else np.zeros_like(sxx)
    centre, radius = -(sxx + syy) / 2, np.hypot((sxx - syy) / 2, sxy)
    s3 = centre - radius
    return np.where(s3 > 0, (centre + radius) / np.where(s3 > 0, s3, 1.0), np.nan)


def _read_one(g: pd.DataFrame, elastic_window: float, dilatancy_window: float,
              critical_fraction: float, rve: Any) -> tuple[dict[str, Any], list[str]]:
    """The parameters of one RVE's curve ``g`` (rows in step order): {name: (value,
    window)} and notes."""
    notes: list[str] = []
    ea = g["axial_strain"].to_numpy(float)
    e1 = -np.log1p(-ea)
    e3 = -np.log1p(g["lateral_strain"].to_numpy(float))
    sxx, syy = g["sxx"].to_numpy(float), g["syy"].to_numpy(float)
    # E, ν: least-squares slopes over the elastic window, then plane-strain Hooke's law
    win = ea <= ea[0] + elastic_window
    if win.sum() < 3:
        raise ParameterError("elastic_window", f"{elastic_window:g} holds {int(win.sum())} "
                             f"record(s) of RVE {rve}, fewer than 3: record more often")
    k1, k3, r = (np.polyfit(e1[win], y[win], 1)[0] for y in (-syy, -sxx, e3))
    a, b = np.linalg.solve([[k1, -k3], [k3, -k1]], [1.0, r])
    nu = b / (a + b)
    young = (1.0 + nu) / (a + b)
    if not (young > 0 and -1.0 < nu < 0.5):
        raise ParameterError("curve", f"of RVE {rve} gives E = {young:.4g} Pa, ν = {nu:.4g} "
                             f"over its first {elastic_window:g} axial strain: not an elastic "
                             "solid (narrow elastic_window to the curve's first, straight "
                             "part where it reaches into plastic flow, widen it where it "
                             "holds only noise; or look at the curve)")
    out = {"young": (young, (ea[0], ea[win][-1])), "poisson": (nu, (ea[0], ea[win][-1]))}
    # the plastic strains: the elastic strain of the stress change taken off
    d1, d3 = -syy - (-syy[0]), -sxx - (-sxx[0])
    e1p = e1 - ((1 - nu**2) * d1 - nu * (1 + nu) * d3) / young
    e3p = e3 - ((1 - nu**2) * d3 - nu * (1 + nu) * d1) / young
    gamma_p, ev_p = e1p - e3p, e1p + e3p
    # φ at the peak of the principal stress ratio
    ratio = principal_ratio(g)
    r_max = float(np.nanmax(ratio))
    peak = int(np.flatnonzero(ratio >= r_max * (1 - 1e-9))[0])
    phi = float(_phi(r_max))
    out["friction_angle"] = (phi, (ea[peak], ea[peak]))
    if peak == len(ea) - 1:
        notes.append(f"RVE {rve}: σ1/σ3 still rises at the end of the test: φ is a lower "
                     "bound; test to a larger axial strain")
    window_end = float(ea[win][-1])
    if window_end - ea[0] > 0.5 * (ea[peak] - ea[0]):
        notes.append(f"RVE {rve}: the elastic window (elastic_window {elastic_window:g}, to "
                     f"axial strain {window_end:.3g}) reaches past half the way to the peak "
                     f"of σ1/σ3 (at {ea[peak]:.3g}; the test ends at {ea[-1]:.3g}): E "
                     f"({young:.3g} Pa) and ν ({nu:.3g}) are secants over plastic flow, not "
                     "elastic (E too low, ν towards 0.5); narrow elastic_window to the "
                     "curve's first, straight part")
    # ψ: slope of εv^p against γ^p at the peak (a quadratic over the window around it)
    around = np.abs(ea - ea[peak]) <= dilatancy_window / 2
    x = gamma_p[around] - gamma_p[peak]
    if around.sum() < 4 or np.ptp(x) <= 1e-12:
        raise ParameterError("dilatancy_window", f"{dilatancy_window:g} around the peak of "
                             f"RVE {rve} holds no plastic flow to read ψ from: widen it")
    slope = np.polyfit(x, ev_p[around], 2)[1]
    psi = float(np.degrees(np.arcsin(np.clip(-slope, -1.0, 1.0))))
    out["dilation_angle"] = (psi, (ea[around][0], ea[around][-1]))
    # φcs: the mean stress ratio over the last fraction of the axial strain
    last = ea >= ea[-1] - critical_fraction * (ea[-1] - ea[0])
    phi_cs = float(_phi(np.nanmean(ratio[last])))
    out["critical_friction_angle"] = (phi_cs, (ea[last][0], ea[-1]))
    mobilised = _phi(ratio)
    tail = np.polyfit(ea[last], mobilised[last], 1)[0] * (ea[-1] - ea[last][0])
    if tail < -0.5:
        notes.append(f"RVE {rve}: the friction angle still falls by {-tail:.2g}° over the "
                     "last window: φcs is an upper bound; test to a larger axial strain")
    # softening strain: the plastic shear strain φ takes from the peak down to φcs, from the
    # linear fit of its descent (the top and bottom tenths of the drop left out)
    drop = phi - phi_cs
    if drop < 0.05:
        out["softening_strain"] = (0.0, (ea[peak], ea[peak]))
        return out, notes
    after = np.arange(peak, len(ea))
    reached = after[mobilised[after] <= phi_cs + 0.1 * drop]
    end = int(reached[0]) if reached.size else len(ea)
    fit = np.arange(peak, end)
    fit = fit[mobilised[fit] <= phi - 0.1 * drop]
    kappa = gamma_p - gamma_p[peak]
    if fit.size >= 3 and (slope := np.polyfit(kappa[fit], mobilised[fit], 1)[0]) < 0:
        softening = drop / -slope
        window = (ea[fit[0]], ea[fit[-1]])
    else:  # too few records on the descent: where it first reaches φcs
        hit = after[mobilised[after] <= phi_cs]
        stop = int(hit[0]) if hit.size else len(ea) - 1
        softening, window = float(kappa[stop]), (ea[peak], ea[stop])
        notes.append(f"RVE {rve}: too few records on the descent for a fit: the softening "
                     "strain is the plastic shear strain from the peak to where φcs is "
                     "first reached")
    out["softening_strain"] = (float(softening), window)
    return out, notes


_METHODS = {
    "young": "plane-strain secant over the elastic window: least-squares slopes k1 = dσ1/dε1, "
         "k3 = dσ3/dε1, r = dε3/dε1 solved for a = (1 − ν²)/E, b = ν(1 + ν)/E from "
         "dε1 = a dσ1 − b dσ3, dε3 = a dσ3 − b dσ1; E = (1 + ν)/(a + b)",
    "poisson": "as E: ν = b/(a + b) (σ3 constant: ν = −r/(1 − r))",
    "friction_angle": "peak of the principal stress ratio R = σ1/σ3, c = 0: "
                      "sin φ = (R − 1)/(R + 1)",
    "dilation_angle": "sin ψ = −dεv^p/dγ^p at the peak (γ^p = ε1^p − ε3^p, "
                      "εv^p = ε1^p + ε3^p, the "
           "elastic strain of the stress change removed with E, ν), slope at the peak of a "
           "quadratic fit over the window",
    "cohesion": "0: a test at one pressure cannot separate c from φ; the discs are "
                "cohesionless",
    "critical_friction_angle": "mean stress ratio over the last fraction of the axial strain, "
                               "c = 0",
    "softening_strain": "plastic shear strain γ^p over which the mobilised φ falls from its "
                        "peak to φcs: linear fit of φ against γ^p on the descent (0 when "
                        "there is none)",
}


def read_parameters(curve: pd.DataFrame, pressure: float,
                    elastic_window: float = DEFAULT_ELASTIC_WINDOW,
                    dilatancy_window: float = DEFAULT_DILATANCY_WINDOW,
                    critical_fraction: float = DEFAULT_CRITICAL_FRACTION,
                    source: str = "curve", notes: tuple[str, ...] = (),
                    settings: dict[str, Any] | None = None) -> Calibration:
    """Mohr–Coulomb parameters of drained biaxial curve(s), pure on the table.

    ``curve`` has the columns of :func:`~granular_material.procedures.biaxial_test`
    (``rve`` optional: one RVE; ``sxy`` optional: 0), ``pressure`` is P [Pa]. Each RVE is
    read alone; a parameter is the mean over the RVEs, its :class:`Reading` keeps the
    scatter. E and ν (plane strain, isotropic; σ3 held, so dσ3 ≈ 0)::

        dε1 = [(1 − ν²) dσ1 − ν(1 + ν) dσ3]/E,   dε3 = [(1 − ν²) dσ3 − ν(1 + ν) dσ1]/E
        σ3 constant:  ν = −r/(1 − r),  E = (1 − ν²) dσ1/dε1,  r = dε3/dε1

    φ = asin((R − 1)/(R + 1)) at the peak of R = σ1/σ3; φcs the same of R's mean over the
    last ``critical_fraction`` of the axial strain; ψ from sin ψ = −dεv^p/dγ^p at the peak,
    the elastic part *removed* (with E, ν; it vanishes at the peak itself, where dσ = 0);
    the softening strain the γ^p of φ's linear descent to φcs. ``ParameterError`` names the
    setting (or ``curve``) when a curve cannot be read.
    """
    if not (math.isfinite(pressure) and pressure > 0):
        raise ParameterError("pressure", f"must be a positive number of Pa, got {pressure!r}")
    for name, value in (("elastic_window", elastic_window),
                        ("dilatancy_window", dilatancy_window),
                        ("critical_fraction", critical_fraction)):
        if not (math.isfinite(value) and value > 0):
            raise ParameterError(name, f"must be a positive number, got {value!r}")
    if critical_fraction > 1:
        raise ParameterError("critical_fraction", f"must be at most 1, got {critical_fraction!r}")
    _columns(curve)
    if curve.empty:
        raise ParameterError("curve", "has no rows")
    groups = ([(0, curve)] if "rve" not in curve else list(curve.groupby("rve")))
    values: dict[str, list[float]] = {k: [] for k in PARAMETER_UNITS}
    windows: dict[str, list[tuple[float, float]]] = {k: [] for k in PARAMETER_UNITS}
    all_notes = list(notes)
    for rve, g in groups:
        g = g.sort_values("step") if "step" in g else g
        read, more = _read_one(g, elastic_window, dilatancy_window, critical_fraction, rve)
        read["cohesion"] = (0.0, (float(g["axial_strain"].iloc[0]),) * 2)
        all_notes += more
        for name, (value, window) in read.items():
            values[name].append(float(value))
            windows[name].append((float(window[0]), float(window[1])))
    readings = {name: Reading(name, float(np.mean(values[name])), unit, _METHODS[name],
                              tuple(values[name]), tuple(windows[name]))
                for name, unit in PARAMETER_UNITS.items()}
    parameters = {name: r.value for name, r in readings.items()}
    phi, phi_cs = "friction_angle", "critical_friction_angle"
    if parameters[phi_cs] > parameters[phi]:  # no softening: the peak is the end
        parameters[phi_cs] = parameters[phi]
        all_notes.append("φcs read above φ (no descent): φcs = φ")
    if parameters["dilation_angle"] < 0:
        parameters["dilation_angle"] = 0.0
        all_notes.append(f"ψ read below 0 ({readings['dilation_angle'].value:.3g}°, "
                         "contraction at the "
                         "peak): ψ = 0")
    if parameters["softening_strain"] <= 0 or parameters[phi_cs] >= parameters[phi]:
        parameters["softening_strain"], parameters[phi_cs] = 0.0, parameters[phi]
    if parameters["dilation_angle"] > parameters[phi]:
        parameters["dilation_angle"] = parameters[phi]
        all_notes.append(f"ψ read above φ ({readings['dilation_angle'].value:.3g}°): ψ = φ "
                         "(Mohr–Coulomb flow is at most associated)")
    return Calibration(parameters, readings, curve, float(pressure), source,
                       tuple(all_notes), dict(settings or {}))
