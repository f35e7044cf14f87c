"""Shear-band measures of a Gauss-point shear-strain field."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from granular_material.results.localization import mohr_coulomb_inclination, shear_band


def _points(gamma_of_xy, n=(20, 40), step=7, strain=0.04) -> pd.DataFrame:
    x, y = np.meshgrid(np.linspace(0, 0.05, n[0]), np.linspace(0, 0.10, n[1]))
    x, y = x.ravel(), y.ravel()
    return pd.DataFrame({"step": step, "axial_strain": strain, "x": x, "y": y,
                         "shear_strain": gamma_of_xy(x, y)})


@pytest.mark.parametrize("angle", [60.0, -55.0, 48.0])
def test_inclined_band_is_found_with_its_angle(angle):
    t = math.radians(angle)
    normal = np.array([-math.sin(t), math.cos(t)])
    centre = np.array([0.025, 0.05])

    def gamma(x, y):
        distance = (x - centre[0]) * normal[0] + (y - centre[1]) * normal[1]
        return 0.01 + 0.2 * np.exp(-(distance / 0.003) ** 2)

    band = shear_band(_points(gamma))
    assert band.inclination_deg == pytest.approx(angle, abs=2.0)
    assert band.elongation > 0.95
    assert band.localization > 5
    assert (band.centre_x, band.centre_y) == pytest.approx(tuple(centre), abs=2e-3)
    assert band.step == 7 and band.axial_strain == 0.04


def test_homogeneous_field_shows_no_localisation():
    rng = np.random.default_rng(1)
    band = shear_band(_points(lambda x, y: 0.02 * (1 + 0.05 * rng.standard_normal(x.size))))
    assert band.localization < 1.15
    assert band.elongation < 0.9  # scattered points: no line


def test_mohr_coulomb_inclination_and_bad_input():
    assert mohr_coulomb_inclination(1.0) == 45.0
    assert mohr_coulomb_inclination(3.0) == pytest.approx(45 + 15)  # sin φ = 1/2
    with pytest.raises(ValueError, match="stress_ratio"):
        mohr_coulomb_inclination(0.5)
    with pytest.raises(ValueError, match="fraction"):
        shear_band(_points(lambda x, y: x), fraction=0.9)
    with pytest.raises(ValueError, match="columns"):
        shear_band(pd.DataFrame({"x": [0.0]}))
