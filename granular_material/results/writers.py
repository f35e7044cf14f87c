"""Files of the runs: CSV tables, the Gauss-point table of records, JSON summaries and an
XDMF time series for ParaView (:class:`FieldWriter`: ``fields.xdmf``, its values in
``fields.h5``).

``steps.csv`` and the Gauss-point table (``points.npy``, a NumPy file of records:
:mod:`~granular_material.results.point_table`; also ``points.csv`` on request) of a biaxial
run are written by :func:`write_tables` only, whether whole at the end or step by step while
the run goes (:class:`BiaxialWriter`); :func:`read_points` reads either.

A table that grows while a run goes is whole on disk at every step. Its rows are appended by
:func:`append_csv`: the step's rows in one write after the table's last whole row, taken
back (truncated) when the write fails, so that only a process killed outright (SIGKILL, power
lost) can cut a row; a header of other columns rewrites the table whole (the union). A
killed process loses nothing it wrote (the kernel holds it); against a power cut a
:class:`BiaxialWriter` flushes its tables to the disk (``fsync``) with the first step that
ends :data:`SYNC_SECONDS` after the last flush, points before steps, and when the run ends
(an ``fsync`` at every step cost 1–4 ms a table on a shared disk, more than formatting a
128-point step). A step writes ``tracked.csv`` and its points first and its
``steps.csv`` row last: a step is committed once that row is whole. :func:`read_table`
leaves a cut last row out, and :func:`read_run_tables` also the rows of steps ``steps.csv``
does not hold. A resumed run writes its tables anew from its checkpoint. The appended tables
are the run's whole tables: nothing writes them again at the end (issue 62), and a step's
rows of numbers are formatted by :func:`format_rows`, pandas' text at about a third of its
cost, a column that repeats from step to step (the points' coordinates) formatted once.

Measured by writing the tables of 1000 steps (median of 3, a 2-core machine shared
with other work, so seconds vary; ratios are of one run): ``steps.csv`` rewritten whole
every step took 27–102 s over the run, appended 5.4 s (102 s in that run); a 4-point
``points.csv`` appended 3.8 s (0.6 s without the ``fsync``), rewritten whole 87 s; a
400-point one appended 19 s (14 s without the ``fsync``).
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import time
from collections.abc import Iterator, Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from granular_material.filesafe import deferred_signals, write_whole
from granular_material.results.plots import plot_maps, plot_stress_strain
from granular_material.results.point_table import append_npy, read_npy_table, write_npy_table

if TYPE_CHECKING:
    from granular_material.fem.boundary_value.biaxial import BiaxialProblem
    from granular_material.results.biaxial import BiaxialResult

__all__ = ["BiaxialWriter", "FieldWriter", "SyncClock", "append_csv", "cell_means", "format_rows",
           "read_points", "read_run_tables", "read_table", "strict_json", "sync_files",
           "write_csv", "write_json", "write_outputs", "write_points", "write_tables"]

_CELL_FIELDS = ("sxx", "syy", "sxy", "exx", "eyy", "exy", "volumetric_strain",
                "shear_strain", "rotation", "mean_pressure", "unconfined", "failed",
                "void_ratio", "coordination", "stress_zz", "plastic_shear_strain",
                "friction_angle", "return_region", "dem")


#: a :class:`BiaxialWriter` flushes its growing tables to the disk once this many seconds
#: have passed since it last did, and at the run's end [s]
SYNC_SECONDS = 1.0


class SyncClock:
    """When a run's growing tables are next flushed to the disk: with the first step (not
    the first of the tables, written whole) :data:`SYNC_SECONDS` after the last flush."""

    def __init__(self) -> None:
        self.last = -math.inf  # when the tables were last flushed (time.monotonic)

    def due(self, first: bool = False) -> bool:
        """Whether a step (``first``: the tables' first) flushes them; counted as the flush."""
        now = time.monotonic()
        if first or now - self.last < SYNC_SECONDS:
            return False
        self.last = now
        return True

    def flushed(self) -> None:
        """The tables were flushed now (at the run's end, or out of turn)."""
        self.last = time.monotonic()


def sync_files(paths: Sequence[Path]) -> None:
    """Flush the files ``paths`` to the disk (``fsync``), in their order; one that is not
    there (removed meanwhile, or never written) is passed over."""
    for path in paths:
        try:
            fd = os.open(path, os.O_RDONLY)
        except FileNotFoundError:
            continue
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def write_csv(frame: pd.DataFrame, path: str | Path, append: bool = False, *,
              sync: bool = True) -> Path:
    """Write ``frame`` to ``path`` without its index (its folder made if need be); a new file
    replaces the old one only once it is complete, and a failed write leaves no ``.part``
    behind. ``append`` adds the rows to an existing table instead (:func:`append_csv`, with
    ``sync``)."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a folder, not a CSV file")
    if append:
        return append_csv(frame, path, sync=sync)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_whole(path, lambda tmp: frame.to_csv(tmp, index=False))


#: bytes read at a time from a table's end while looking for its last whole row
_TAIL_CHUNK = 1 << 16


def _whole_end(fh: Any, size: int) -> int:
    """The size [bytes] of the open binary table ``fh`` up to the end of its last whole row
    (a row ends with a newline): ``size`` where nothing is cut, 0 where no row is whole."""
    end = size
    while end > 0:
        start = max(0, end - _TAIL_CHUNK)
        fh.seek(start)
        chunk = fh.read(end - start)
        cut = chunk.rfind(b"\n")
        if cut >= 0:
            return start + cut + 1
        end = start
    return 0


def _header(fh: Any) -> list[str]:
    """The column names of the open binary table ``fh`` (its first row)."""
    fh.seek(0)
    line = fh.readline().decode("utf-8", errors="replace")
    return next(csv.reader([line]), [])


#: the formatted cells of the columns :func:`format_rows` saw last, by name, length and type:
#: the bits of the values and their text (a column that repeats from one step to the next, the
#: coordinates of the Gauss points, is formatted once)
_LAST_CELLS: dict[tuple[str, int, str], tuple[np.ndarray, list[str]]] = {}
#: at most this many columns are remembered
_LAST_CELLS_MAX = 64
#: a column of which at most this share of values changed since the step before keeps the
#: other cells' text and formats only those (the friction angle and return region of a
#: Mohr–Coulomb point change only where it yields)
_PATCHED_SHARE = 0.5


def _cells(name: str, values: np.ndarray) -> list[str]:
    """The CSV cells of one column of numbers, as pandas writes them: floats as ``repr``
    (numpy's shortest round-trip text, which Python's ``repr`` matches), NaN as an empty
    cell, integers and booleans as ``str``; a column of one repeated value formatted once,
    one equal bit for bit to the column last seen under ``name`` not formatted again, and of
    one that differs from it in a few values only those formatted."""
    n = len(values)
    bits = values.view(np.uint64 if values.dtype.kind == "f" else values.dtype)
    key = (name, n, values.dtype.str)
    last = _LAST_CELLS.get(key)
    changed = None if last is None else np.flatnonzero(last[0] != bits)
    if changed is not None and not len(changed):
        return last[1]
    if n and (bits == bits[0]).all():
        cells = _cells_of(values[:1]) * n
    elif changed is not None and len(changed) <= _PATCHED_SHARE * n:
        cells = list(last[1])  # the cells of the values that changed formatted anew
        for k, cell in zip(changed.tolist(), _cells_of(values[changed]), strict=True):
            cells[k] = cell
    else:
        cells = _cells_of(values)
    if len(_LAST_CELLS) >= _LAST_CELLS_MAX and key not in _LAST_CELLS:
        _LAST_CELLS.pop(next(iter(_LAST_CELLS)))
    _LAST_CELLS[key] = (bits.copy(), cells)
    return cells


def _cells_of(values: np.ndarray) -> list[str]:
    """The CSV cells of ``values`` (float64, int64 or bool), formatted one by one."""
    if values.dtype.kind == "f":
        cells = list(map(repr, values.tolist()))
        if np.isnan(values).any():
            cells = ["" if v != v else c for v, c in zip(values.tolist(), cells, strict=True)]
        return cells
    return list(map(str, values.tolist()))


def _column(frame: pd.DataFrame, k: int) -> np.ndarray:
    """Column ``k`` of ``frame`` as an array (without the Series pandas makes of it where it
    offers the column itself, ten times faster)."""
    column = getattr(frame, "_get_column_array", None)
    return np.asarray(column(k)) if column is not None else frame.iloc[:, k].to_numpy()


def _texts(values: np.ndarray) -> list[str] | None:
    """The cells of a column of Python ``str`` (the steps table's histories), as they are
    (the csv module quotes them); None for any other column of objects."""
    cells = values.tolist()
    return cells if all(type(cell) is str for cell in cells) else None


def format_rows(frame: pd.DataFrame, order: list[int] | None = None) -> str:
    """The rows of ``frame`` (its columns in ``order``, positions; None: as they are) as
    ``frame.to_csv(index=False, header=False)`` writes them, byte for byte, formatted faster
    where every column holds float64, int64, booleans or text (the Gauss-point tables, a
    ``steps.csv`` row) in two columns or more; any other frame is formatted by pandas (the
    csv module quotes a row of one empty cell)."""
    order = list(range(frame.shape[1])) if order is None else list(order)
    arrays = [_column(frame, k) for k in order]
    if not len(frame) or len(arrays) < 2:
        return frame.iloc[:, order].to_csv(index=False, header=False)
    cells: list[list[str]] = []
    text = False
    for k, a in zip(order, arrays, strict=True):
        if a.dtype in (np.float64, np.int64, np.bool_):
            cells.append(_cells(str(frame.columns[k]), a))
            continue
        column = _texts(a) if a.dtype == object else None
        if column is None:
            return frame.iloc[:, order].to_csv(index=False, header=False)
        cells.append(column)
        text = True
    rows = zip(*cells, strict=True)
    if not text:
        return os.linesep.join(map(",".join, rows)) + os.linesep
    buffer = io.StringIO()  # pandas' own writer of text cells: the csv module, quoting alike
    csv.writer(buffer, lineterminator=os.linesep, quoting=csv.QUOTE_MINIMAL).writerows(rows)
    return buffer.getvalue()


def append_csv(frame: pd.DataFrame, path: str | Path, *, sync: bool = True) -> Path:
    """Add the rows of ``frame`` to the CSV table at ``path``, whole rows or none.

    The rows go in one write at the end of the table's last whole row (a row an earlier
    killed write cut is dropped first), are flushed to the disk (``fsync``) where ``sync``
    (a killed process loses nothing the kernel holds; a power cut what is not flushed), and
    are taken back when the write fails (a full disk: ``OSError`` naming the table, the table as it
    was). Stop signals wait until the rows are in. Columns are matched by name; a frame with
    other columns than the table's rewrites the table whole (the union of both, empty cells
    where a row has no value). A missing or empty table is written whole, with its header.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path} is a folder, not a CSV file")
    if not path.exists() or path.stat().st_size == 0:
        return write_csv(frame, path)
    with open(path, "rb") as fh:
        header = _header(fh)
        end = _whole_end(fh, os.fstat(fh.fileno()).st_size)
    names = [str(c) for c in frame.columns]
    if sorted(names) != sorted(header) or len(set(header)) != len(header):
        whole = pd.concat([read_table(path),  # pandas reads floats back bit for bit
                           frame.set_axis(names, axis=1)],
                          ignore_index=True)
        return write_csv(whole, path)
    payload = format_rows(frame, [names.index(name) for name in header]).encode("utf-8")
    with deferred_signals():
        fd = os.open(path, os.O_WRONLY)
        try:
            os.ftruncate(fd, end)  # a row cut by an earlier killed write, dropped
            os.lseek(fd, end, os.SEEK_SET)
            view = memoryview(payload)
            while view:
                view = view[os.write(fd, view):]
            if sync:
                os.fsync(fd)
        except OSError as exc:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, end)
            raise OSError(exc.errno, f"cannot add to {path}: {exc.strerror or exc}") from exc
        finally:
            os.close(fd)
    return path


def read_table(path: str | Path, **read_csv: Any) -> pd.DataFrame:
    """The CSV table at ``path`` up to its last whole row: a row cut by a killed write
    (no newline at its end) is left out, never read as a row of empty or shortened values.
    ``read_csv``: passed on to :func:`pandas.read_csv`."""
    path = Path(path)
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        end = _whole_end(fh, size)
        if end == 0:
            return pd.DataFrame()  # not even the header is whole
        if end == size:
            return pd.read_csv(path, **read_csv)
        fh.seek(0)
        return pd.read_csv(io.BytesIO(fh.read(end)), **read_csv)


def _committed(table: pd.DataFrame, committed: set[Any] | None) -> pd.DataFrame:
    """``table`` without the rows of steps not in ``committed`` (None: every row)."""
    if committed is not None and "step" in table:
        return table[table["step"].isin(committed)].reset_index(drop=True)
    return table


def _committed_steps(out: Path) -> set[Any] | None:
    """The steps ``steps.csv`` under ``out`` holds (None: it has no ``step`` column)."""
    steps = read_table(out / "steps.csv")
    return set(steps["step"]) if "step" in steps else set() if steps.empty else None


def _points_table(out: Path) -> pd.DataFrame | None:
    """The Gauss-point table of the run folder ``out`` as written, from ``points.npy`` or
    else ``points.csv`` (None: neither is there)."""
    if (out / "points.npy").exists():
        return read_npy_table(out / "points.npy")
    if (out / "points.csv").exists():
        return read_table(out / "points.csv")
    return None


def read_points(folder: str | Path) -> pd.DataFrame:
    """The Gauss-point history of the run in ``folder``: every point at every committed step,
    read from ``points.npy`` (what a run writes) or ``points.csv`` (a run with the option
    ``points_csv``, or of an older version), without the records of steps ``steps.csv`` does
    not hold (a run killed between a step's points and its row). ``FileNotFoundError`` where
    the folder holds neither file."""
    out = Path(folder)
    table = _points_table(out)
    if table is None:
        raise FileNotFoundError(f"{out} holds no points.npy nor points.csv: not the folder "
                                "of a FEM run, or one that wrote no steps")
    if not (out / "steps.csv").exists():
        return table
    return _committed(table, _committed_steps(out))


def read_run_tables(out_dir: str | Path) -> dict[str, pd.DataFrame]:
    """The tables of a run folder as they stood at its last committed step, also of a run
    killed while it wrote: ``steps`` (``steps.csv``) and, where written, ``points``
    (``points.npy`` or ``points.csv``: :func:`read_points`) and ``tracked``, each without a
    cut last row and without the rows of a step that ``steps.csv`` does not hold yet."""
    out = Path(out_dir)
    tables = {"steps": read_table(out / "steps.csv")}
    committed = _committed_steps(out)
    points = _points_table(out)
    if points is not None:
        tables["points"] = _committed(points, committed)
    if (out / "tracked.csv").exists():
        tables["tracked"] = _committed(read_table(out / "tracked.csv"), committed)
    return tables


def strict_json(data: Any) -> Any:
    """``data`` with every number that is not finite (NaN, ±inf, as Python or numpy floats,
    also inside arrays) as None, so that it is written as strict JSON (``null``, where
    Python's json would write ``NaN`` or ``Infinity``, which JSON readers refuse)."""
    if isinstance(data, dict):
        return {key: strict_json(value) for key, value in data.items()}
    if isinstance(data, (list, tuple)):
        return [strict_json(value) for value in data]
    if isinstance(data, np.ndarray):
        return strict_json(data.tolist())
    if isinstance(data, (float, np.floating)):
        return float(data) if math.isfinite(data) else None
    if isinstance(data, np.integer):
        return int(data)
    return data


def write_json(data: Any, path: str | Path, indent: int = 2) -> Path:
    """Write ``data`` as strict JSON to ``path`` (a number that is not finite as ``null``:
    :func:`strict_json`; other values JSON cannot hold as their ``str``); a new file
    replaces the old one only once it is complete, and a failed write leaves no ``.part``
    behind."""
    text = json.dumps(strict_json(data), indent=indent, default=str, allow_nan=False) + "\n"
    return write_whole(path, lambda tmp: tmp.write_text(text))


def write_points(points: pd.DataFrame, out_dir: str | Path, append: bool = False, *,
                 csv: bool = False, sync: bool = True) -> dict[str, Path]:
    """Write the Gauss-point table ``points`` under ``out_dir``: ``points.npy``
    (:mod:`~granular_material.results.point_table`) and, where ``csv``, ``points.csv`` too,
    each whole or, where ``append``, its rows added (flushed to the disk where ``sync``).
    Returns their paths by name, ``points`` and ``points_csv``."""
    out = Path(out_dir)
    paths = {"points": out / "points.npy"}
    if append:
        append_npy(points, paths["points"], sync=sync)
    else:
        out.mkdir(parents=True, exist_ok=True)
        write_npy_table(points, paths["points"])
    if csv:
        paths["points_csv"] = write_csv(points, out / "points.csv", append=append, sync=sync)
    return paths


def write_tables(steps: pd.DataFrame, points: pd.DataFrame, out_dir: str | Path,
                 append_points: bool = False, *, points_csv: bool = False) -> dict[str, Path]:
    """Write ``points.npy`` (and ``points.csv`` where ``points_csv``) and ``steps.csv`` under
    ``out_dir``; returns their paths (``steps``, ``points`` and ``points_csv``).

    ``append_points``: add the rows of ``points`` to the existing tables of points (a run that
    writes step by step) instead of writing them whole. ``steps.csv`` is written whole,
    last: its rows are the committed steps.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = write_points(points, out, append_points, csv=points_csv)
    paths["steps"] = out / "steps.csv"
    write_csv(steps, paths["steps"])  # last: a step is committed once its row is here
    return paths


#: the XDMF topology of each cell kind :meth:`BiaxialProblem.nodes` names (meshio's names)
_XDMF_TOPOLOGY = {"quad": "Quadrilateral", "quad8": "Quadrilateral_8",
                  "quad9": "Quadrilateral_9", "triangle": "Triangle",
                  "triangle6": "Triangle_6"}
#: the end of the fields file's XML: each step's grid is written before it
_XDMF_TAIL = b"    </Grid>\n  </Domain>\n</Xdmf>\n"


def _xdmf_item(data: np.ndarray, h5: str, dataset: str, indent: str) -> str:
    """The XDMF ``DataItem`` of ``data`` stored as ``dataset`` in the HDF5 file named ``h5``
    (float64 or int64)."""
    kind = {"f": "Float", "i": "Int"}[data.dtype.kind]
    dims = " ".join(map(str, data.shape))
    return (f'{indent}<DataItem DataType="{kind}" Dimensions="{dims}" Format="HDF" '
            f'Precision="{data.dtype.itemsize}">{h5}:/{dataset}</DataItem>\n')


def cell_means(points: pd.DataFrame) -> dict[str, np.ndarray]:
    """Each element's mean of the Gauss-point columns named in ``_CELL_FIELDS`` that
    ``points`` holds (booleans as 0/1), by element number (pandas' group means)."""
    means = points.groupby("element").mean(numeric_only=True)
    return {k: means[k].to_numpy(dtype=float) for k in _CELL_FIELDS if k in means}


class FieldWriter:
    """XDMF time series of the mesh with per-step fields, for ParaView and meshio: the XML
    ``path`` (``fields.xdmf``) names the values, which are in the HDF5 file beside it of the
    same stem (``fields.h5``; written through h5py).

    A context manager: ``with FieldWriter(path, problem) as fields: fields.write(...)``.
    Cells: quad, quad8, quad9, triangle or triangle6, with every node of the element
    (midside and centre nodes included, see :meth:`BiaxialProblem.nodes`).
    Point data: ``displacement`` [m] (nnodes, 3). Cell data: element means of the
    Gauss-point columns named in ``_CELL_FIELDS`` that the table holds, and where it has a
    ``region`` column (materials by region), each element's region numbered 0, 1, … in the
    alphabetical order of the regions' names. Time: what :meth:`write` is given (a biaxial
    run's axial strain, a boundary-value run's load factor).

    In the HDF5 file: ``/mesh/geometry`` and ``/mesh/topology``, and every step's fields as
    ``/NAME/K`` (K = 0, 1, … the steps written). Both files are begun anew when the writer is
    entered and grow step by step: a step's values are written and flushed first, then its
    grid is added to the XML before the XML's closing tags (whose bytes are rewritten with
    it), so the pair read by meshio or ParaView holds every step whose grid is written. The
    same steps written give the same bytes (no times are stored), which a resumed run,
    writing its steps again from the first, relies on.
    """

    def __init__(self, path: str | Path, problem: BiaxialProblem) -> None:
        self.path = Path(path)
        self.h5_path = self.path.with_suffix(".h5")
        self.problem = problem
        self._h5: Any = None
        self._fd: int | None = None
        self._end = 0  # where the XML's closing tags begin [bytes]
        self._steps = 0
        self._dofs: np.ndarray | None = None
        self._groups: dict[str, Any] = {}  # the HDF5 file's groups by name
        self._broken = False  # a write failed: nothing more is written

    def __enter__(self) -> FieldWriter:
        import h5py

        self.path.parent.mkdir(parents=True, exist_ok=True)
        xy, cells, kind, self._dofs = self.problem.nodes()
        if kind not in _XDMF_TOPOLOGY:
            raise ValueError(f"the fields file cannot hold cells of kind {kind!r}")
        geometry = np.column_stack([xy, np.zeros(xy.shape[0])]).astype(np.float64)
        topology = np.ascontiguousarray(cells, dtype=np.int64)
        self._broken = False
        with self._naming(self.h5_path):
            self._h5 = h5py.File(self.h5_path, "w", track_order=False)
        try:
            self._groups = {}
            with self._naming(self.h5_path):
                self._dataset("mesh", "geometry", geometry)
                self._dataset("mesh", "topology", topology)
                self._h5.flush()
            name = self.h5_path.name
            head = ('<Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude">\n'
                    "  <Domain>\n"
                    '    <Grid Name="mesh" GridType="Uniform">\n'
                    '      <Geometry GeometryType="XYZ">\n'
                    + _xdmf_item(geometry, name, "mesh/geometry", "        ")
                    + "      </Geometry>\n"
                    f'      <Topology TopologyType="{_XDMF_TOPOLOGY[kind]}" '
                    f'NumberOfElements="{len(topology)}">\n'
                    + _xdmf_item(topology, name, "mesh/topology", "        ")
                    + "      </Topology>\n"
                    "    </Grid>\n"
                    '    <Grid Name="steps" GridType="Collection" '
                    'CollectionType="Temporal">\n').encode("utf-8")
            with self._naming(self.path):
                self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
                self._write_at(0, head + _XDMF_TAIL)
            self._end = len(head)
        except BaseException:
            self._broken = True
            self.__exit__()
            raise
        self._steps = 0
        return self

    def _dataset(self, group: str, name: str, values: np.ndarray) -> None:
        """``values`` stored as the dataset ``/group/name`` of the HDF5 file, without times
        (through h5py's low-level calls: a third of the high-level ones' cost a dataset)."""
        import h5py

        values = np.ascontiguousarray(values)
        gid = self._groups.get(group)
        if gid is None:
            gid = self._groups[group] = self._h5.create_group(group).id
        dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
        dcpl.set_obj_track_times(False)
        dataset = h5py.h5d.create(gid, name.encode(), h5py.h5t.py_create(values.dtype),
                                  h5py.h5s.create_simple(values.shape), dcpl=dcpl)
        dataset.write(h5py.h5s.ALL, h5py.h5s.ALL, values)

    def _write_at(self, offset: int, data: bytes) -> None:
        """``data`` written into the XML file from ``offset`` on (always to a longer file:
        the closing tags it overwrites are in ``data`` again)."""
        assert self._fd is not None
        view = memoryview(data)
        while view:
            written = os.pwrite(self._fd, view, offset)
            view, offset = view[written:], offset + written

    def __exit__(self, *exc: object) -> None:
        try:
            if self._h5 is not None:
                if self._broken or (exc and exc[0] is not None):
                    with contextlib.suppress(OSError, RuntimeError, ValueError):
                        self._h5.close()  # already failing: that error is the one told
                else:
                    with self._naming(self.h5_path):
                        self._h5.close()
        finally:
            self._h5, self._groups = None, {}
            if self._fd is not None:
                os.close(self._fd)
                self._fd = None

    @contextlib.contextmanager
    def _naming(self, path: Path) -> Iterator[None]:
        """Errors of writing ``path`` (HDF5's included: a full disk) as an ``OSError`` that
        names it; the writer is then broken (its files are closed without more writing)."""
        try:
            yield
        except (OSError, RuntimeError) as exc:
            self._broken = True
            if isinstance(exc, OSError) and exc.errno is not None:
                raise OSError(exc.errno, f"cannot write {path}: {exc.strerror or exc}") from exc
            raise OSError(f"cannot write {path}: {exc}") from exc

    def write(self, time: float, u: np.ndarray, points: pd.DataFrame) -> None:
        """Append one step: nodal displacement ``u`` (ndofs,) and the Gauss-point table."""
        ux, uy = u[self._dofs[0]], u[self._dofs[1]]
        fields = {"displacement": np.column_stack([ux, uy, np.zeros_like(ux)])}
        fields.update(cell_means(points))
        if "region" in points:  # materials by region: numbered in their names' order
            names = points.groupby("element")["region"].first().astype(str)
            order = {name: k for k, name in enumerate(sorted(set(names)))}
            fields["region"] = names.map(order).to_numpy(dtype=float)
        k = self._steps
        name = self.h5_path.name
        grid = [f'      <Grid Name="step {k}" GridType="Uniform">\n'
                '        <xi:include xpointer="xpointer(//Grid[@Name=&quot;mesh&quot;]/*'
                '[self::Topology or self::Geometry])"/>\n'
                f'        <Time Value="{float(time)!r}"/>\n']
        if self._broken:
            raise OSError(f"cannot write {self.h5_path}: an earlier write failed")
        with deferred_signals(), self._naming(self.h5_path):  # a step's values, then its grid
            for field, values in fields.items():
                values = np.asarray(values, dtype=np.float64)
                self._dataset(field, str(k), values)
                shape = "Vector" if values.ndim == 2 else "Scalar"
                center = "Node" if field == "displacement" else "Cell"
                grid.append(f'        <Attribute Name="{field}" AttributeType="{shape}" '
                            f'Center="{center}">\n'
                            + _xdmf_item(values, name, f"{field}/{k}", "          ")
                            + "        </Attribute>\n")
            grid.append("      </Grid>\n")
            self._h5.flush()
        text = "".join(grid).encode("utf-8")
        with deferred_signals(), self._naming(self.path):
            self._write_at(self._end, text + _XDMF_TAIL)
        self._end += len(text)
        self._steps += 1


class BiaxialWriter:
    """Writes a biaxial run under ``out_dir`` while it goes: an observer of
    :func:`~granular_material.runs.run_biaxial`, used as a context manager::

        with BiaxialWriter(out) as writer:
            result = run_biaxial(setup, material, n_steps, observer=writer)

    Every step appends to the tables (a long run can be followed, and is not lost if it is
    stopped; the module docstring says what a killed run leaves) and to ``fields.xdmf``.
    The Gauss-point table is ``points.npy``, and also ``points.csv`` where ``points_csv``
    (:func:`write_points`).
    The appended tables are the whole tables of the run: :meth:`finish` writes them anew only
    where they could differ from the result's (a step not recorded here, or a column whose
    type changed between steps, which the result's table holds as one type). The tables are
    flushed to the disk (``fsync``) with the first step :data:`SYNC_SECONDS` after the last
    flush and by :meth:`finish`. The fields file is finished when the ``with`` block ends,
    however it ends.
    """

    def __init__(self, out_dir: str | Path, *, points_csv: bool = False) -> None:
        self.out_dir = Path(out_dir)
        self.points_csv = points_csv
        self._stack = ExitStack()
        self._fields: FieldWriter | None = None
        self._steps = 0  # steps recorded: after the first, the tables are appended
        self._tracked_any = False  # tracked.csv begun: later rows are appended
        self._rows = {"steps": 0, "points": 0, "tracked": 0}  # rows recorded by table
        #: each table's columns and their types as first recorded; False once they changed
        self._kinds: dict[str, Any] = {}
        self._clock = SyncClock()
        self._unsynced: set[str] = set()  # files of the tables appended to since

    def __enter__(self) -> BiaxialWriter:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self._stack.close()
        finally:
            if exc[0] is None:
                self.sync()
            else:  # already failing: the tables as far as they are
                with contextlib.suppress(OSError):
                    self.sync()

    def sync(self) -> None:
        """Flush the tables appended to since their last flush to the disk (``fsync``)."""
        names = [name for name in ("tracked.csv", "points.npy", "points.csv", "steps.csv")
                 if name in self._unsynced]  # steps last
        self._unsynced.difference_update(names)
        sync_files([self.out_dir / name for name in names])
        self._clock.flushed()

    def _append(self, name: str, frame: pd.DataFrame, append: bool, sync: bool) -> None:
        """Add ``frame`` to table ``name`` (``append`` False: write it whole), flushed to the
        disk where ``sync``."""
        if name == "points":
            files = list(write_points(frame, self.out_dir, append, csv=self.points_csv,
                                      sync=sync).values())
        else:
            files = [write_csv(frame, self.out_dir / f"{name}.csv", append=append, sync=sync)]
        for path in files:
            if append and not sync:
                self._unsynced.add(path.name)
            else:
                self._unsynced.discard(path.name)

    def start(self, problem: BiaxialProblem) -> None:
        """Open the fields file of ``problem``'s mesh."""
        self._fields = self._stack.enter_context(
            FieldWriter(self.out_dir / "fields.xdmf", problem)
        )
        self._steps = 0
        self._tracked_any = False
        self._rows = {"steps": 0, "points": 0, "tracked": 0}
        self._kinds = {}
        self._clock, self._unsynced = SyncClock(), set()
        if not self.points_csv:  # an earlier run's, which this one does not write
            (self.out_dir / "points.csv").unlink(missing_ok=True)

    def _seen(self, name: str, frame: pd.DataFrame) -> None:
        """Count ``frame``'s rows as recorded in table ``name`` and note whether its columns
        and their types are those the table was begun with."""
        self._rows[name] += len(frame)
        kinds = tuple(zip(map(str, frame.columns), map(str, frame.dtypes), strict=True))
        if self._kinds.setdefault(name, kinds) != kinds:
            self._kinds[name] = False

    def record(self, row: dict[str, Any], points: pd.DataFrame, u: np.ndarray,
               tracked: pd.DataFrame | None = None) -> None:
        """One committed step: its ``steps`` row, its Gauss-point table, the displacement,
        its tracked rows (added to ``tracked.csv``)."""
        if self._fields is None:
            raise RuntimeError("BiaxialWriter.start(problem) must come before record()")
        self._fields.write(row["axial_strain"], u, points)
        # all of a step's tables flushed, or none: tracked and points before steps
        more = self._steps > 0
        sync = self._clock.due(first=not more)
        if sync:
            if "tracked.csv" in self._unsynced and (tracked is None or not len(tracked)):
                self.sync()  # earlier steps' tracked rows, before this step's points
        # each table's rows count once written: a stop signal delivered between two writes
        # leaves the count short, and finish() then writes the tables whole
        if tracked is not None and len(tracked):
            self._append("tracked", tracked, self._tracked_any, sync)
            self._tracked_any = True
        if tracked is not None:
            self._seen("tracked", tracked)
        step = pd.DataFrame([row])
        self._append("points", points, more, sync)
        self._seen("points", points)
        self._append("steps", step, more, sync)  # the commit
        self._seen("steps", step)
        self._steps += 1

    def holds(self, result: BiaxialResult) -> bool:
        """Whether the tables appended here are, byte for byte, those :func:`write_tables`
        writes of ``result`` (``points_csv`` as here): every row of the result recorded,
        each table's columns and their types alike at every step (so that the result's
        concatenated table formats every cell as the step's own table did)."""
        tables = {"steps": result.steps, "points": result.points, "tracked": result.tracked}
        return self._steps > 0 and all(
            self._rows[name] == len(table) and self._kinds.get(name, True) is not False
            for name, table in tables.items())

    def finish(self, result: BiaxialResult) -> None:
        """The whole tables of the run: those appended step by step (flushed to the disk), or
        written anew where they could differ (:meth:`holds`)."""
        if self.holds(result):
            self.sync()
            return
        self._unsynced.clear()  # written anew, whole
        write_tables(result.steps, result.points, self.out_dir, points_csv=self.points_csv)
        if len(result.tracked):
            write_csv(result.tracked, self.out_dir / "tracked.csv")


def write_outputs(result: BiaxialResult, out_dir: str | Path,
                  map_strain: float | Sequence[float] | None = None,
                  reference: pd.DataFrame | None = None, *,
                  tables: bool = True, points_csv: bool = False,
                  figures: bool = True) -> dict[str, Path]:
    """Tables, the stress–strain figure and the maps figures under ``out_dir``
    (``points_csv``: the Gauss-point table as ``points.csv`` too, :func:`write_tables`).

    ``figures`` False: no figures (matplotlib is not imported), and those an earlier run
    drew in ``out_dir`` (``stress_strain.png``, ``maps.png``, ``maps_*pct.png``) are removed.

    ``tables`` False: the tables are not written again, being already whole there (a
    :class:`BiaxialWriter`'s, after its :meth:`~BiaxialWriter.finish`); their paths are
    returned all the same.

    ``map_strain``: axial strain(s) of the maps; None: the last step. One strain gives
    ``maps.png``; several give ``maps_<strain in %>pct.png`` each (keys ``maps_<strain>``).
    ``fields.xdmf`` is the one a :class:`BiaxialWriter` wrote there during the run.
    """
    out = Path(out_dir)
    if tables:
        paths = write_tables(result.steps, result.points, out, points_csv=points_csv)
        if len(result.tracked):
            paths["tracked"] = write_csv(result.tracked, out / "tracked.csv")
    else:
        paths = {"steps": out / "steps.csv", "points": out / "points.npy"}
        if points_csv:
            paths["points_csv"] = out / "points.csv"
        if len(result.tracked):
            paths["tracked"] = out / "tracked.csv"
    if figures:
        paths["stress_strain"] = plot_stress_strain(result.steps, out / "stress_strain.png",
                                                    reference)
        if map_strain is None:
            map_strain = float(result.steps["axial_strain"].iloc[-1])
        strains = ([float(map_strain)] if np.isscalar(map_strain)
                   else [float(e) for e in map_strain])
        if len(strains) == 1:
            paths["maps"] = plot_maps(result, strains[0], out / "maps.png")
        else:
            for strain in strains:
                paths[f"maps_{strain:g}"] = plot_maps(result, strain,
                                                      out / f"maps_{100 * strain:.1f}pct.png")
    else:  # an earlier run's, which this one does not draw
        for stale in [out / "stress_strain.png", out / "maps.png", *out.glob("maps_*pct.png")]:
            stale.unlink(missing_ok=True)
    paths["fields"] = out / "fields.xdmf"
    return paths
