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
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.errors import ParameterError
from granular_material.procedures.calibration_reading import (
    DEFAULT_CRITICAL_FRACTION,
    DEFAULT_DILATANCY_WINDOW,
    DEFAULT_ELASTIC_WINDOW,
    PARAMETER_UNITS,
    Calibration,
    Reading,
    principal_ratio,
    read_parameters,
)
from granular_material.procedures.packing import check_pressure_for_rves
from granular_material.vocabulary import renamed

__all__ = ["DEFAULT_CRITICAL_FRACTION", "DEFAULT_DILATANCY_WINDOW", "DEFAULT_ELASTIC_WINDOW",
           "DEFAULT_RECORD_EVERY", "PARAMETER_UNITS", "Calibration", "Reading",
           "calibrate_mohr_coulomb", "drained_point_curve", "model_curve", "principal_ratio",
           "read_parameters"]

#: DEM steps between the records of the calibration's biaxial tests (at the DEM material's
#: 1e-5 strain a step: ten records in the elastic window)
DEFAULT_RECORD_EVERY = 10
#: the RVE's stress is re-consolidated to P when σxx or σyy is further than this from −P
RECONSOLIDATE_TOLERANCE = 0.01


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
        raise ParameterError("confining", f"must be a positive number of Pa, got {pressure!r}")
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
    from granular_material.fem.materials.mohr_coulomb import MohrCoulomb

    if axial_strain is None:
        axial_strain = float(calibration.curve["axial_strain"].max())
    material = MohrCoulomb(**calibration.material_keywords())
    return drained_point_curve(material, calibration.pressure, axial_strain,
                               strain_per_increment)


# -- the DEM tests -------------------------------------------------------------------------
def _check_reading(reading: dict[str, Any]) -> None:
    """The window settings of :func:`read_parameters` given to a calibration: known names,
    numbers; a ParameterError naming the first that is not, before any DEM step."""
    import inspect

    known = {name for name, p in inspect.signature(read_parameters).parameters.items()
             if isinstance(p.default, float)}
    for name, value in reading.items():
        if name not in known:
            raise ParameterError(name, f"is no setting of the calibration's reading (it "
                                       f"takes {', '.join(sorted(known))})")
        if isinstance(value, bool) or not isinstance(value, int | float) or not (
                math.isfinite(value) and value > 0):
            raise ParameterError(name, f"must be a positive number, got {value!r}")


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


def calibrate_mohr_coulomb(rve_path_or_data: Any, confining: float | None = None,
                           axial_strain: float = 0.1,
                           device: str | None = "cpu", progress: bool = False,
                           rves: int | None = None, dtype: str = "float64",
                           record_every: int = DEFAULT_RECORD_EVERY,
                           **reading: float) -> Calibration:
    """Drained biaxial DEM tests of the RVEs of a file (or an ``RVEData``) at the confining
    pressure ``confining`` P [Pa] to ``axial_strain`` (compression positive), then
    :func:`read_parameters` on their curves (``reading``: its window settings; ``pressure=``,
    the old name of ``confining``, is still read, with a
    :class:`~granular_material.vocabulary.RenamedWarning`).

    Every RVE (or the first ``rves``) is tested: the scatter between them is part of the
    answer. An RVE whose σxx or σyy is off −P by more than 1 % is first re-consolidated
    isotropically to P (said in the notes: its void ratio changes). The stepping is the
    DEM material's default (``DEFAULT_STRAIN_PER_STEP`` of
    :mod:`~granular_material.procedures.strain_path`, 1e-5) a DEM step; a record every
    ``record_every`` steps. ``ParameterError`` naming the field (``rve``, ``confining``,
    ``axial_strain``, ``rves``) before any DEM step.
    """
    if "pressure" in reading:
        confining = renamed({"pressure": reading.pop("pressure"), "confining": confining},
                            "calibrate", given=lambda v: v is not None)["confining"]
    pressure = confining
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
        raise ParameterError("confining", f"must be a positive number of Pa, got {pressure!r}")
    if not (isinstance(record_every, int) and record_every >= 1):
        raise ParameterError("record_every", f"must be an integer >= 1, got {record_every!r}")
    try:
        check_biaxial(axial_strain, pressure, DEFAULT_STRAIN_PER_STEP, names=BIAXIAL_NAMES)
    except ValueError as exc:
        raise ParameterError("axial_strain", str(exc).removeprefix("axial_strain ")) from None
    _check_reading(reading)
    if device is not None and not isinstance(device, str):
        raise ParameterError("device", f"must be a device name (cpu, cuda, cuda:N) or None, "
                                       f"got {device!r}")
    if dtype not in ("float64", "float32"):
        raise ParameterError("dtype", f"must be float64 or float32, got {dtype!r}")
    data, source = _rve_data(rve_path_or_data, rves)
    check_pressure_for_rves(data, pressure, "confining")
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
