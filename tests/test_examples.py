"""The examples run, at a small size, as the tests of what they show."""

from __future__ import annotations

import pytest
from granular_material_examples import skfem_material_swap as example


@pytest.mark.parametrize("element", ["quad1", "tri2"])
def test_swap_example_linear_elastic_matches_the_closed_form(element):
    stress = example.main("linear-elastic", element, axial_strain=0.004, steps=2)
    # σxx held at −P: σyy = P + E/(1−ν²) ε_a, E = 60 MPa, ν = 0.3
    assert stress[-1] == pytest.approx(100e3 + 60e6 / (1 - 0.09) * 0.004, rel=1e-9)


@pytest.mark.parametrize("element", ["quad1", "tri2"])
def test_swap_example_mohr_coulomb_peaks_at_the_closed_form(element):
    stress = example.main("mohr-coulomb", element, axial_strain=0.01, steps=5)
    # c = 0, φ = 30°: σ1/σ3 = (1 + sin φ)/(1 − sin φ) = 3 once yielding
    assert stress[-1] == pytest.approx(3 * 100e3, rel=1e-6)


@pytest.mark.parametrize("element", ["quad1", "tri2"])
def test_swap_example_dem_converges_with_totals_and_increments_alike(element, monkeypatch):
    monkeypatch.setitem(example.PARAMETERS, "dem", {**example.PARAMETERS["dem"],
                                                    "particles": 24})
    total = example.main("dem", element, axial_strain=0.002, steps=2, refine=0)
    increment = example.main("dem", element, axial_strain=0.002, steps=2, refine=0,
                             measure="increment")
    assert 100e3 < total[0] < total[1]  # compressed beyond the confinement, stiffening
    assert increment == pytest.approx(total, rel=1e-6)  # the same state either way


def test_swap_example_is_installed_with_its_scenes():
    from importlib.resources import files

    root = files("granular_material_examples")
    assert root.joinpath("skfem_material_swap.py").is_file()
    assert root.joinpath("scenes", "single-element.toml").is_file()
