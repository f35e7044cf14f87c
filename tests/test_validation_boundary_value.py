"""The closed-form bounds of the boundary-value report (Prandtl, Rankine), against the values
DESIGN.md §5 quotes."""

from __future__ import annotations

import pytest
from granular_material_validation.boundary_value import bearing_factor, rankine


@pytest.mark.parametrize("phi, n_q", [(29.0, 16.4), (30.0, 18.4), (35.0, 33.3)])
def test_prandtl_bearing_factor(phi, n_q):
    assert bearing_factor(phi) == pytest.approx(n_q, abs=0.05)


def test_rankine_coefficients():
    k_p, k_a = rankine(30.0)
    assert k_p == pytest.approx(3.0)
    assert k_a == pytest.approx(1 / 3)
    assert rankine(0.0) == pytest.approx((1.0, 1.0))
