"""The run specification: what one FEM run is, typed and frozen, from the edge to the kernel.

A :class:`RunSpec` gathers the problem (:class:`ProblemSpec`), the Newton settings
(:class:`NewtonSpec`), the material (:class:`MaterialSpec`: an entry-point name and that
material's own typed parameters), the outputs (:class:`OutputSpec`) and where it runs
(device, CPU shards, backend). Every field has its default and its check here, once: first
by its annotated type (:mod:`~granular_material.runs.spec_checks`: a number finite, a count
whole, a pair of two, a name a string; a material's parameters by its ``Parameters``' own
annotations), then by its range; a value that cannot run is a :class:`SpecError` naming the
field, whether the spec is built in Python or read from TOML, JSON or the flat form. The
command line, the scenes, the presets and the checkpoints all build one
(:mod:`granular_material.runs.serial`), and :func:`granular_material.runs.run` runs it.

Field names are unique across the sections, so a field is also known by its bare name (its
*flat* name: ``axial_strain``), which is the command-line option (``--axial-strain``) and the
scene key (``axial-strain``). Units are SI; strains and the axial strain compression positive.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from granular_material.runs.spec_checks import (
    MAX_CUTBACKS,
    MAX_ITERATIONS,
    MAX_MAP_STRAINS,
    MAX_TRACKED_ROWS,
    SpecError,
    check_device,
)
from granular_material.runs.spec_sections import (
    BACKENDS,
    FULL_SCALE,
    REDUCED_SCALE,
    SCALES,
    TESTS,
    AdaptivitySpec,
    MaterialSpec,
    NewtonSpec,
    OutputSpec,
    ProblemSpec,
    RegularisationSpec,
    _at_least,
    _one_of,
    _typed,
)

__all__ = ["BACKENDS", "FULL_SCALE", "MAX_CUTBACKS", "MAX_ITERATIONS", "MAX_MAP_STRAINS",
           "MAX_TRACKED_ROWS", "REDUCED_SCALE", "SCALES", "TESTS", "AdaptivitySpec",
           "MaterialSpec", "NewtonSpec", "OutputSpec", "ProblemSpec", "RegularisationSpec",
           "RunSpec", "SpecError"]


@dataclass(frozen=True, kw_only=True)
class RunSpec:
    """One FEM run: problem, material, Newton settings, outputs and where it runs.

    Attributes:
        problem: the boundary-value problem.
        material: the material at the Gauss points.
        newton: the Newton solver.
        output: what is written.
        regularisation: the FEM's regularisation (none: the classical medium).
        adaptivity: a biaxial specimen of the DEM material modelled only where it requires
            it (:class:`AdaptivitySpec`): every point starts on the Mohr–Coulomb twin
            calibrated from the first point's RVE, and moves to its own RVE (the one an
            all-DEM run gives it) once a threshold is met; None: every point DEM (default).
        device: the DEM device, "cpu", "cuda" or "cuda:N"; None: CUDA where present.
        shards: CPU threads (shards) of a DEM batch; None: one per core.
        backend: "inprocess" or "mpi" (a material's points in shards on an MPI job's ranks).
        preset: the name of the preset whose values the spec took (a record; the values
            themselves are in the fields).
    """

    problem: ProblemSpec
    material: MaterialSpec
    newton: NewtonSpec = field(default_factory=NewtonSpec)
    output: OutputSpec = field(default_factory=OutputSpec)
    regularisation: RegularisationSpec = field(default_factory=RegularisationSpec)
    adaptivity: AdaptivitySpec | None = None
    device: str | None = None
    shards: int | None = None
    backend: str = "inprocess"
    preset: str | None = None

    def __post_init__(self) -> None:
        for name, kind in (("problem", ProblemSpec), ("material", MaterialSpec),
                           ("newton", NewtonSpec), ("output", OutputSpec),
                           ("regularisation", RegularisationSpec)):
            if not isinstance(getattr(self, name), kind):
                raise SpecError(name, f"must be a {kind.__name__}, got "
                                      f"{type(getattr(self, name)).__name__}")
        _typed(self)
        if self.device is not None:
            check_device(self.device)
        if self.preset is not None:
            from granular_material.runs.presets import PRESET_NAMES

            _one_of("preset", self.preset, PRESET_NAMES)
        _one_of("backend", self.backend, BACKENDS)
        self.regularisation.check_element(self.problem.element)
        if self.shards is not None:
            _at_least("shards", self.shards, 1)
        if self.backend != "inprocess" and not hasattr(self.material.cls, "launch"):
            raise SpecError("backend", f"{self.backend} needs a material that runs on it "
                                       f"(dem), not {self.material.name}")
        self._check_adaptivity()

    def _check_adaptivity(self) -> None:
        """SpecError naming ``adaptivity`` where it cannot act: another material than dem,
        a single element, the MPI backend, tracked points (their RVEs are not all held)."""
        a = self.adaptivity
        if a is None:
            return
        if not isinstance(a, AdaptivitySpec):
            raise SpecError("adaptivity", f"must be an AdaptivitySpec, got {type(a).__name__}")
        if self.material.name != "dem":
            raise SpecError("adaptivity", f"puts DEM RVEs where the twin of the dem material "
                                          f"is no longer trusted; it needs `material` dem, "
                                          f"not {self.material.name}")
        if self.problem.test != "biaxial":
            raise SpecError("adaptivity", f"is the biaxial specimen's, not the "
                                          f"{self.problem.test} test's")
        if self.backend != "inprocess":
            raise SpecError("adaptivity", f"holds its RVEs in this process, not on "
                                          f"`backend` {self.backend}")
        if self.output.track is not None:
            raise SpecError("adaptivity", "holds no RVE at a point still on its twin: "
                                          "`track` needs every point DEM (leave one out)")

    def replace(self, **sections: Any) -> RunSpec:
        """A copy with whole sections or run fields replaced (dataclasses.replace)."""
        return replace(self, **sections)
