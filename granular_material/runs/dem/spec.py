"""The specifications of the DEM runs: preparing RVEs (:class:`PrepareSpec`), the drained
biaxial test of the RVEs of a file (:class:`BiaxialDemSpec`) and a ∇u path driven on them
(:class:`DriveSpec`), the problems of ``granular-material prepare``, ``biaxial-dem`` and
``dem-drive``.

Each is frozen and flat: its fields are the command's options by their bare names
(``axial_strain`` is ``--axial-strain``), with the command's defaults, checked on
construction by type and range (a :class:`~granular_material.runs.spec_checks.SpecError`
naming the field); what takes the files or several fields together (the output file, the
packing, the steps a test needs, memory) is :func:`~granular_material.runs.dem.check`'s, before
any work. Units are SI; strains compression positive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, ClassVar

from granular_material.checks import RVE_MATERIAL_DEFAULTS
from granular_material.dem.kernels import DTYPES
from granular_material.procedures.element_tests import DEFAULT_AXIAL_STRAIN, DEFAULT_RECORD_EVERY
from granular_material.reference_values import (
    DEFAULT_DISCS,
    DEFAULT_MAX_DEM_STEPS,
    DEFAULT_PRESSURE,
    DEFAULT_STRAIN_PER_STEP,
)
from granular_material.runs.spec_checks import SpecError, check_device, conform_fields

__all__ = ["DEM_TESTS", "DRIVE_INCREMENTS", "DTYPES", "LAWS",
           "SPECS", "BiaxialDemSpec", "DemSpec", "DriveSpec", "PrepareSpec", "field_names"]

#: the DEM problems, by the command that runs each
DEM_TESTS = ("prepare", "biaxial-dem", "dem-drive")
#: the contact stiffness laws of prepared RVEs
LAWS = ("constant", "frictmat")
#: the increments of dem-drive by default
DRIVE_INCREMENTS = 10

_D = RVE_MATERIAL_DEFAULTS


def _positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise SpecError(name, f"must be a positive finite number, got {value!r}")


def _at_least_one(name: str, value: int) -> None:
    if value < 1:
        raise SpecError(name, f"must be >= 1, got {value!r}")


def _one_of(name: str, value: Any, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise SpecError(name, f"must be one of {', '.join(choices)}, got {value!r}")


class _RunFields:
    """What every DEM spec shares: where it runs and how it reports (its checks)."""

    test: ClassVar[str]
    device: str | None
    dtype: str

    def _check_run(self) -> None:
        conform_fields(self, error=SpecError)
        if self.device is not None:
            check_device(self.device)
        _one_of("dtype", self.dtype, DTYPES)

    def replace(self, **changes: Any) -> Any:
        """A copy with ``changes`` (dataclasses.replace; checked again)."""
        return replace(self, **changes)  # type: ignore[type-var]


@dataclass(frozen=True, kw_only=True)
class PrepareSpec(_RunFields):
    """``prepare``: B random packings of N discs in periodic cells, consolidated without
    friction to ``pressure``, then friction set and re-equilibrated; written as an RVE file.

    Attributes:
        particles: discs per RVE N.
        seed: random seed; RVE b draws from seed + b.
        pressure: isotropic consolidation pressure [Pa].
        batch: RVEs B.
        target_void_ratio: first compress the gas to this 2D void ratio; None: not.
        radius_min, radius_max: disc radii [m].
        law: contact stiffness law, "constant" (kn, kt) or "frictmat" (contact_young,
            kt_over_kn).
        kn, kt: normal and tangential contact stiffness [N/m] (law constant).
        contact_young: the discs' Young's modulus [Pa] that sets kn = 2E r1 r2/(r1 + r2)
            (law frictmat).
        kt_over_kn: FrictMat kt/kn [-].
        contact_friction_angle: interparticle friction angle [rad], set after the
            frictionless consolidation.
        damping: local non-viscous damping [-].
        density: [kg/m³]. thickness: disc thickness [m].
        out: the RVE file written.
        device: "cpu", "cuda" or "cuda:N"; None: CUDA where present.
        dtype: "float64" or "float32".
        progress: progress bars on stderr.
    """

    test: ClassVar[str] = "prepare"
    particles: int = DEFAULT_DISCS
    seed: int = 1
    pressure: float = DEFAULT_PRESSURE
    batch: int = 1
    target_void_ratio: float | None = _D["target_void_ratio"]
    radius_min: float = _D["radius_min"]
    radius_max: float = _D["radius_max"]
    law: str = _D["law"]
    kn: float = _D["kn"]
    kt: float = _D["kt"]
    contact_young: float = _D["contact_young"]
    kt_over_kn: float = _D["kt_over_kn"]
    contact_friction_angle: float = _D["contact_friction_angle"]
    damping: float = _D["damping"]
    density: float = _D["density"]
    thickness: float = _D["thickness"]
    out: Path = Path("rve.npz")
    device: str | None = None
    dtype: str = "float64"
    progress: bool = False

    def __post_init__(self) -> None:
        self._check_run()
        for name in ("particles", "batch"):
            _at_least_one(name, getattr(self, name))
        for name in ("pressure", "radius_min", "radius_max", "kn", "kt", "contact_young",
                     "kt_over_kn", "density", "thickness"):
            _positive(name, getattr(self, name))
        if self.target_void_ratio is not None:
            _positive("target_void_ratio", self.target_void_ratio)
        _one_of("law", self.law, LAWS)

    def packing_fields(self) -> dict[str, Any]:
        """The RVE material fields as the packing's checks take them
        (:data:`~granular_material.checks.RVE_MATERIAL_DEFAULTS`), with the seed."""
        return {name: getattr(self, name) for name in
                ("target_void_ratio", "radius_min", "radius_max", "law", "kn", "kt",
                 "contact_young", "kt_over_kn", "contact_friction_angle", "damping",
                 "density", "thickness", "seed")}


@dataclass(frozen=True, kw_only=True)
class BiaxialDemSpec(_RunFields):
    """``biaxial-dem``: the drained biaxial test of every RVE of a file, σxx held at
    −``confining`` by a servo while εyy is driven to ``axial_strain``.

    Attributes:
        rve: the RVE file (.npz).
        axial_strain: final axial strain [-], engineering, compression positive.
        confining: lateral stress magnitude [Pa].
        strain_per_step: largest axial (logarithmic) strain a DEM step [-].
        record_every: DEM steps between the curve's rows.
        max_dem_steps: the most DEM steps the test may take (refused before it starts).
        out: CSV of the curve(s); None: none (and no checkpoint to resume from).
        plot: PNG of σ1/σ3 and εv against εa; None: none.
        device, dtype, progress: as :class:`PrepareSpec`'s.
    """

    test: ClassVar[str] = "biaxial-dem"
    rve: Path
    axial_strain: float = DEFAULT_AXIAL_STRAIN
    confining: float = DEFAULT_PRESSURE
    strain_per_step: float = DEFAULT_STRAIN_PER_STEP
    record_every: int = DEFAULT_RECORD_EVERY
    max_dem_steps: int = DEFAULT_MAX_DEM_STEPS
    out: Path | None = None
    plot: Path | None = None
    device: str | None = None
    dtype: str = "float64"
    progress: bool = False

    def __post_init__(self) -> None:
        self._check_run()
        for name in ("axial_strain", "confining", "strain_per_step"):
            _positive(name, getattr(self, name))
        for name in ("record_every", "max_dem_steps"):
            _at_least_one(name, getattr(self, name))


@dataclass(frozen=True, kw_only=True)
class DriveSpec(_RunFields):
    """``dem-drive``: the displacement gradient ``grad_u`` applied to every RVE of a file in
    ``increments`` equal strain-driven increments, each RVE recorded after every one.

    Attributes:
        rve: the RVE file (.npz).
        grad_u: the total ∇u (∂u_i/∂x_j) as (Gxx, Gxy, Gyx, Gyy) [-].
        increments: K.
        max_strain_per_step: the largest strain a DEM step [-].
        max_dem_steps: the most DEM steps of the whole path (refused before it starts).
        out: CSV of the path; None: none (and no checkpoint to resume from).
        device, dtype, progress: as :class:`PrepareSpec`'s.
    """

    test: ClassVar[str] = "dem-drive"
    rve: Path
    grad_u: tuple[float, float, float, float]
    increments: int = DRIVE_INCREMENTS
    max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP
    max_dem_steps: int = DEFAULT_MAX_DEM_STEPS
    out: Path | None = None
    device: str | None = None
    dtype: str = "float64"
    progress: bool = False

    def __post_init__(self) -> None:
        self._check_run()
        _positive("max_strain_per_step", self.max_strain_per_step)
        for name in ("increments", "max_dem_steps"):
            _at_least_one(name, getattr(self, name))


#: a DEM run's specification
DemSpec = PrepareSpec | BiaxialDemSpec | DriveSpec
#: the spec of each DEM test
SPECS: dict[str, type] = {kind.test: kind for kind in (PrepareSpec, BiaxialDemSpec, DriveSpec)}


def field_names(kind: type) -> tuple[str, ...]:
    """The fields of the DEM spec ``kind``, in order."""
    return tuple(f.name for f in fields(kind))
