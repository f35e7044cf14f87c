"""Post-processing on demand: named post-processors run on chosen Gauss points, every k steps.

Post-processors are found by name in the ``granular_material.postprocessors`` entry-point
group (e.g. ``pore-fractal`` of the pore fractal plugin). Each is a callable
``f(data: RVEData, rve_index: int) -> dict[str, float]`` of one RVE of a batch. A run asks for
some of them on some points (``--track``) every ``every`` committed load steps (``--every``,
step 0, the initial state, included); nothing else is computed. Rows go to ``tracked.csv``:
step, axial_strain, point, postprocessor, seconds (the call's cost), then the values.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import pandas as pd

from granular_material.entry_points import entry_point_names, load_entry_point
from granular_material.errors import ParameterError

__all__ = [
    "POSTPROCESSOR_GROUP",
    "PostProcessor",
    "Tracking",
    "available_postprocessors",
    "load_postprocessor",
]

POSTPROCESSOR_GROUP = "granular_material.postprocessors"

#: a post-processor: the values of RVE ``rve_index`` of an RVE batch
PostProcessor = Callable[[Any, int], dict[str, float]]


class TrackedMaterial(Protocol):
    """A material whose Gauss points carry RVEs (e.g. the DEM material)."""

    def committed_rves(self, points: Any = None) -> Any:
        """The committed RVE states of the point indices ``points``."""
        ...


def available_postprocessors() -> list[str]:
    """Names registered in the ``granular_material.postprocessors`` entry-point group."""
    return entry_point_names(POSTPROCESSOR_GROUP)


def load_postprocessor(name: str) -> PostProcessor:
    """The post-processor registered under ``name``; ``ValueError`` naming the choices."""
    return load_entry_point(POSTPROCESSOR_GROUP, name, "post-processor")


@dataclass(frozen=True)
class Tracking:
    """Which post-processors run on which Gauss points, and how often.

    Attributes:
        postprocessors: entry-point names, at least one.
        points: Gauss point indices (``element * nqp + q``), or None for all points.
        every: run on committed load steps 0, every, 2·every, … (>= 1).
    """

    postprocessors: tuple[str, ...]
    points: tuple[int, ...] | None = None
    every: int = 1

    def __post_init__(self) -> None:
        if not self.postprocessors:
            raise ValueError("tracking needs at least one post-processor")
        for name in self.postprocessors:
            load_postprocessor(name)  # unknown names fail before any work
        if int(self.every) != self.every or self.every < 1:
            raise ValueError(f"every must be an integer >= 1, got {self.every!r}")
        if self.points is not None:
            if not self.points:
                raise ValueError("track at least one point (or all)")
            if min(self.points) < 0:
                raise ValueError(f"point ids must be >= 0, got {min(self.points)}")

    @classmethod
    def parse(cls, postprocessors: Sequence[str], track: Sequence[str],
              every: int) -> Tracking:
        """From command-line values: ``track`` holds point ids or the word ``all``."""
        if any(t == "all" for t in track):
            if len(track) > 1:
                raise ParameterError("track", "takes point ids or 'all', not both")
            return cls(tuple(postprocessors), None, every)
        try:
            points = tuple(int(t) for t in track)
        except ValueError as exc:
            raise ParameterError("track", f"takes point ids or 'all', got {list(track)}"
                                 ) from exc
        return cls(tuple(postprocessors), points, every)

    def check_points(self, n_points: int) -> None:
        """``ValueError`` when a tracked point is not a Gauss point of the mesh."""
        if self.points is not None and max(self.points) >= n_points:
            raise ValueError(f"tracked point {max(self.points)} does not exist: the mesh has "
                             f"{n_points} Gauss points (0…{n_points - 1})")

    def due(self, step: int) -> bool:
        """Whether committed load step ``step`` is tracked."""
        return step % self.every == 0

    def rows(self, material: TrackedMaterial, step: int, axial_strain: float,
             n_points: int) -> pd.DataFrame:
        """The tracked values at this committed step, one row per point and post-processor."""
        if not hasattr(material, "committed_rves"):
            raise TypeError("tracking needs a material whose points carry RVEs (dem)")
        points = list(range(n_points)) if self.points is None else list(self.points)
        data = material.committed_rves(points)
        rows = []
        for name in self.postprocessors:
            function = load_postprocessor(name)
            for index, point in enumerate(points):
                t0 = time.perf_counter()
                values = function(data, index)
                rows.append({"step": step, "axial_strain": axial_strain, "point": point,
                             "postprocessor": name, "seconds": time.perf_counter() - t0,
                             **values})
        return pd.DataFrame(rows)
