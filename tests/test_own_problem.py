"""The guide's own boundary-value problem (examples/own_problem.py, docs/guide/own-problem.md)
runs at a small size, converges through its peak and writes a ParaView series."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest
from granular_material_examples import own_problem as example


@pytest.fixture(scope="module")
def softening(tmp_path_factory):
    out = tmp_path_factory.mktemp("own-problem")
    return example.main("mohr-coulomb", steps=8, settlement=0.024, out=out, progress=False,
                        elements=(4, 2)), out


def test_it_converges_through_the_peak(softening):
    curve, _ = softening
    assert curve.stopped == ""  # every step committed, cut-backs allowed
    assert len(curve.pressure) == 9 and curve.settlement[-1] == pytest.approx(0.024)
    # step 0 is the geostatic state: the footing carries the surcharge, q = 20 kPa
    assert curve.pressure[0] == pytest.approx(example.Q, rel=1e-6)
    k = curve.peak
    assert 0 < k < len(curve.pressure) - 2  # a peak with steps after it
    assert min(curve.pressure[k + 1:]) < 0.9 * curve.pressure[k]  # softening past it
    assert all(i > 0 for i in curve.iterations[1:])


def test_the_series_opens_as_paraview_would(softening):
    curve, out = softening
    root = ET.parse(out / "fields.pvd").getroot()
    entries = root.findall("./Collection/DataSet")
    assert len(entries) == len(curve.pressure)
    assert [float(e.get("timestep")) for e in entries] == pytest.approx(curve.settlement)
    last = meshio.read(out / entries[-1].get("file"))
    uy = last.point_data["displacement"][:, 1]
    assert uy.min() == pytest.approx(-0.024, rel=1e-9)  # the footing's settlement
    loose = np.asarray(last.cell_data["unconfined"][0])
    assert set(np.unique(loose)) <= {0.0, 1.0}
    # the cells flagged are those holding a point counted as unconfined in the last step
    assert loose.sum() <= curve.unconfined[-1]
    assert (loose.sum() > 0) == (curve.unconfined[-1] > 0)


def test_a_step_that_cannot_converge_stops_with_the_committed_ones_kept(monkeypatch):
    settings_made = example.NewtonSettings

    def no_cutbacks(**kwargs):
        return settings_made(**{**kwargs, "max_iterations": 1, "max_cutbacks": 0})

    monkeypatch.setattr(example, "NewtonSettings", no_cutbacks)
    curve = example.main("mohr-coulomb", steps=4, settlement=0.02, progress=False,
                         elements=(3, 2))
    assert "did not converge" in curve.stopped
    assert len(curve.pressure) >= 1 and curve.pressure[0] == pytest.approx(example.Q, rel=1e-6)


def test_the_same_problem_runs_through_its_peak_with_the_second_gradient():
    """The example with --internal-length: tri6 carries it; every step commits, the peak is
    passed, and v and λ are carried (the terms are there)."""
    curve = example.main("mohr-coulomb", steps=8, settlement=0.024, progress=False,
                         elements=(4, 2), internal_length=0.05)
    plain = example.main("mohr-coulomb", steps=8, settlement=0.024, progress=False,
                         elements=(4, 2))
    assert curve.stopped == ""
    assert curve.pressure[0] == pytest.approx(example.Q, rel=1e-6)
    assert 0 < curve.peak < len(curve.pressure) - 1
    # the double stress stiffens the bands: a different curve, above the classical one
    assert max(curve.pressure) > max(plain.pressure)
