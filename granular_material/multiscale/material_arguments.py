"""How :class:`~granular_material.multiscale.DEMMaterial` reads its arguments: its settings
as keywords or a :class:`~granular_material.multiscale.parameters.DEMMaterialParameters`, the
deprecated ``pressure``, and where its warnings point (the user's line)."""

from __future__ import annotations

import os
import sys
import warnings
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

from granular_material.errors import ParameterError
from granular_material.multiscale.parameters import DEMMaterialParameters
from granular_material.typed_fields import conform_mapping

__all__ = ["material_parameters", "user_stacklevel"]

#: the material's settings, by name (:class:`DEMMaterialParameters`' fields)
_SETTINGS = frozenset(f.name for f in fields(DEMMaterialParameters))


def user_stacklevel() -> int:
    """The ``stacklevel`` of a warning issued by the caller of this function that points at
    the first frame outside granular_material (the user's line)."""
    import granular_material

    root = os.path.dirname(granular_material.__file__) + os.sep
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_code.co_filename.startswith(root):
        frame, level = frame.f_back, level + 1
    return level


def material_parameters(given: DEMMaterialParameters | str | Path | None, pressure: float | None,
                settings: dict[str, Any]) -> DEMMaterialParameters:
    """The material's parameters of :class:`DEMMaterial`'s arguments."""
    unknown = sorted(set(settings) - _SETTINGS)
    if unknown:
        raise TypeError(f"DEMMaterial() got an unexpected keyword {unknown[0]!r} (its settings "
                        f"are {', '.join(sorted(_SETTINGS))})")
    if pressure is not None:
        if "confining" in settings:
            raise ParameterError("confining", "is given twice: give confining (pressure is "
                                              "its deprecated name), not both")
        warnings.warn("DEMMaterial(pressure=...) is deprecated: call it confining= (the "
                      "run specification's and the command line's name)",
                      DeprecationWarning, stacklevel=user_stacklevel())
        settings = {**settings, "confining": pressure}
    # types, named (the initial stress array has its own check, which says more)
    settings = {**settings, **conform_mapping(DEMMaterialParameters, {
        k: v for k, v in settings.items() if k != "initial_stress"})}
    if isinstance(given, DEMMaterialParameters):
        return replace(given, **settings) if settings else given
    if given is not None:  # the RVE file, the first positional argument of old
        settings = {**settings, **conform_mapping(DEMMaterialParameters, {"rve": given})}
    if settings.get("packing") is None:
        settings.pop("packing", None)
    return DEMMaterialParameters(**settings)


