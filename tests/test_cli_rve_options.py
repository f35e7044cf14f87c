"""The FEM commands' RVE material options default to None (issue 43): one given at its
default value still counts as given, so beside a material that prepares no RVEs (or an RVE
file, which carries its own) it is refused, and a DEM run that gives none gets the
material's defaults, as before."""

from __future__ import annotations

import pytest

from granular_material.checks import RVE_MATERIAL_DEFAULTS
from granular_material.cli import build_parser
from granular_material.cli.fem import spec_from_args
from granular_material.cli.options import UsageError
from granular_material.multiscale.run_hooks import DEMParameters


def _spec(*argv: str):
    args = build_parser(argv[0]).parse_args([*argv, "--no-progress"])
    return spec_from_args(args)


@pytest.mark.parametrize("material", ["mohr-coulomb", "linear-elastic"])
@pytest.mark.parametrize("command", ["single-element", "biaxial"])
def test_an_rve_option_at_its_default_is_refused_beside_a_continuum(command, material):
    default = RVE_MATERIAL_DEFAULTS["contact_friction_angle"]
    with pytest.raises(UsageError, match=rf"^--contact-friction-angle sets the material of the "
                                         rf"RVEs a run prepares, but --material {material} "):
        _spec(command, "--material", material, "--contact-friction-angle", str(default))


def test_an_rve_option_at_its_default_is_refused_beside_an_rve_file(small_rve_path):
    with pytest.raises(UsageError, match=rf"^--kn sets the material of the RVEs a run "
                                         rf"prepares, but --rve {small_rve_path} carries"):
        _spec("single-element", "--rve", str(small_rve_path), "--kn",
              str(RVE_MATERIAL_DEFAULTS["kn"]))


def test_a_dem_run_without_rve_options_gets_the_materials_defaults():
    parameters = _spec("single-element").material.parameters
    assert isinstance(parameters, DEMParameters)
    for name, default in RVE_MATERIAL_DEFAULTS.items():
        assert getattr(parameters, name) == default, name
    given = _spec("single-element", "--contact-friction-angle", "0.3").material.parameters
    assert given.contact_friction_angle == 0.3 and given.kn == RVE_MATERIAL_DEFAULTS["kn"]
