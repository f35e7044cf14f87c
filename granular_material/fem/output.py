"""Outputs of a biaxial run: CSV tables, an XDMF time series for ParaView, figures.

Plots follow the geotechnical habit and say so on their axes: axial strain, stress and
volumetric strain are drawn compression positive.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from granular_material.fem.localization import shear_band

if TYPE_CHECKING:
    from granular_material.fem.problems import BiaxialProblem
    from granular_material.fem.runner import BiaxialResult

__all__ = ["FieldWriter", "plot_maps", "plot_stress_strain", "write_outputs", "write_tables"]

_CELL_FIELDS = ("sxx", "syy", "sxy", "exx", "eyy", "exy", "volumetric_strain",
                "shear_strain", "void_ratio", "coordination")


class FieldWriter:
    """XDMF time series (XML data, no HDF5 needed) of the mesh with per-step fields.

    Point data: ``displacement`` [m] (nnodes, 3). Cell data: element means of the
    Gauss-point columns named in ``_CELL_FIELDS`` that the table holds. Time = axial strain.
    """

    def __init__(self, path: str | Path, problem: BiaxialProblem) -> None:
        import meshio

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        mesh = problem.basis.mesh
        self._nodal = problem.basis.nodal_dofs
        self._writer = meshio.xdmf.TimeSeriesWriter(str(path), data_format="XML")
        self._writer.__enter__()
        points = np.column_stack([mesh.p.T, np.zeros(mesh.p.shape[1])])
        self._writer.write_points_cells(points, [("quad", mesh.t.T.astype(np.int64))])

    def write(self, time: float, u: np.ndarray, points: pd.DataFrame) -> None:
        """Append one step: nodal displacement ``u`` (ndofs,) and the Gauss-point table."""
        ux, uy = u[self._nodal[0]], u[self._nodal[1]]
        disp = np.column_stack([ux, uy, np.zeros_like(ux)])
        means = points.groupby("element").mean(numeric_only=True)
        cell_data = {k: [means[k].to_numpy(dtype=float)] for k in _CELL_FIELDS if k in means}
        self._writer.write_data(float(time), point_data={"displacement": disp},
                                cell_data=cell_data)

    def close(self) -> None:
        """Finish the file."""
        self._writer.__exit__(None, None, None)


def write_tables(result: BiaxialResult, out_dir: str | Path) -> dict[str, Path]:
    """Write ``steps.csv`` and ``points.csv`` under ``out_dir``; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"steps": out / "steps.csv", "points": out / "points.csv"}
    result.steps.to_csv(paths["steps"], index=False)
    result.points.to_csv(paths["points"], index=False)
    return paths


def plot_stress_strain(steps: pd.DataFrame, path: str | Path, reference: pd.DataFrame | None = None,
                       label: str = "FEM") -> Path:
    """Stress ratio and volumetric strain against axial strain (compression positive).

    ``reference``, if given, is a table with ``axial_strain``, ``stress_ratio`` and
    ``volumetric_strain`` columns in the same conventions (e.g. the pure-DEM biaxial test).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    series = [(steps, label)] + ([(reference, "DEM (single RVE)")] if reference is not None else [])
    for table, name in series:
        a.plot(100 * table["axial_strain"], table["stress_ratio"], label=name)
        b.plot(100 * table["axial_strain"], -100 * table["volumetric_strain"], label=name)
    a.set_xlabel("axial strain ε_a [%] (compression +)")
    a.set_ylabel("stress ratio σ_1/σ_3 [-] (compression +)")
    b.set_xlabel("axial strain ε_a [%] (compression +)")
    b.set_ylabel("volumetric strain ε_v [%] (contraction +)")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_maps(result: BiaxialResult, axial_strain: float, path: str | Path) -> Path:
    """Maps of u_x, u_y [mm] and shear strain γ [%] at the step nearest ``axial_strain``.

    Drawn on the deformed mesh (true scale), after Wu et al. (2025), Fig. 8.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.tri import Triangulation

    steps = result.steps
    row = result.row_nearest(axial_strain)
    step = int(steps["step"].iloc[row])
    u = result.displacements[row]
    basis = result.problem.basis
    mesh = basis.mesh
    ux, uy = u[basis.nodal_dofs[0]], u[basis.nodal_dofs[1]]
    x, y = mesh.p[0] + ux, mesh.p[1] + uy
    quads = mesh.t.T
    tri = Triangulation(1e3 * x, 1e3 * y, np.vstack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]))
    points = result.points[result.points["step"] == step]
    gamma = points.groupby("element")["shear_strain"].mean().to_numpy()
    fig, axes = plt.subplots(1, 3, figsize=(12, 5), constrained_layout=True)
    for ax, values, title in ((axes[0], 1e3 * ux, "u_x [mm]"), (axes[1], 1e3 * uy, "u_y [mm]")):
        im = ax.tripcolor(tri, values, shading="gouraud", cmap="viridis")
        fig.colorbar(im, ax=ax, label=title)
    im = axes[2].tripcolor(tri, facecolors=100 * np.concatenate([gamma, gamma]), cmap="inferno",
                          vmin=0.0, vmax=max(100 * float(gamma.max()), 1e-12))
    fig.colorbar(im, ax=axes[2], label="shear strain γ [%]")
    for ax, title in zip(axes, ("displacement u_x", "displacement u_y", "shear strain"),
                         strict=True):
        ax.set_aspect("equal")
        ax.set_title(title)
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
    band = shear_band(result.points, step)
    fig.suptitle(f"step {step}, axial strain {100 * steps['axial_strain'].iloc[row]:.2f} % "
                 f"(compression +)\nlargest-γ {100 * band.band_fraction:.0f} % of points: "
                 f"inclination {band.inclination_deg:.0f}°, elongation "
                 f"{band.elongation:.2f}, γ ratio {band.localization:.1f}")
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def write_outputs(result: BiaxialResult, out_dir: str | Path,
                  map_strain: float | Sequence[float] | None = None,
                  reference: pd.DataFrame | None = None) -> dict[str, Path]:
    """Tables, the stress–strain figure and the maps figures under ``out_dir``.

    ``map_strain``: axial strain(s) of the maps; None: the last step. One strain gives
    ``maps.png``; several give ``maps_<strain in %>pct.png`` each (keys ``maps_<strain>``).
    """
    out = Path(out_dir)
    paths = write_tables(result, out)
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
