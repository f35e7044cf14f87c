"""Files of the runs: CSV tables, JSON summaries and an XDMF time series for ParaView.

``steps.csv`` and ``points.csv`` of a biaxial run are written by :func:`write_tables` only,
whether whole at the end or step by step while the run goes (:class:`BiaxialWriter`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from granular_material.filesafe import write_whole
from granular_material.results.plots import plot_maps, plot_stress_strain

if TYPE_CHECKING:
    from granular_material.fem.problems import BiaxialProblem
    from granular_material.results.biaxial import BiaxialResult

__all__ = ["BiaxialWriter", "FieldWriter", "write_csv", "write_json", "write_outputs",
           "write_tables"]

_CELL_FIELDS = ("sxx", "syy", "sxy", "exx", "eyy", "exy", "volumetric_strain",
                "shear_strain", "void_ratio", "coordination")


def write_csv(frame: pd.DataFrame, path: str | Path, append: bool = False) -> Path:
    """Write ``frame`` to ``path`` without its index (its folder made if need be); a new file
    replaces the old one only once it is complete, and a failed write leaves no ``.part``
    behind. ``append`` adds the rows (no header) to an existing file instead."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a folder, not a CSV file")
    if append:
        try:
            frame.to_csv(path, index=False, mode="a", header=False)
        except OSError as exc:
            raise OSError(exc.errno, f"cannot add to {path}: {exc.strerror or exc}") from exc
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_whole(path, lambda tmp: frame.to_csv(tmp, index=False))


def write_json(data: Any, path: str | Path, indent: int = 2) -> Path:
    """Write ``data`` as JSON to ``path`` (values JSON cannot hold as their ``str``); a new
    file replaces the old one only once it is complete, and a failed write leaves no
    ``.part`` behind."""
    text = json.dumps(data, indent=indent, default=str) + "\n"
    return write_whole(path, lambda tmp: tmp.write_text(text))


def write_tables(steps: pd.DataFrame, points: pd.DataFrame, out_dir: str | Path,
                 append_points: bool = False) -> dict[str, Path]:
    """Write ``steps.csv`` and ``points.csv`` under ``out_dir``; returns their paths.

    ``append_points``: add the rows of ``points`` to the existing ``points.csv`` (a run that
    writes step by step) instead of writing the whole table.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"steps": out / "steps.csv", "points": out / "points.csv"}
    write_csv(steps, paths["steps"])
    write_csv(points, paths["points"], append=append_points)
    return paths


class FieldWriter:
    """XDMF time series (XML data, no HDF5 needed) of the mesh with per-step fields.

    A context manager: ``with FieldWriter(path, problem) as fields: fields.write(...)``.
    Cells: quad, quad8 or quad9, with every node of the element (midside and centre nodes
    of quad8 and quad9 included, see :meth:`BiaxialProblem.nodes`).
    Point data: ``displacement`` [m] (nnodes, 3). Cell data: element means of the
    Gauss-point columns named in ``_CELL_FIELDS`` that the table holds. Time = axial strain.
    """

    def __init__(self, path: str | Path, problem: BiaxialProblem) -> None:
        self.path = Path(path)
        self.problem = problem
        self._stack = ExitStack()
        self._writer: Any = None
        self._dofs: np.ndarray | None = None

    def __enter__(self) -> FieldWriter:
        import meshio

        self.path.parent.mkdir(parents=True, exist_ok=True)
        xy, cells, kind, self._dofs = self.problem.nodes()
        # meshio writes the whole file when it is closed: under a temporary name, renamed
        # into place by __exit__ (write_whole)
        self._writer = self._stack.enter_context(
            meshio.xdmf.TimeSeriesWriter(str(self.path) + ".part", data_format="XML")
        )
        points = np.column_stack([xy, np.zeros(xy.shape[0])])
        self._writer.write_points_cells(points, [(kind, cells.astype(np.int64))])
        return self

    def __exit__(self, *exc: object) -> None:
        write_whole(self.path, lambda tmp: self._stack.close())

    def write(self, time: float, u: np.ndarray, points: pd.DataFrame) -> None:
        """Append one step: nodal displacement ``u`` (ndofs,) and the Gauss-point table."""
        ux, uy = u[self._dofs[0]], u[self._dofs[1]]
        disp = np.column_stack([ux, uy, np.zeros_like(ux)])
        means = points.groupby("element").mean(numeric_only=True)
        cell_data = {k: [means[k].to_numpy(dtype=float)] for k in _CELL_FIELDS if k in means}
        self._writer.write_data(float(time), point_data={"displacement": disp},
                                cell_data=cell_data)


class BiaxialWriter:
    """Writes a biaxial run under ``out_dir`` while it goes: an observer of
    :func:`~granular_material.runs.run_biaxial`, used as a context manager::

        with BiaxialWriter(out) as writer:
            result = run_biaxial(setup, material, n_steps, observer=writer)

    Every step appends to the tables (a long run can be followed, and is not lost if it is
    stopped) and to ``fields.xdmf``; :meth:`finish` writes the tables once more, whole. The
    fields file is finished when the ``with`` block ends, however it ends.
    """

    def __init__(self, out_dir: str | Path) -> None:
        self.out_dir = Path(out_dir)
        self._stack = ExitStack()
        self._fields: FieldWriter | None = None
        self._rows: list[dict[str, Any]] = []
        self._tracked_any = False  # tracked.csv begun: later rows are appended

    def __enter__(self) -> BiaxialWriter:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()

    def start(self, problem: BiaxialProblem) -> None:
        """Open the fields file of ``problem``'s mesh."""
        self._fields = self._stack.enter_context(
            FieldWriter(self.out_dir / "fields.xdmf", problem)
        )
        self._rows = []
        self._tracked_any = False

    def record(self, row: dict[str, Any], points: pd.DataFrame, u: np.ndarray,
               tracked: pd.DataFrame | None = None) -> None:
        """One committed step: its ``steps`` row, its Gauss-point table, the displacement,
        its tracked rows (added to ``tracked.csv``)."""
        if self._fields is None:
            raise RuntimeError("BiaxialWriter.start(problem) must come before record()")
        self._rows.append(row)
        self._fields.write(row["axial_strain"], u, points)
        write_tables(pd.DataFrame(self._rows), points, self.out_dir,
                     append_points=len(self._rows) > 1)
        if tracked is not None and len(tracked):
            write_csv(tracked, self.out_dir / "tracked.csv", append=self._tracked_any)
            self._tracked_any = True

    def finish(self, result: BiaxialResult) -> None:
        """Write the whole tables of the run."""
        write_tables(result.steps, result.points, self.out_dir)
        if len(result.tracked):
            write_csv(result.tracked, self.out_dir / "tracked.csv")


def write_outputs(result: BiaxialResult, out_dir: str | Path,
                  map_strain: float | Sequence[float] | None = None,
                  reference: pd.DataFrame | None = None) -> dict[str, Path]:
    """Tables, the stress–strain figure and the maps figures under ``out_dir``.

    ``map_strain``: axial strain(s) of the maps; None: the last step. One strain gives
    ``maps.png``; several give ``maps_<strain in %>pct.png`` each (keys ``maps_<strain>``).
    ``fields.xdmf`` is the one a :class:`BiaxialWriter` wrote there during the run.
    """
    out = Path(out_dir)
    paths = write_tables(result.steps, result.points, out)
    if len(result.tracked):
        paths["tracked"] = write_csv(result.tracked, out / "tracked.csv")
    paths["stress_strain"] = plot_stress_strain(result.steps, out / "stress_strain.png",
                                                reference)
    if map_strain is None:
        map_strain = float(result.steps["axial_strain"].iloc[-1])
    strains = [float(map_strain)] if np.isscalar(map_strain) else [float(e) for e in map_strain]
    if len(strains) == 1:
        paths["maps"] = plot_maps(result, strains[0], out / "maps.png")
    else:
        for strain in strains:
            paths[f"maps_{strain:g}"] = plot_maps(result, strain,
                                                  out / f"maps_{100 * strain:.1f}pct.png")
    paths["fields"] = out / "fields.xdmf"
    return paths
