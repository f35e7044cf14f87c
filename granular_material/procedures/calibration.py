"""Calibration of a Mohr–Coulomb material from drained biaxial DEM tests of an RVE file.

Three parts, each usable alone:

- :func:`read_parameters` (pure, on a curve table): E and ν, φ, ψ, φcs and the softening
  strain of every RVE's curve, with their scatter across the RVEs;
- :func:`drained_point_curve`: any material of the ``Material`` protocol driven at one point
  through the drained plane-strain biaxial path (σxx held at −P by solving the lateral
  strain with the material's tangent), tabled as the DEM test's curve;
  :func:`model_curve` does it for the calibrated Mohr–Coulomb material;
- :func:`calibrate_mohr_coulomb`: the DEM tests of an RVE file, then the reading.

Strains are read as logarithmic strains of the cell, compression positive:
ε1 = −ln(1 − εa), ε3 = −ln(1 + εlat), εv = ε1 + ε3 (the DEM test moves the cell in equal
logarithmic steps, and the point driver moves its point the same way, ∇u on the committed
configuration, as the FEM hands it to a finite-strain material). Stresses are compression
positive in the readings: σ1 = −σyy and σ3 = −σxx on the axes for the elastic constants;
the friction angles use the principal stresses (the RVE's own shear stress σxy included),
R = σ1/σ3 their ratio.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.errors import ParameterError

__all__ = ["DEFAULT_CRITICAL_FRACTION", "DEFAULT_DILATANCY_WINDOW", "DEFAULT_ELASTIC_WINDOW",
           "DEFAULT_RECORD_EVERY", "PARAMETER_UNITS", "Calibration", "Reading",
           "calibrate_mohr_coulomb", "drained_point_curve", "model_curve", "principal_ratio",
           "read_parameters"]

#: axial strain [-] of the window E and ν are read over, from the start of the test
DEFAULT_ELASTIC_WINDOW = 1.0e-3
#: width [-] in axial strain of the window around the peak ψ is read over
DEFAULT_DILATANCY_WINDOW = 1.0e-2
#: the last fraction of the axial strain φcs is read over (its mean stress ratio)
DEFAULT_CRITICAL_FRACTION = 0.2
#: DEM steps between the records of the calibration's biaxial tests (at the DEM material's
#: 1e-5 strain a step: ten records in the elastic window)
DEFAULT_RECORD_EVERY = 10
#: the Mohr–Coulomb run parameters, in the order written, with their units
PARAMETER_UNITS = {"E": "Pa", "nu": "-", "phi": "deg", "psi": "deg", "cohesion": "Pa",
                   "phi_cs": "deg", "softening_strain": "-"}
#: the RVE's stress is re-consolidated to P when σxx or σyy is further than this from −P
RECONSOLIDATE_TOLERANCE = 0.01


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
        parameters: the run parameters by name (:data:`PARAMETER_UNITS`: ``E`` [Pa], ``nu``,
            ``phi``, ``psi``, ``phi_cs`` [deg], ``cohesion`` [Pa], ``softening_strain``).
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
        softens = p["softening_strain"] > 0 and p["phi_cs"] < p["phi"]
        return {"young": p["E"], "poisson": p["nu"], "friction_angle": p["phi"],
                "dilation_angle": p["psi"], "cohesion": p["cohesion"],
                "critical_friction_angle": p["phi_cs"] if softens else None,
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
                             "solid (widen elastic_window, or look at the curve)")
    out = {"E": (young, (ea[0], ea[win][-1])), "nu": (nu, (ea[0], ea[win][-1]))}
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
    out["phi"] = (phi, (ea[peak], ea[peak]))
    if peak == len(ea) - 1:
        notes.append(f"RVE {rve}: σ1/σ3 still rises at the end of the test: φ is a lower "
                     "bound; test to a larger axial strain")
    # ψ: slope of εv^p against γ^p at the peak (a quadratic over the window around it)
    around = np.abs(ea - ea[peak]) <= dilatancy_window / 2
    x = gamma_p[around] - gamma_p[peak]
    if around.sum() < 4 or np.ptp(x) <= 1e-12:
        raise ParameterError("dilatancy_window", f"{dilatancy_window:g} around the peak of "
                             f"RVE {rve} holds no plastic flow to read ψ from: widen it")
    slope = np.polyfit(x, ev_p[around], 2)[1]
    psi = float(np.degrees(np.arcsin(np.clip(-slope, -1.0, 1.0))))
    out["psi"] = (psi, (ea[around][0], ea[around][-1]))
    # φcs: the mean stress ratio over the last fraction of the axial strain
    last = ea >= ea[-1] - critical_fraction * (ea[-1] - ea[0])
    phi_cs = float(_phi(np.nanmean(ratio[last])))
    out["phi_cs"] = (phi_cs, (ea[last][0], ea[-1]))
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
    "E": "plane-strain secant over the elastic window: least-squares slopes k1 = dσ1/dε1, "
         "k3 = dσ3/dε1, r = dε3/dε1 solved for a = (1 − ν²)/E, b = ν(1 + ν)/E from "
         "dε1 = a dσ1 − b dσ3, dε3 = a dσ3 − b dσ1; E = (1 + ν)/(a + b)",
    "nu": "as E: ν = b/(a + b) (σ3 constant: ν = −r/(1 − r))",
    "phi": "peak of the principal stress ratio R = σ1/σ3, c = 0: sin φ = (R − 1)/(R + 1)",
    "psi": "sin ψ = −dεv^p/dγ^p at the peak (γ^p = ε1^p − ε3^p, εv^p = ε1^p + ε3^p, the "
           "elastic strain of the stress change removed with E, ν), slope at the peak of a "
           "quadratic fit over the window",
    "cohesion": "0: a test at one pressure cannot separate c from φ; the discs are "
                "cohesionless",
    "phi_cs": "mean stress ratio over the last fraction of the axial strain, c = 0",
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
    if parameters["phi_cs"] > parameters["phi"]:  # no softening: the peak is the end
        parameters["phi_cs"] = parameters["phi"]
        all_notes.append("φcs read above φ (no descent): φcs = φ")
    if parameters["psi"] < 0:
        parameters["psi"] = 0.0
        all_notes.append(f"ψ read below 0 ({readings['psi'].value:.3g}°, contraction at the "
                         "peak): ψ = 0")
    if parameters["softening_strain"] <= 0 or parameters["phi_cs"] >= parameters["phi"]:
        parameters["softening_strain"], parameters["phi_cs"] = 0.0, parameters["phi"]
    if parameters["psi"] > parameters["phi"]:
        parameters["psi"] = parameters["phi"]
        all_notes.append(f"ψ read above φ ({readings['psi'].value:.3g}°): ψ = φ "
                         "(Mohr–Coulomb flow is at most associated)")
    return Calibration(parameters, readings, curve, float(pressure), source,
                       tuple(all_notes), dict(settings or {}))


# -- the material at one point -------------------------------------------------------------
#: axial (logarithmic) strain of one increment of :func:`drained_point_curve` by default [-]
DEFAULT_POINT_INCREMENT = 1.0e-4


def drained_point_curve(material: Any, pressure: float, axial_strain: float,
                        strain_per_increment: float = DEFAULT_POINT_INCREMENT,
                        tolerance: float = 1.0e-10, max_iterations: int = 50) -> pd.DataFrame:
    """Drive ``material`` (the ``Material`` protocol, not yet allocated: it is allocated
    with one point) through the drained plane-strain biaxial path at one point.

    Each increment shortens the axis y by the same logarithmic strain (n increments of at
    most ``strain_per_increment`` ending at the engineering ``axial_strain``, compression
    positive), as the DEM test moves its cell: ∇u on the committed configuration,
    ∂u_y/∂y = exp(−Δ) − 1; it solves the lateral ∂u_x/∂x for σxx = −``pressure`` [Pa] by
    Newton's method on the material's tangent D_xxxx (``|σxx + P| ≤ tolerance·P``), then
    commits.
    The material's starting stress is its own (a Mohr–Coulomb or linear-elastic material
    made with ``initial_stress = −P`` starts on the path).

    Returns the table of :func:`~granular_material.procedures.biaxial_test` (``rve`` 0,
    ``step`` the increment, ``axial_strain``, ``lateral_strain``, ``volumetric_strain`` of
    the stretches Π(1 + ∇u), ``sxx``, ``syy``, ``sxy`` [Pa], ``stress_ratio`` syy/sxx) and
    ``iterations`` (Newton's per increment). ``RuntimeError`` when a point fails or the
    lateral strain does not converge.
    """
    if not (math.isfinite(pressure) and pressure > 0):
        raise ParameterError("pressure", f"must be a positive number of Pa, got {pressure!r}")
    if not (math.isfinite(axial_strain) and 0 < axial_strain < 0.9):
        raise ParameterError("axial_strain", f"must lie in (0, 0.9), got {axial_strain!r}")
    if not (math.isfinite(strain_per_increment) and strain_per_increment > 0):
        raise ParameterError("strain_per_increment",
                             f"must be a positive number, got {strain_per_increment!r}")
    log_total = -math.log1p(-axial_strain)
    n = math.ceil(log_total / strain_per_increment)
    step_y = math.expm1(-log_total / n)  # ∇u_yy of one increment on the committed cell
    material.allocate(1)
    ex = ey = 0.0
    gx = 0.0
    rows = []

    def record(step: int, stress: np.ndarray, iterations: int) -> None:
        rows.append({"rve": 0, "step": step, "axial_strain": -math.expm1(ey),
                     "lateral_strain": math.expm1(ex), "volumetric_strain": math.expm1(ex + ey),
                     "sxx": stress[0, 0], "syy": stress[1, 1],
                     "sxy": 0.5 * (stress[0, 1] + stress[1, 0]),
                     "stress_ratio": stress[1, 1] / stress[0, 0], "iterations": iterations})

    record(0, material.evaluate(np.zeros((1, 2, 2))).stress[0], 0)
    for step in range(1, n + 1):
        iteration = 0
        while iteration < max_iterations:
            iteration += 1
            response = material.evaluate(np.array([[[gx, 0.0], [0.0, step_y]]]))
            if not response.ok:
                raise RuntimeError(f"the material failed at increment {step} "
                                   f"({response.reasons[0]})")
            residual = response.stress[0, 0, 0] + pressure
            if abs(residual) <= tolerance * pressure:
                break
            gx -= residual / response.tangent[0, 0, 0, 0, 0]
        if abs(residual) > tolerance * pressure:
            raise RuntimeError(f"σxx not held at −{pressure:g} Pa at increment {step} in "
                               f"{max_iterations} iterations (residual {residual:.3g} Pa)")
        material.commit()
        ex, ey = ex + math.log1p(gx), ey + math.log1p(step_y)
        record(step, response.stress[0], iteration)
    return pd.DataFrame(rows)


def model_curve(calibration: Calibration, axial_strain: float | None = None,
                strain_per_increment: float = DEFAULT_POINT_INCREMENT) -> pd.DataFrame:
    """The calibrated ``MohrCoulomb`` material (at ``initial_stress`` −P) through the drained
    path of :func:`drained_point_curve`, to ``axial_strain`` (default: the end of the
    calibration's curve)."""
    from granular_material.fem.mohr_coulomb import MohrCoulomb

    if axial_strain is None:
        axial_strain = float(calibration.curve["axial_strain"].max())
    material = MohrCoulomb(**calibration.material_keywords())
    return drained_point_curve(material, calibration.pressure, axial_strain,
                               strain_per_increment)


# -- the DEM tests -------------------------------------------------------------------------
def _rve_data(rve: Any, rves: int | None) -> tuple[Any, str]:
    """The RVEs to test (the first ``rves`` of a file or an RVEData) and their source."""
    from granular_material.dem import RVEData, load_rve

    if isinstance(rve, RVEData):
        data, source = rve, "RVE data"
    else:
        path = Path(rve)
        if not path.is_file():
            raise ParameterError("rve", f"{path} does not exist" if not path.exists()
                                 else f"{path} is not a file")
        data, source = load_rve(path), str(path)
    if data.n_rve < 1:
        raise ParameterError("rve", f"{source} holds no RVE")
    if rves is not None:
        if not (isinstance(rves, int) and rves >= 1):
            raise ParameterError("rves", f"must be an integer >= 1, got {rves!r}")
        if rves > data.n_rve:
            raise ParameterError("rves", f"{rves} asks for more RVEs than the {data.n_rve} "
                                 f"of {source}")
        data = data.take(slice(0, rves))
    return data, source


def calibrate_mohr_coulomb(rve_path_or_data: Any, pressure: float, axial_strain: float = 0.1,
                           device: str | None = "cpu", progress: bool = False,
                           rves: int | None = None, dtype: str = "float64",
                           record_every: int = DEFAULT_RECORD_EVERY,
                           **reading: float) -> Calibration:
    """Drained biaxial DEM tests of the RVEs of a file (or an ``RVEData``) at the confining
    pressure ``pressure`` [Pa] to ``axial_strain`` (compression positive), then
    :func:`read_parameters` on their curves (``reading``: its window settings).

    Every RVE (or the first ``rves``) is tested: the scatter between them is part of the
    answer. An RVE whose σxx or σyy is off −P by more than 1 % is first re-consolidated
    isotropically to P (said in the notes: its void ratio changes). The stepping is the
    DEM material's default (``DEFAULT_STRAIN_PER_STEP`` of
    :mod:`~granular_material.procedures.strain_path`, 1e-5) a DEM step; a record every
    ``record_every`` steps. ``ParameterError`` naming the field (``rve``, ``pressure``,
    ``axial_strain``, ``rves``) before any DEM step.
    """
    from granular_material.dem import DEMBatch
    from granular_material.procedures.element_tests import (
        BIAXIAL_NAMES,
        biaxial_test,
        check_biaxial,
        lateral_stress_error,
    )
    from granular_material.procedures.servo import consolidate
    from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP

    if not (isinstance(pressure, int | float) and math.isfinite(pressure) and pressure > 0):
        raise ParameterError("pressure", f"must be a positive number of Pa, got {pressure!r}")
    if not (isinstance(record_every, int) and record_every >= 1):
        raise ParameterError("record_every", f"must be an integer >= 1, got {record_every!r}")
    try:
        check_biaxial(axial_strain, pressure, DEFAULT_STRAIN_PER_STEP, names=BIAXIAL_NAMES)
    except ValueError as exc:
        raise ParameterError("axial_strain", str(exc).removeprefix("axial_strain ")) from None
    data, source = _rve_data(rve_path_or_data, rves)
    batch = DEMBatch(data, device=device, dtype=dtype)
    notes: list[str] = []
    h = batch.homogenize()
    diag = np.stack([h.stress[:, 0, 0], h.stress[:, 1, 1]], axis=1)
    off = np.abs(diag / -pressure - 1.0).max(axis=1)
    if (off > RECONSOLIDATE_TOLERANCE).any():
        p_before = -h.mean_stress
        consolidate(batch, pressure, progress=progress)
        e_after = batch.homogenize().void_ratio
        notes.append("re-consolidated isotropically to P: mean stress before "
                     + ", ".join(f"{p:.4g}" for p in p_before[:5]) + " Pa, void ratio "
                     + ", ".join(f"{a:.4g} → {b:.4g}" for a, b in
                                 zip(h.void_ratio[:5], e_after[:5], strict=False)))
    curve = biaxial_test(batch, axial_strain=axial_strain, confining=pressure,
                         strain_per_step=DEFAULT_STRAIN_PER_STEP, record_every=record_every,
                         progress=progress)
    held = lateral_stress_error(curve, pressure)
    worst = float(held["median_error"].max())
    if worst > 0.05:
        notes.append(f"the servo held σxx at −P only to {worst:.1%} (median, worst RVE): "
                     "not quite a drained test")
    settings = {"axial_strain": float(axial_strain), "rves": int(data.n_rve),
                "discs": int(data.n_disc), "strain_per_step": DEFAULT_STRAIN_PER_STEP,
                "record_every": int(record_every), "device": batch.device}
    return read_parameters(curve, pressure, source=source, notes=tuple(notes),
                           settings=settings, **reading)
