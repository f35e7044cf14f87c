"""The checks of a run specification's fields beyond their types: tracked points,
post-processors, the device; and :class:`SpecError`, the error of a field that cannot run.
Every field is first conformed to its annotated type
(:mod:`granular_material.typed_fields`, re-exported here)."""

from __future__ import annotations

from granular_material.errors import ParameterError
from granular_material.typed_fields import (
    conform,
    conform_fields,
    conform_mapping,
    describe,
    field_types,
)

__all__ = ["SpecError", "check_device", "check_postprocess", "check_track", "conform",
           "conform_fields", "conform_mapping", "describe", "field_types"]


class SpecError(ParameterError):
    """A value of a run specification that cannot run; ``field`` is its flat name."""


def check_track(track: tuple[str, ...]) -> None:
    """Tracked points: ``("all",)`` or point ids, each a whole number >= 0, none twice."""
    if not track:
        raise SpecError("track", "must name point ids or 'all' (leave it out for none)")
    if "all" in track:
        if len(track) > 1:
            raise SpecError("track", f"takes point ids or 'all', not both, got {list(track)}")
        return
    bad = [t for t in track if not t.strip().isdigit()]
    if bad:
        raise SpecError("track", f"takes point ids (whole numbers >= 0) or 'all', got "
                                 f"{bad[0]!r}")
    if len({int(t) for t in track}) != len(track):
        raise SpecError("track", f"names a point twice: {list(track)}")


def check_postprocess(names: tuple[str, ...]) -> None:
    """Post-processors: installed ones, at least one."""
    from granular_material.fem.tracking import available_postprocessors

    known = available_postprocessors()
    if not names:
        raise SpecError("postprocess", "must name at least one post-processor (leave it out "
                                       "for every installed one)")
    unknown = [n for n in names if n not in known]
    if unknown:
        raise SpecError("postprocess", f"{unknown[0]!r} is no installed post-processor (they "
                                       f"are {', '.join(known) or 'none'})")


def check_device(device: str) -> None:
    """A device's form: cpu, cuda or cuda:N (whether CUDA is present is the run's check)."""
    if device in ("cpu", "cuda"):
        return
    if device.startswith("cuda:") and device[5:].isdigit():
        return
    raise SpecError("device", f"must be cpu, cuda or cuda:N, got {device!r}")
