"""Figures of the runs. The one module that selects matplotlib's backend (Agg: files only,
no display needed); everything that draws gets pyplot from :func:`pyplot`.

Plots follow the geotechnical habit and say so on their axes: axial strain, stress and
volumetric strain are drawn compression positive.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from granular_material.filesafe import write_whole
from granular_material.results.localization import shear_band

if TYPE_CHECKING:
    from granular_material.results.biaxial import BiaxialResult

__all__ = ["FAST_PNG", "deformed_triangles", "plot_biaxial_curves", "plot_maps",
           "plot_stress_strain", "pyplot", "save_figure"]


#: the margins of a run's two figures (fractions of the figure), set once instead of by
#: matplotlib's constrained layout: measured on the 16 × 32 specimen (median of 5), the curves
#: took 0.151 s with it and 0.100 s without, the maps 0.362 s and 0.228 s (issue 62)
_PLAIN_LAYOUT = {"curves": {"left": 0.07, "right": 0.98, "bottom": 0.13, "top": 0.95,
                            "wspace": 0.25},
                 "maps": {"left": 0.05, "right": 0.96, "bottom": 0.1, "top": 0.82,
                          "wspace": 0.45}}


def pyplot() -> ModuleType:
    """``matplotlib.pyplot`` on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


#: zlib's level for the PNG files of a run's own figures: the same pixels as the default
#: level 6, in about a third of its time and a third more bytes (a 1440 × 600 maps figure:
#: 0.12 s and 603 kB against 0.34 s and 457 kB, at a load of 6)
FAST_PNG = 1


def save_figure(fig: Any, path: str | Path, dpi: int = 120,
                compress_level: int | None = None) -> Path:
    """Save the matplotlib figure ``fig`` to ``path`` (format from its suffix) whole or not
    at all: drawn into ``path.part`` and renamed into place; a failed write leaves no
    ``.part`` and its error names the file. ``compress_level``: zlib's level (0–9) of a
    PNG file (None: matplotlib's default)."""
    path = Path(path)
    kind = path.suffix.removeprefix(".").lower() or "png"
    extra = ({"pil_kwargs": {"compress_level": compress_level}}
             if compress_level is not None and kind == "png" else {})
    return write_whole(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format=kind, **extra))


def plot_biaxial_curves(curve: pd.DataFrame, path: str | Path) -> Path:
    """σ1/σ3 and εv against εa of the pure-DEM biaxial curve(s) of
    :func:`~granular_material.procedures.biaxial_test` (one line per RVE)."""
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for rve, group in curve.groupby("rve"):
        eps = 100 * group["axial_strain"]
        ax1.plot(eps, group["stress_ratio"], label=f"RVE {rve}")
        ax2.plot(eps, -100 * group["volumetric_strain"], label=f"RVE {rve}")
    ax1.set_xlabel("axial strain εa [%] (compression positive)")
    ax1.set_ylabel("stress ratio σ1/σ3 [-]")
    ax2.set_xlabel("axial strain εa [%] (compression positive)")
    ax2.set_ylabel("volumetric strain εv [%] (contraction positive)")
    if curve["rve"].nunique() <= 10:
        ax1.legend()
    fig.suptitle("Drained biaxial test of the RVE(s)")
    try:
        return save_figure(fig, path)
    finally:
        plt.close(fig)


def plot_stress_strain(steps: pd.DataFrame, path: str | Path, reference: pd.DataFrame | None = None,
                       label: str = "FEM") -> Path:
    """Stress ratio and volumetric strain against axial strain (compression positive).

    ``reference``, if given, is a table with ``axial_strain``, ``stress_ratio`` and
    ``volumetric_strain`` columns in the same conventions (e.g. the pure-DEM biaxial test).
    """
    plt = pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    fig.subplots_adjust(**_PLAIN_LAYOUT["curves"])
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
    try:
        return save_figure(fig, path, compress_level=FAST_PNG)
    finally:
        plt.close(fig)


def deformed_triangles(xy: np.ndarray, cells: np.ndarray, kind: str, ux: np.ndarray,
                       uy: np.ndarray) -> tuple[np.ndarray, ...]:
    """The deformed mesh as straight triangles for a map: (x, y, ux, uy) at its nodes [m]
    (a centre node added to each quad8), the triangles (k, 3) and the element of each.

    ``xy`` (nodes, 2) [m], ``cells`` in meshio order of the meshio cell type ``kind``
    ("quad", "triangle", "triangle6", "quad8", "quad9"), ``ux``/``uy`` nodal displacements.
    """
    x, y = xy[:, 0] + ux, xy[:, 1] + uy
    if kind == "quad":
        triangles = np.vstack([cells[:, [0, 1, 2]], cells[:, [0, 2, 3]]])
        element = np.concatenate([np.arange(cells.shape[0])] * 2)
    elif kind == "triangle":
        triangles, element = cells, np.arange(cells.shape[0])
    elif kind == "triangle6":  # four triangles through the midside nodes
        triangles = np.vstack([cells[:, [0, 3, 5]], cells[:, [3, 1, 4]], cells[:, [5, 4, 2]],
                               cells[:, [3, 4, 5]]])
        element = np.tile(np.arange(cells.shape[0]), 4)
    else:  # midside (and centre) nodes: each element as triangles fanned from its centre
        triangles, element = _fan(cells)
        if kind == "quad8":  # no centre node: add one, at the mean of the corners
            x = np.concatenate([x, x[cells[:, :4]].mean(axis=1)])
            y = np.concatenate([y, y[cells[:, :4]].mean(axis=1)])
            ux = np.concatenate([ux, ux[cells[:, :4]].mean(axis=1)])
            uy = np.concatenate([uy, uy[cells[:, :4]].mean(axis=1)])
    return x, y, ux, uy, triangles, element


def _fan(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of quad8/quad9 cells (meshio order) fanned from each element's centre: node
    8 of a quad9, or a node appended per element (index ``n_nodes + e``) for a quad8; and
    the element of every triangle."""
    n_elem = cells.shape[0]
    if cells.shape[1] == 9:
        centre = cells[:, 8]
    else:
        centre = int(cells.max()) + 1 + np.arange(n_elem)
    ring = cells[:, [0, 4, 1, 5, 2, 6, 3, 7]]  # corner, midside, corner, ... around the edge
    triangles = np.concatenate([np.column_stack([ring[:, k], ring[:, (k + 1) % 8], centre])
                                for k in range(8)])
    return triangles, np.tile(np.arange(n_elem), 8)


def plot_maps(result: BiaxialResult, axial_strain: float, path: str | Path) -> Path:
    """Maps of u_x, u_y [mm] and shear strain γ [%] at the step nearest ``axial_strain``.

    Drawn on the deformed mesh (true scale), after Wu et al. (2025), Fig. 8.
    """
    plt = pyplot()
    from matplotlib.tri import Triangulation

    steps = result.steps
    row = result.row_nearest(axial_strain)
    step = int(steps["step"].iloc[row])
    u = result.displacements[row]
    xy, cells, kind, dofs = result.problem.nodes()
    points = result.points[result.points["step"] == step]
    gamma = points.groupby("element")["shear_strain"].mean().to_numpy()
    x, y, ux, uy, triangles, element = deformed_triangles(xy, cells, kind, u[dofs[0]],
                                                          u[dofs[1]])
    tri = Triangulation(1e3 * x, 1e3 * y, triangles)
    fig, axes = plt.subplots(1, 3, figsize=(12, 5))
    fig.subplots_adjust(**_PLAIN_LAYOUT["maps"])
    for ax, values, title in ((axes[0], 1e3 * ux, "u_x [mm]"), (axes[1], 1e3 * uy, "u_y [mm]")):
        im = ax.tripcolor(tri, values, shading="gouraud", cmap="viridis")
        fig.colorbar(im, ax=ax, label=title)
    im = axes[2].tripcolor(tri, facecolors=100 * gamma[element], cmap="inferno",
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
    try:
        return save_figure(fig, path, compress_level=FAST_PNG)
    finally:
        plt.close(fig)
