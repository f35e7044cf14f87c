"""Each default named once, each input check made once: the command line, the library and
the checks module all read the same named values and run the same checks (no DEM run)."""

from __future__ import annotations

import argparse
import re
from dataclasses import fields
from types import SimpleNamespace

import numpy as np
import pytest

from granular_material.checks import RVE_MATERIAL_DEFAULTS
from granular_material.cli import build_parser
from granular_material.cli.options import UsageError, packing_parameters
from granular_material.dem import RVEMeta
from granular_material.dem.rve.file import FRICTMAT_STIFFNESS
from granular_material.procedures.driven_path import plan_path
from granular_material.procedures.element_tests import (
    DEFAULT_AXIAL_STRAIN,
    DEFAULT_RECORD_EVERY,
    check_biaxial,
)
from granular_material.procedures.packing import (
    DEFAULT_DISCS,
    DEFAULT_PRESSURE,
    DEFAULT_RADIUS_RANGE,
    check_packing,
)
from granular_material.procedures.strain_path import DEFAULT_MAX_DEM_STEPS, DEFAULT_STRAIN_PER_STEP


def _defaults(command: str) -> dict[str, object]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {a.dest: a.default for a in sub.choices[command]._actions}


def test_rve_material_defaults_are_the_meta_and_packing_ones() -> None:
    meta = RVEMeta()
    d = RVE_MATERIAL_DEFAULTS
    assert (d["radius_min"], d["radius_max"]) == DEFAULT_RADIUS_RANGE
    assert {"law": d["law"], "kn": d["kn"], "kt": d["kt"]} == meta.stiffness
    assert {"law": "frictmat", "young": d["contact_young"],
            "kt_over_kn": d["kt_over_kn"]} == FRICTMAT_STIFFNESS
    assert d["contact_friction_angle"] == meta.friction_angle
    for name in ("damping", "density", "thickness"):
        assert d[name] == getattr(meta, name)


def test_dem_commands_take_the_named_defaults() -> None:
    prepare = _defaults("prepare")
    assert (prepare["particles"], prepare["pressure"]) == (DEFAULT_DISCS, DEFAULT_PRESSURE)
    biaxial = _defaults("biaxial-dem")
    assert biaxial["axial_strain"] == DEFAULT_AXIAL_STRAIN
    assert biaxial["confining"] == DEFAULT_PRESSURE
    assert biaxial["strain_per_step"] == DEFAULT_STRAIN_PER_STEP
    assert biaxial["record_every"] == DEFAULT_RECORD_EVERY
    assert biaxial["max_dem_steps"] == DEFAULT_MAX_DEM_STEPS
    drive = _defaults("dem-drive")
    assert drive["max_strain_per_step"] == DEFAULT_STRAIN_PER_STEP
    assert drive["max_dem_steps"] == DEFAULT_MAX_DEM_STEPS


@pytest.mark.parametrize(("change", "particles", "pressure", "library", "option"), [
    ({"radius_min": 8e-3}, 400, 1e5, "r_min = 0.008 exceeds r_max = 0.007",
     "--radius-min 0.008 exceeds --radius-max 0.007"),
    ({}, 5, 1e5, "n_disc = 5 is too few for radii", "--particles 5 is too few for radii"),
    ({}, 400, 100.0, "pressure = 100 Pa is too low", "--pressure 100 Pa is too low"),
    ({}, 400, 1e7, "pressure = 1e+07 Pa would press", "--pressure 1e+07 Pa would press"),
])
def test_one_packing_check_named_by_its_caller(change, particles, pressure, library,
                                               option) -> None:
    options = SimpleNamespace(**{**RVE_MATERIAL_DEFAULTS, **change})
    meta = RVEMeta()
    radii = (options.radius_min, options.radius_max)
    with pytest.raises(ValueError, match=re.escape(library)):
        check_packing(particles, pressure, meta, radii)
    with pytest.raises(UsageError, match=re.escape(option)):
        packing_parameters(options, particles, pressure)


def test_one_biaxial_check_named_by_its_caller() -> None:
    assert check_biaxial(0.1, 1e5, 1e-5) == 10537
    with pytest.raises(ValueError, match=r"axial_strain = 0\.1 at strain_per_step = 1e-12 "
                                         r"needs 1\.054e"):
        check_biaxial(0.1, 1e5, 1e-12, max_steps=10**6)
    with pytest.raises(ValueError, match="more than --max-dem-steps 1000000"):
        check_biaxial(0.1, 1e5, 1e-12, max_steps=10**6, names={"max_steps": "--max-dem-steps"})
    with pytest.raises(ValueError, match=r"--axial-strain must be below 0\.9"):
        check_biaxial(0.95, 1e5, 1e-5, names={"axial_strain": "--axial-strain"})


def test_one_path_plan() -> None:
    grad = np.array([[0.0, 0.001], [0.0, 0.0]])
    assert plan_path(grad, 3) == [34, 34, 34]
    with pytest.raises(ValueError, match=r"needs 102 DEM steps in 3 increments .* more than "
                                         r"max_steps = 101"):
        plan_path(grad, 3, max_steps=101)
    with pytest.raises(ValueError, match="inverts the cell at increment 1 of 1"):
        plan_path(np.array([[-2.5, 0.0], [0.0, 0.0]]), 1)


def test_each_dem_material_setting_is_declared_once() -> None:
    """The DEM material's settings are fields of one chain of frozen dataclasses, each
    declared in one of them; the material and its backend take them only as that object. The
    one field declared twice is the run's tangent (RUN_TANGENT, documented beside it)."""
    import inspect

    from granular_material.multiscale import (
        DEMDriving,
        DEMMaterial,
        DEMMaterialParameters,
        DEMParameters,
        DEMRVEs,
        InProcessBackend,
    )
    from granular_material.multiscale.run_hooks import RUN_TANGENT

    declared: dict[str, list[str]] = {}
    for cls in (DEMDriving, DEMRVEs, DEMMaterialParameters, DEMParameters):
        for name in inspect.get_annotations(cls):
            if not name.startswith("_") and name not in ("tangents", "drives",
                                                         "reuse_corrections",
                                                         "default_particles"):
                declared.setdefault(name, []).append(cls.__name__)
    twice = {name: where for name, where in declared.items() if len(where) > 1}
    assert twice == {"tangent": ["DEMDriving", "DEMParameters"]}
    assert DEMParameters().tangent == RUN_TANGENT != DEMDriving().tangent
    assert list(inspect.signature(DEMMaterial.__init__).parameters) == [
        "self", "parameters", "progress", "pressure", "settings"]
    assert list(inspect.signature(InProcessBackend.__init__).parameters) == [
        "self", "batch", "driving"]
    # the spec's fields and the material's share DEMRVEs' declarations, nothing else
    spec = {f.name for f in fields(DEMParameters)}
    material = {f.name for f in fields(DEMMaterialParameters)}
    assert spec & material == {f.name for f in fields(DEMRVEs)}
