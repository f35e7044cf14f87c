"""Helpers shared by the FEM tests: test materials' committed strain, a unit element loaded
on top, a stop at a load step, tables without their clock times, the scene text of a block
pressed on top, a benchmark script imported as a module."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pandas as pd
from skfem import Basis, ElementQuad1, ElementVector, FacetBasis, LinearForm, MeshQuad

from granular_material.fem import Loading

#: a boundary-value scene's block held at its boundary ``{base}`` and pressed 1 mm on top,
#: linear-elastic at a uniform 20 kPa: its [[conditions]], [initial] and [material] (format
#: ``base``)
PRESSED_BLOCK = """[[conditions]]
type = "fixed"
boundary = "{base}"
[[conditions]]
type = "displacement"
boundary = "top"
component = "y"
value = -0.001
[initial]
state = "uniform"
pressure = 20e3
[material]
name = "linear-elastic"
[material.parameters]
young = 60e6
poisson = 0.3
"""

#: columns that hold clock times, which differ between equal runs
CLOCK = ("wall_time", "seconds", "timings")


def without_clock(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` without its clock-time columns."""
    return frame.drop(columns=[c for c in frame.columns if any(k in c for k in CLOCK)])


class StopAtStep:
    """``on_step`` callback of ``run_biaxial``: Ctrl-C once load step ``step`` is committed."""

    def __init__(self, step: int) -> None:
        self.step = step

    def __call__(self, solver, record, points) -> None:
        if record.step == self.step:
            raise KeyboardInterrupt


class StopAfterRecord:
    """A run observer (``runs.run``'s second argument): Ctrl-C once load step ``step`` is
    recorded."""

    def __init__(self, step: int) -> None:
        self.step = step

    def start(self, problem) -> None:
        pass

    def record(self, row, points, u, tracked=None) -> None:
        if row["step"] == self.step:
            raise KeyboardInterrupt

    def finish(self, result) -> None:
        pass


class CommittedStrain:
    """The state of a test material whose response depends on its committed total strain
    alone (n, 2, 2): allocate, commit, revert, checkpoint and restore. A subclass's
    ``evaluate`` reads ``self.strain`` and sets ``self.trial``."""

    def __init__(self) -> None:
        self.strain = np.zeros((0, 2, 2))
        self.trial: np.ndarray | None = None

    @property
    def n_points(self) -> int:
        return int(self.strain.shape[0])

    def allocate(self, n_points: int) -> None:
        self.strain = np.zeros((n_points, 2, 2))

    def commit(self) -> None:
        self.strain = self.trial

    def revert(self) -> None:
        self.trial = None

    def checkpoint(self, path) -> None:
        np.save(path, self.strain)

    def restore(self, path) -> None:
        self.strain = np.load(path)


@LinearForm
def _pressure(v, w):
    return -w.q * (w.n[0] * v[0] + w.n[1] * v[1])


def top_loaded_element(q: float) -> tuple[Basis, Loading]:
    """One unit Q4 on rollers at the bottom (one node pinned), pressure q [Pa] on top: its
    basis and loading."""
    mesh = MeshQuad()
    basis = Basis(mesh, ElementVector(ElementQuad1()), intorder=2)
    bottom = np.flatnonzero(mesh.p[1] == 0)
    dofs = np.concatenate([basis.nodal_dofs[1, bottom], basis.nodal_dofs[0, bottom[:1]]])
    top = FacetBasis(mesh, basis.elem, facets=mesh.facets_satisfying(lambda x: x[1] == 1),
                     intorder=2)
    force = _pressure.assemble(top, q=q)
    return basis, Loading(dofs, np.zeros(dofs.size), np.zeros(basis.N), force)


#: the benchmark scripts' folder
BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def benchmark_module(name: str) -> ModuleType:
    """``benchmarks/NAME.py`` imported as the module ``NAME`` (its folder on sys.path, for the
    modules beside it that it imports)."""
    if str(BENCHMARKS) not in sys.path:
        sys.path.insert(0, str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def run_table(folder: Path, name: str) -> pd.DataFrame:
    """Table ``name`` (``steps.csv``, ``points.csv``, ``tracked.csv``) of the run in
    ``folder``: the Gauss-point table as the run wrote it (``points.npy`` or ``points.csv``,
    :func:`~granular_material.results.read_points`), any other read from its CSV file."""
    from granular_material.results import read_points

    if name == "points.csv":
        return read_points(folder)
    return pd.read_csv(Path(folder) / name)
