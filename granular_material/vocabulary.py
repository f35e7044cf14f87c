"""One name per quantity: the names that were renamed, old → new, in one table, and the one
way an old name is still read (for one release, with a deprecation naming the new one).

Where an old name is read depends on the material: the DEM material's old ``friction_angle``
(the contacts' friction [rad]) is now ``contact_friction_angle``, while Mohr–Coulomb's
``friction_angle`` (the soil's φ [°]) is the new name of its old ``phi``. So each rename
belongs to a *context* (:data:`RENAMED`): a material's parameters (its entry-point name:
its run specification's fields, its command-line options and scene keys, its material
file), never read in another, so that no radian value is ever read as degrees.

Scene keys are snake_case (``axial_strain``), as the Python names and the run
specification's; command-line options are the same names in kebab-case, mapped mechanically
(:func:`key_of`; the other way is the command line's own,
:func:`granular_material.cli.options.flag_of`). A scene key written in kebab-case is the
deprecated spelling of its snake_case key. A warning names the fields in backquotes, which
the command line shows as its options.
"""

from __future__ import annotations

import functools
import os
import sys
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

from granular_material.errors import ParameterError

__all__ = ["RENAMED", "Rename", "RenamedWarning", "accept_old_keywords", "key_of", "renamed",
           "renames", "user_stacklevel", "warn_renamed"]


class RenamedWarning(DeprecationWarning):
    """A parameter, scene key, run-specification field or option given under its old name
    (read as the new one until the next release). The command line shows it as a
    ``warning:`` line on stderr."""


@dataclass(frozen=True)
class Rename:
    """One renamed quantity: ``old`` → ``new`` (Python / scene / spec names; options are
    their kebab-case), its unit and what it is."""

    old: str
    new: str
    unit: str
    meaning: str


_E = Rename("E", "young", "Pa", "Young's modulus of the continuum")
_NU = Rename("nu", "poisson", "-", "Poisson's ratio of the continuum")

#: the renames by context: a material's entry-point name (its parameters, options, scene
#: keys, spec fields and material file)
RENAMED: dict[str, tuple[Rename, ...]] = {
    "dem": (
        Rename("friction_angle", "contact_friction_angle", "rad",
               "the contacts' friction angle of the RVEs' discs, μ = tan of it"),
        Rename("young", "contact_young", "Pa",
               "law frictmat: the discs' Young's modulus that sets the contact stiffness "
               "kn = 2E·r1·r2/(r1 + r2) (not a continuum's modulus)"),
    ),
    "mohr-coulomb": (
        _E, _NU,
        Rename("phi", "friction_angle", "deg", "peak friction angle φ of the soil"),
        Rename("psi", "dilation_angle", "deg", "peak dilation angle ψ"),
        Rename("phi_cs", "critical_friction_angle", "deg",
               "critical-state friction angle φcs that φ softens to"),
    ),
    "linear-elastic": (_E, _NU),
    # a Python keyword of DEMMaterial (the run specification's and the commands' name)
    "DEMMaterial": (Rename("pressure", "confining", "Pa",
                           "isotropic pressure the prepared RVEs are consolidated at"),),
    # granular-material calibrate and calibrate_mohr_coulomb
    "calibrate": (Rename("pressure", "confining", "Pa",
                         "confining pressure P of the drained biaxial tests"),),
}
#: how a warning names whose an old name is, by context (default: the material's)
_WHOSE = {"DEMMaterial": "DEMMaterial's", "calibrate": "calibrate's"}


def renames(context: str) -> dict[str, Rename]:
    """The renames of ``context`` by their old name (empty for a context without any)."""
    return {r.old: r for r in RENAMED.get(context, ())}


def key_of(name: str) -> str:
    """The scene key / Python name of an option or a kebab-case key:
    ``--axial-strain`` or ``axial-strain`` → ``axial_strain``."""
    return name.removeprefix("--").replace("-", "_")


def user_stacklevel() -> int:
    """The ``stacklevel`` of a warning issued by the caller of this function that points at
    the first frame outside granular_material (the user's line)."""
    root = os.path.dirname(os.path.abspath(__file__)) + os.sep
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_code.co_filename.startswith(root):
        frame, level = frame.f_back, level + 1
    return level


def warn_renamed(old: str, new: str, what: str = "", note: str = "") -> None:
    """Issue the :class:`RenamedWarning` of ``old`` read as ``new`` (``what``: whose name it
    is, e.g. "the dem material's"; ``note``: the unit and meaning)."""
    whose = f"{what} " if what else ""
    said = f" ({note})" if note else ""
    warnings.warn(f"{whose}`{old}` is deprecated: it is now `{new}`{said}; the old name is "
                  "read until the next release", RenamedWarning, stacklevel=user_stacklevel())


def renamed(values: Mapping[str, Any], context: str, *, warn: bool = True,
            given: Callable[[Any], bool] | None = None) -> dict[str, Any]:
    """``values`` (names → values) with the old names of ``context`` (:data:`RENAMED`) read
    as their new ones, each with a :class:`RenamedWarning` unless ``warn`` is False (a saved
    checkpoint the user did not write). An old name given beside its new one is a
    ParameterError naming the new one; ``given`` (default: every value) says which values
    count as given (e.g. not None: an option left out)."""
    table = renames(context)
    counts = given or (lambda value: True)
    out = dict(values)
    for old, rename in table.items():
        if old not in out or old == rename.new:
            continue
        value = out.pop(old)
        if not counts(value):
            continue
        if rename.new in out and counts(out[rename.new]):
            raise ParameterError(rename.new, f"is given twice: also under its old name "
                                             f"`{old}`; give `{rename.new}`, not both")
        if warn:
            warn_renamed(old, rename.new, _WHOSE.get(context, f"the {context} material's"),
                         f"[{rename.unit}], {rename.meaning}")
        out[rename.new] = value
    return out


_C = TypeVar("_C", bound=type)


def accept_old_keywords(context: str) -> Callable[[_C], _C]:
    """Class decorator of a parameters dataclass: its ``__init__`` also takes the old
    keywords of ``context`` (:func:`renamed`: read as the new ones, with a
    :class:`RenamedWarning`). Its fields and signature are the new names'."""
    def decorate(cls: _C) -> _C:
        init = cls.__init__

        @functools.wraps(init)
        def init_renamed(self: Any, *args: Any, **kwargs: Any) -> None:
            if renames(context).keys() & kwargs.keys():
                kwargs = renamed(kwargs, context)
            init(self, *args, **kwargs)

        cls.__init__ = init_renamed  # type: ignore[misc]
        return cls
    return decorate
