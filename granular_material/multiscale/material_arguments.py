"""How :class:`~granular_material.multiscale.DEMMaterial` reads its arguments: its settings
as keywords or a :class:`~granular_material.multiscale.parameters.DEMMaterialParameters`, the
deprecated ``pressure``, and where its warnings point (the user's line)."""

from __future__ import annotations

from dataclasses import fields, replace
from pathlib import Path
from typing import Any

from granular_material.multiscale.parameters import DEMMaterialParameters
from granular_material.typed_fields import conform_mapping
from granular_material.vocabulary import renamed, user_stacklevel

__all__ = ["material_parameters", "user_stacklevel"]

#: the material's settings, by name (:class:`DEMMaterialParameters`' fields)
_SETTINGS = frozenset(f.name for f in fields(DEMMaterialParameters))


def material_parameters(given: DEMMaterialParameters | str | Path | None, pressure: float | None,
                settings: dict[str, Any]) -> DEMMaterialParameters:
    """The material's parameters of :class:`DEMMaterial`'s arguments."""
    unknown = sorted(set(settings) - _SETTINGS)
    if unknown:
        raise TypeError(f"DEMMaterial() got an unexpected keyword {unknown[0]!r} (its settings "
                        f"are {', '.join(sorted(_SETTINGS))})")
    if pressure is not None:  # its old name: warned, read as confining
        settings = renamed({**settings, "pressure": pressure}, "DEMMaterial")
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


