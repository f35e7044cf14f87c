"""The boundary-value figures give lengths in a unit that fits the domain: mm for a model
footing under 1 m, m for a slope."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import granular_material.results.bvp_plots as bvp_plots
from granular_material.fem import rectangle_mesh


def _labels(monkeypatch) -> list:
    """The figures plot_* would save, kept open for their labels."""
    figures: list = []

    def keep(fig, path, **options):
        figures.append(fig)
        return path

    monkeypatch.setattr(bvp_plots, "save_figure", keep)
    return figures


@pytest.mark.parametrize(("width", "height", "unit", "factor"), [
    (50.0, 20.0, "m", 1.0), (0.6, 0.4, "mm", 1e3)])
def test_mechanism_and_curve_take_their_length_unit_from_the_domain(
        monkeypatch, tmp_path, width, height, unit, factor):
    figures = _labels(monkeypatch)
    data = rectangle_mesh(width, height, 4, 2, "quad4")
    xy = data.mesh.p.T
    cells = data.mesh.t.T
    u = 1e-3 * width * np.ones(xy.shape[0])
    bvp_plots.plot_mechanism(xy, cells, "quad", u, -u, np.linspace(0, 0.1, cells.shape[0]),
                             tmp_path / "m.png")
    ax = figures[0].axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == (f"x [{unit}]", f"y [{unit}]")
    assert ax.get_xlim()[1] >= factor * width * 0.99
    note = next(t.get_text() for t in ax.texts if "arrows" in t.get_text())
    assert note.endswith(f"{factor * np.hypot(1e-3 * width, 1e-3 * width):.3g} {unit}")
    steps = pd.DataFrame({"crest_force_y": [0.0, -1e3, -2e3],
                          "crest_displacement": [0.0, 0.01 * width, 0.02 * width]})
    bvp_plots.plot_load_displacement(steps, [("crest", "y", 0.1 * width)], tmp_path / "c.png",
                                     size=width)
    ax = figures[1].axes[0]
    assert ax.get_xlabel() == f"crest displacement [{unit}]"
    assert ax.get_ylabel().endswith(f"(force / {factor * 0.1 * width:g} {unit})")
    assert ax.lines[0].get_xdata()[-1] == pytest.approx(factor * 0.02 * width)
    for fig in figures:
        bvp_plots.pyplot().close(fig)
