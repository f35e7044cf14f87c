"""What a material is told of the run it is built for (:class:`RunContext`).

A material class that a run specification names may offer run hooks beside its
``Parameters`` (a frozen dataclass of its own parameters):

- ``check_run(parameters, context) -> int``: refuse, before any work, what cannot run
  (a :class:`~granular_material.errors.ParameterError` naming the parameter); returns the
  discs (or other units of memory, at :data:`granular_material.checks.DISC_BYTES` each)
  that one Gauss point will hold;
- ``for_run(parameters, context) -> Material``: the material, not yet allocated;
- ``run_summary(parameters, context) -> dict``: what the run's summary says of it;
- ``launch(backend, main) -> int``: run ``main`` with the material's points on ``backend``;
- ``reference_curve(axial_strain, confining, device, progress) -> DataFrame`` (a method),
  asked for where its parameters set ``compare_dem``: the material's own drained biaxial
  curve beside a single element (the DEM's: RVE 0 in pure DEM), kept in the checkpoint;
- ``noisy`` (class attribute): its stress carries noise (looser Newton defaults).

A material without them is built as ``cls(**parameters)`` and holds nothing the run
estimates.

It lives beside the :class:`~granular_material.fem.materials.protocol.Material` protocol, which it
extends: the run specification (:mod:`granular_material.runs`) fills it in, a material
reads it, and neither imports the other.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["RunContext"]


@dataclass(frozen=True)
class RunContext:
    """The run a material is built for.

    Attributes:
        test: "single-element" or "biaxial".
        n_points: Gauss points of the mesh.
        confining: confining pressure [Pa], compression positive.
        axial_strain: final axial strain [-], compression positive.
        steps: load steps.
        scale_discs: discs per RVE of the specimen's scale (None: a single element).
        device: the device chosen for the run ("cpu", "cuda:0", ...).
        shards: CPU shards of a batch (None: one per core).
        backend: "inprocess" or "mpi".
        progress: show progress bars.
        convergence: the Newton convergence test ("force", "displacement" or
            "residual-displacement").
    """

    test: str
    n_points: int
    confining: float
    axial_strain: float
    steps: int
    scale_discs: int | None
    device: str
    shards: int | None
    backend: str
    progress: bool
    convergence: str
