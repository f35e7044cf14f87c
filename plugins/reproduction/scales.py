"""The sizes of a reproduction (``--scale smoke|cpu|paper``).

``paper`` is Wu et al.'s study at full size (for a GPU); ``cpu`` keeps every part of it but
reduces what a 2-core workstation cannot run in about an hour (the specimen's mesh and
RVEs, the strain per DEM step, the batches of the speed-up); ``smoke`` runs every part at a
toy size, for the tests. What each scale reduces is written into the report.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from granular_material.procedures.element_tests import DEFAULT_AXIAL_STRAIN
from granular_material.procedures.packing import DEFAULT_PRESSURE
from granular_material.procedures.strain_path import DEFAULT_STRAIN_PER_STEP

__all__ = ["SCALES", "ReproductionScale"]


@dataclass(frozen=True)
class ReproductionScale:
    """The sizes of one reproduction.

    Attributes:
        name: smoke, cpu or paper.
        sizes: RVE sizes of Figs. 3–4 [discs] (Wu et al.: 10², 12², …, 30²).
        seeds: packings of each size (Wu et al.: 5).
        void_ratio: e0 the random gas is compacted to before consolidation [-].
        pressure: consolidation pressure p0 and confining pressure [Pa].
        biaxial_sizes: sizes of Fig. 5 [discs] (a subset of ``sizes``).
        dem_axial_strain: axial strain of the pure-DEM biaxial tests [-].
        dem_strain_per_step: axial strain per DEM step of the pure-DEM tests [-].
        element_discs: discs of the single element's RVE (Fig. 6).
        element_steps: load steps of the single element to ``fem_axial_strain``.
        specimen_elements: (nx, ny) Q4 elements of the 50 × 100 mm specimen (Figs. 7–10).
        specimen_discs: discs of each of its RVEs (one packing per Gauss point).
        specimen_steps: load steps of the specimen to ``fem_axial_strain``.
        fem_axial_strain: final axial strain of the FEM × DEM runs [-].
        map_strain: axial strain of the maps and shear-band measures (Wu et al.: 2 %).
        track_every: load steps between pore-fractal analyses of every Gauss point's RVE.
        resolution_discs: RVE size of the resolution study [discs] (one of ``sizes``).
        speedup_sizes: RVE sizes of Fig. 11 [discs] (a subset of ``sizes``).
        speedup_batches: numbers of RVEs of Fig. 11.
        speedup_steps: DEM steps timed per case (the paper times 10⁴; fewer are scaled).
        yade_steps: DEM steps of the YADE rate (0: not measured).
        repeats: timings per speed-up case (the median is kept).
    """

    name: str
    sizes: tuple[int, ...]
    seeds: tuple[int, ...]
    biaxial_sizes: tuple[int, ...]
    dem_axial_strain: float
    dem_strain_per_step: float
    element_discs: int
    element_steps: int
    specimen_elements: tuple[int, int]
    specimen_discs: int
    specimen_steps: int
    fem_axial_strain: float
    map_strain: float
    track_every: int
    speedup_sizes: tuple[int, ...]
    speedup_batches: tuple[int, ...]
    speedup_steps: int
    yade_steps: int
    repeats: int = 3
    resolution_discs: int = 400
    void_ratio: float = 0.18
    pressure: float = DEFAULT_PRESSURE

    def __post_init__(self) -> None:
        for name in ("biaxial_sizes", "speedup_sizes"):
            if not set(getattr(self, name)) <= set(self.sizes):
                raise ValueError(f"{name} must be among the sizes {self.sizes} (the same "
                                 "RVEs)")
        for name in ("element_discs", "resolution_discs"):
            if getattr(self, name) not in self.sizes:
                raise ValueError(f"{name} must be among the sizes {self.sizes}")
        if len(self.seeds) < 2:
            raise ValueError("a reproduction needs at least two seeds (a scatter)")


SCALES: dict[str, ReproductionScale] = {
    "smoke": ReproductionScale(
        name="smoke", sizes=(16, 25, 36), seeds=(1, 2), biaxial_sizes=(16, 36),
        dem_axial_strain=0.02, dem_strain_per_step=1.0e-4, element_discs=16,
        element_steps=3, specimen_elements=(1, 2), specimen_discs=16, specimen_steps=3,
        fem_axial_strain=0.015, map_strain=0.01, track_every=1, speedup_sizes=(16,),
        speedup_batches=(1, 4), speedup_steps=200, yade_steps=0, repeats=1,
        resolution_discs=36,
    ),
    "cpu": ReproductionScale(
        name="cpu", sizes=tuple(side * side for side in range(10, 31, 2)),
        seeds=(1, 2, 3, 4, 5), biaxial_sizes=(100, 256, 400, 676, 900),
        dem_axial_strain=DEFAULT_AXIAL_STRAIN, dem_strain_per_step=DEFAULT_STRAIN_PER_STEP,
        element_discs=400, element_steps=50,
        specimen_elements=(5, 10), specimen_discs=100, specimen_steps=50,
        fem_axial_strain=0.05, map_strain=0.02, track_every=5, speedup_sizes=(100, 400, 900),
        speedup_batches=(1, 2, 4, 8, 16, 32, 64), speedup_steps=500, yade_steps=2000,
    ),
}

#: Wu et al.'s own sizes: 10 × 15 elements of 400-disc RVEs (600 Gauss points), 10⁻⁶ strain
#: per DEM step in the pure-DEM tests, 10⁴ timed DEM steps, batches up to 4096 RVEs
SCALES["paper"] = replace(
    SCALES["cpu"], name="paper", dem_strain_per_step=1.0e-6, element_steps=100,
    specimen_elements=(10, 15), specimen_discs=400, specimen_steps=100,
    fem_axial_strain=0.1, track_every=4,
    speedup_batches=(1, 4, 16, 64, 256, 1024, 4096), speedup_steps=10_000, yade_steps=5000,
)
