"""The FEM commands' choice of material and the options of the continuum materials: the
linear-elastic moduli and the Mohr–Coulomb strength, or a material file (what
``granular-material calibrate`` writes).

The options are the run parameters' names (:class:`LinearElasticRunParameters`,
:class:`MohrCoulombRunParameters`) in kebab-case: ``--young`` [Pa], ``--poisson``,
``--friction-angle``, ``--dilation-angle``, ``--critical-friction-angle`` [degrees],
``--cohesion`` [Pa], ``--softening-strain``; the contacts' friction of the RVEs is
``--contact-friction-angle`` [rad]. The old ``--E``, ``--nu``, ``--phi``, ``--psi`` and
``--phi-cs`` are still read (hidden from the help), renamed with a warning by
:func:`granular_material.vocabulary.renamed` where the material is known.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

from granular_material.cli.options import UsageError
from granular_material.fem import available_materials, load_material
from granular_material.fem.materials.linear_elastic import LinearElasticRunParameters
from granular_material.fem.materials.mohr_coulomb import MohrCoulombRunParameters
from granular_material.vocabulary import renamed, renames

__all__ = ["MATERIAL_OPTIONS", "OLD_MATERIAL_OPTIONS", "add_material_arguments",
           "check_material_options", "material_file_values"]

_ELASTIC = LinearElasticRunParameters()
_MC = MohrCoulombRunParameters()
#: the continuum materials' options (their destinations: the run parameters' names)
MATERIAL_OPTIONS = ("young", "poisson", "friction_angle", "dilation_angle", "cohesion",
                    "critical_friction_angle", "softening_strain")
#: their old names (hidden options, read as the new ones with a warning): the continuum
#: materials' renames of :data:`granular_material.vocabulary.RENAMED`
OLD_MATERIAL_OPTIONS = tuple(dict.fromkeys(
    [*renames("mohr-coulomb"), *renames("linear-elastic")]))
#: the tables of a material file that describe how it was made (not parameters)
_RECORD_TABLES = frozenset({"calibration"})


def add_material_arguments(parser: argparse.ArgumentParser, default: str) -> None:
    """``--material`` (default ``default``), the continuum materials' options and
    ``--material-file``. The options default to None (the material's own default, shown
    in the help), so that one given at its default value still counts as given: it wins
    over the material file and is refused with a material that has no such parameter."""
    parser.add_argument("--material", choices=available_materials(), default=default,
                        help=f"material at the Gauss points (default {default})")
    g = parser.add_argument_group(
        "continuum materials", "linear-elastic and mohr-coulomb: moduli; mohr-coulomb: "
        "strength (angles in degrees; the RVEs' --contact-friction-angle is in rad)")
    g.add_argument("--young", type=float, default=None, metavar="PA",
                   help=f"Young's modulus [Pa] (default {_ELASTIC.young:g})")
    g.add_argument("--poisson", type=float, default=None, metavar="NU",
                   help=f"Poisson's ratio [-] (default {_ELASTIC.poisson:g})")
    g.add_argument("--friction-angle", type=float, default=None, metavar="DEG",
                   help="mohr-coulomb: peak friction angle [deg] (default "
                        f"{_MC.friction_angle:g})")
    g.add_argument("--dilation-angle", type=float, default=None, metavar="DEG",
                   help=f"mohr-coulomb: dilation angle [deg] (default {_MC.dilation_angle:g})")
    g.add_argument("--cohesion", type=float, default=None, metavar="PA",
                   help=f"mohr-coulomb: cohesion [Pa] (default {_MC.cohesion:g})")
    g.add_argument("--critical-friction-angle", type=float, default=None, metavar="DEG",
                   help="mohr-coulomb: critical-state friction angle [deg] that "
                        "--friction-angle softens to (default: no softening)")
    g.add_argument("--softening-strain", type=float, default=None,
                   help="mohr-coulomb: plastic shear strain [-] over which --friction-angle "
                        "softens to --critical-friction-angle and --dilation-angle to 0 "
                        f"(default {_MC.softening_strain:g})")
    for old in OLD_MATERIAL_OPTIONS:  # deprecated, not shown: read as the new ones
        parser.add_argument("--" + old.replace("_", "-"), type=float, default=None,
                            help=argparse.SUPPRESS)
    g.add_argument("--material-file", type=Path, default=None, metavar="FILE",
                   help="the material's parameters from a TOML file (what `granular-material "
                        "calibrate` writes); options given beside it win")


def material_file_values(path: Path, material: str) -> dict[str, Any]:
    """The parameters of ``material`` in the TOML file ``path`` (its top-level keys; a
    ``[calibration]`` table is a record, skipped); a UsageError names what cannot be used."""
    if not Path(path).is_file():
        raise UsageError(f"--material-file {path} does not exist")
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise UsageError(f"--material-file {path} cannot be read: {exc}") from None
    kind = getattr(load_material(material), "Parameters", None)
    known = set() if kind is None else set(kind.__dataclass_fields__)
    values = renamed({k: v for k, v in data.items() if k not in _RECORD_TABLES}, material)
    unknown = sorted(set(values) - known)
    if unknown:
        raise UsageError(f"--material-file {path}: {unknown[0]!r} is no parameter of "
                         f"--material {material} (it has {', '.join(sorted(known)) or 'none'})")
    return values


def check_material_options(material: str, given: Mapping[str, Any]) -> None:
    """A continuum material's option given with a material that has no such parameter is
    refused (e.g. ``--dilation-angle`` with ``--material dem``); ``given`` is read with the
    material's renames (:func:`granular_material.vocabulary.renamed`) first."""
    kind = getattr(load_material(material), "Parameters", None)
    own = set() if kind is None else set(kind.__dataclass_fields__)
    foreign = [k for k in given if k in (*MATERIAL_OPTIONS, *OLD_MATERIAL_OPTIONS)
               and k not in own]
    if foreign:
        flags = ", ".join("--" + k.replace("_", "-") for k in foreign)
        raise UsageError(f"{flags} {'is' if len(foreign) == 1 else 'are'} no option of "
                         f"--material {material}")
