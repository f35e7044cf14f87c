"""The checks of a run specification's fields beyond their types: the bounds of what a user
can make long (map strains, Newton cut-backs and iterations, tracked rows), tracked points,
post-processors, the device; and :class:`SpecError`, the error of a field that cannot run.
Every field is first conformed to its annotated type
(:mod:`granular_material.typed_fields`, re-exported here)."""

from __future__ import annotations

from granular_material.errors import ParameterError
from granular_material.fem.solver.settings import MAX_CUTBACKS
from granular_material.typed_fields import (
    conform,
    conform_fields,
    conform_mapping,
    describe,
    field_types,
)

__all__ = ["MAX_CUTBACKS", "MAX_ITERATIONS", "MAX_MAP_STRAINS", "MAX_TRACKED_ROWS",
           "SpecError", "check_device", "check_map_strains", "check_newton_bounds",
           "check_postprocess", "check_track", "conform", "conform_fields", "conform_mapping",
           "describe", "field_types"]


#: seconds of figures one map strain costs, about (the estimate of a refusal)
_MAP_SECONDS = 1.5
#: the most Newton iterations of an increment (the commands' default is 25)
MAX_ITERATIONS = 10_000
#: the most map strains a run draws: each is a displacement and a shear-strain map and a
#: band measure (20 strains added 30 s to the outputs of a 5 × 10 linear-elastic specimen,
#: and 29 s to a single element's, on a shared 2-core machine)
MAX_MAP_STRAINS = 20
#: the most tracked rows (points × post-processors × tracked steps) a run computes; each is
#: a post-processing of one RVE (up to seconds for the pore fractal of a 400-disc RVE)
MAX_TRACKED_ROWS = 100_000


class SpecError(ParameterError):
    """A value of a run specification that cannot run; ``field`` is its flat name."""


def check_newton_bounds(max_cutbacks: int, max_iterations: int) -> None:
    """Cut-backs and iterations of an increment within :data:`MAX_CUTBACKS` and
    :data:`MAX_ITERATIONS`."""
    if max_cutbacks > MAX_CUTBACKS:
        raise SpecError("max_cutbacks", f"must be at most {MAX_CUTBACKS}: the smallest "
                                        f"increment, 2^-{max_cutbacks} of a step, is below "
                                        "what a float load factor can tell apart, got "
                                        f"{max_cutbacks}")
    if max_iterations > MAX_ITERATIONS:
        raise SpecError("max_iterations", f"must be at most {MAX_ITERATIONS} material "
                                          "evaluations an increment (each a DEM run of every "
                                          f"point), got {max_iterations}")


def check_map_strains(map_strain: tuple[float, ...]) -> None:
    """Map strains: 1 to :data:`MAX_MAP_STRAINS` of them (refused with the estimate)."""
    if not map_strain:
        raise SpecError("map_strain", "must name at least one axial strain")
    if len(map_strain) > MAX_MAP_STRAINS:
        raise SpecError("map_strain", f"names {len(map_strain)} strains, at most "
                                      f"{MAX_MAP_STRAINS}: each is two maps and a band "
                                      f"measure, about {_MAP_SECONDS:g} s of figures "
                                      f"(~{len(map_strain) * _MAP_SECONDS:.0f} s in all)")


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
