"""Figures of a boundary-value problem: the load–displacement curve of each loaded boundary
and the map of the failure mechanism (shear strain on the deformed mesh)."""

from __future__ import annotations

from collections.abc import Collection, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from granular_material.results.plots import FAST_PNG, deformed_triangles, pyplot, save_figure

__all__ = ["length_unit", "plot_load_displacement", "plot_mechanism",
           "plot_phased_load_displacement", "plot_strength_reduction"]


def length_unit(size: float) -> tuple[str, float]:
    """The unit a figure gives lengths in for a domain of ``size`` [m] (its larger extent):
    ("mm", 1e3) below 1 m (a laboratory specimen, a model footing), ("m", 1.0) from 1 m (a
    slope, an embankment); the second is the factor from metres."""
    return ("mm", 1e3) if size < 1.0 else ("m", 1.0)


def plot_load_displacement(steps: pd.DataFrame, bodies: Sequence[tuple[str, str, float]],
                           path: str | Path,
                           references: Sequence[tuple[str, float]] = (),
                           size: float = 0.0) -> Path:
    """One panel per moved boundary: its mean pressure against its displacement.

    ``bodies``: (name, axis "x" | "y", width [m]) of each moved boundary; the curve is
    −F/width [kPa] (compression positive) against the displacement along its motion,
    read from the ``steps`` columns ``{name}_force_{axis}`` [N/m] and
    ``{name}_displacement`` [m]. ``references``: horizontal lines (label, pressure [Pa]),
    e.g. Prandtl's q·N_q. ``size``: the domain's larger extent [m], which sets the unit of
    the displacement and the width (:func:`length_unit`; 0: mm).
    """
    unit, factor = length_unit(size)
    plt = pyplot()
    n = max(len(bodies), 1)
    fig, axes = plt.subplots(1, n, figsize=(5.5 * n, 4.2), constrained_layout=True,
                             squeeze=False)
    for ax, (name, axis, width) in zip(axes[0], bodies, strict=False):
        force = steps[f"{name}_force_{axis}"].to_numpy(dtype=float)
        moved = steps[f"{name}_displacement"].to_numpy(dtype=float)
        sign = -1.0 if np.nanmean(force[1:] if force.size > 1 else force) < 0 else 1.0
        ax.plot(factor * moved, sign * force / width / 1e3, "o-", ms=3, label=name)
        for label, value in references:
            ax.axhline(value / 1e3, ls="--", lw=1, color="0.4")
            ax.annotate(label, (0.02, value / 1e3), xycoords=("axes fraction", "data"),
                        va="bottom", fontsize=8, color="0.3")
        ax.set_xlabel(f"{name} displacement [{unit}]")
        ax.set_ylabel(f"{name} mean pressure [kPa] (force / {factor * width:g} {unit})")
        ax.grid(alpha=0.3)
        ax.set_title(name)
    try:
        return save_figure(fig, path, compress_level=FAST_PNG)
    finally:
        plt.close(fig)


def plot_mechanism(xy: np.ndarray, cells: np.ndarray, kind: str, ux: np.ndarray,
                   uy: np.ndarray, shear_strain: np.ndarray, path: str | Path,
                   title: str = "", scale: float = 1.0,
                   dem_elements: np.ndarray | None = None) -> Path:
    """The mechanism: shear strain γ [%] of every element (``shear_strain``, (nelems,)) on
    the mesh displaced by ``scale`` × (ux, uy) [m] (nodal, meshio order of ``cells``), with
    the nodes' displacement as arrows (the longest a twentieth of the mesh's width, its
    length written beside). Lengths in mm for a mesh under 1 m, else in m
    (:func:`length_unit`). ``dem_elements`` (nelems,) bool: the elements whose points are
    DEM RVEs in an adaptive run, outlined."""
    plt = pyplot()
    from matplotlib.tri import Triangulation

    x, y, dx, dy, triangles, element = deformed_triangles(xy, cells, kind, scale * ux,
                                                          scale * uy)
    unit, f = length_unit(max(float(np.ptp(xy[:, 0])), float(np.ptp(xy[:, 1]))))
    tri = Triangulation(f * x, f * y, triangles)
    gamma = 100 * np.asarray(shear_strain, dtype=float)
    width = np.ptp(x) / max(np.ptp(y), 1e-12)
    fig, ax = plt.subplots(figsize=(4 + 4 * min(width, 2.5), 5), constrained_layout=True)
    im = ax.tripcolor(tri, facecolors=gamma[element], cmap="inferno", vmin=0.0,
                      vmax=max(float(np.nanpercentile(gamma, 99)), 1e-12))
    fig.colorbar(im, ax=ax, label="shear strain γ [%]")
    n = xy.shape[0]
    every = max(n // 400, 1)
    longest = float(np.hypot(dx[:n], dy[:n]).max())
    if longest > 0:  # the longest arrow a twentieth of the mesh's width
        ax.quiver(f * x[:n:every], f * y[:n:every], f * dx[:n:every],
                  f * dy[:n:every], color="cyan", alpha=0.6, width=0.002, angles="xy",
                  scale_units="xy", scale=f * longest / (0.05 * f * np.ptp(x)))
        ax.annotate(f"arrows: displacement, the longest {f * longest / scale:.3g} {unit}",
                    (0.01, 0.01), xycoords="axes fraction", fontsize=8, color="0.3")
    if dem_elements is not None and np.any(dem_elements):
        inside = np.asarray(dem_elements, dtype=bool)[element]
        ax.triplot(Triangulation(f * x, f * y, triangles[inside]), color="lime", lw=0.5,
                   alpha=0.8)
        ax.annotate(f"green: DEM RVEs ({int(np.sum(dem_elements))} of "
                    f"{len(dem_elements)} elements), the twin elsewhere", (0.01, 0.96),
                    xycoords="axes fraction", fontsize=8, color="0.3")
    ax.set_aspect("equal")
    ax.set_xlabel(f"x [{unit}]")
    ax.set_ylabel(f"y [{unit}]")
    ax.set_title(title)
    try:
        return save_figure(fig, path, compress_level=FAST_PNG)
    finally:
        plt.close(fig)


def plot_phased_load_displacement(steps: pd.DataFrame,
                                  curves: Sequence[tuple[str, str, str]],
                                  path: str | Path, resets: Collection[str] = (),
                                  size: float = 0.0) -> Path:
    """The load–displacement curves of a run in phases: one panel per curve, each phase's
    rows a line of its own, from where the phase before ended (at zero displacement for
    the phases of ``resets``, whose displacement is measured from their start).

    ``curves``: (name, load column [Pa], displacement column [m]) of each; ``steps`` must
    have a ``phase`` column. ``size``: the domain's larger extent [m], which sets the unit
    of the displacement (:func:`length_unit`; 0: mm).
    """
    unit, factor = length_unit(size)
    plt = pyplot()
    n = max(len(curves), 1)
    fig, axes = plt.subplots(1, n, figsize=(5.5 * n, 4.2), constrained_layout=True,
                             squeeze=False)
    order = list(dict.fromkeys(steps["phase"]))
    for ax, (name, load, moved) in zip(axes[0], curves, strict=False):
        p = steps[load].to_numpy(dtype=float)
        d = steps[moved].to_numpy(dtype=float)
        phase = steps["phase"].to_numpy()
        for k, label in enumerate(order):
            rows = np.flatnonzero(phase == label)
            if k > 0 and rows.size and rows[0] > 0:
                before = rows[0] - 1  # the phase starts where the one before ended
                x = np.concatenate([[0.0 if label in resets else d[before]], d[rows]])
                y = np.concatenate([[p[before]], p[rows]])
            else:
                x, y = d[rows], p[rows]
            ax.plot(factor * x, y / 1e3, "o-", ms=3, label=str(label))
        ax.set_xlabel(f"{name} displacement [{unit}]")
        ax.set_ylabel(f"{name} load [kPa]")
        ax.grid(alpha=0.3)
        ax.set_title(name)
        ax.legend(title="phase", fontsize=8)
    try:
        return save_figure(fig, path, compress_level=FAST_PNG)
    finally:
        plt.close(fig)


def plot_strength_reduction(factor: Sequence[float], displacement: Sequence[float],
                            path: str | Path, found: float | None = None,
                            stopped_by: str = "") -> Path:
    """The strength reduction factor F [-] against the largest nodal displacement [m] of
    each step, the factor of safety ``found`` marked (how the reduction ``stopped_by``)."""
    d = np.asarray(displacement, dtype=float)
    unit, scale = length_unit(float(d.max(initial=0.0)))
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.0, 3.6), constrained_layout=True)
    ax.plot(scale * d, np.asarray(factor, dtype=float), "o-", ms=2.5)
    if found is not None:
        ax.axhline(found, color="0.4", ls="--", lw=0.8, label=f"F = {found:.3f} ({stopped_by})")
        ax.legend(loc="lower right", fontsize=8)
    ax.set_xlabel(f"largest nodal displacement [{unit}]")
    ax.set_ylabel("strength reduction factor F [-]")
    ax.grid(alpha=0.3)
    try:
        return save_figure(fig, path, dpi=110, compress_level=FAST_PNG)
    finally:
        plt.close(fig)
