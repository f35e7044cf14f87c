"""Bishop's simplified method (granular_material.limit_equilibrium) against published factors
of safety, a closed form, and its edge cases.

Published values:
- Griffiths & Lane (1999), Géotechnique 49(3) 387–403, Example 1: a 2:1 slope of height H on
  a foundation of depth H, φ' = 20°, c'/(γH) = 0.05; Bishop & Morgenstern's charts give
  F = 1.380 (read from a chart: 1.5 % allowed).
- code_aster validation case SSNP006 (V6.03.006): a 1:2 slope 4.5 m high in a model 6.5 m
  high, γ = 16 kN/m³, φ = 20°, c = 5 kPa; Bishop's simplified method with a grid of centres
  (Verruijt) gives F = 1.534 (a computed value: 1 % allowed).
- code_aster validation case SSNP507 (V6.03.507), Griffiths & Lane's clay slope on a
  foundation: 2:1, height H, foundation depth H, φ = 0, c_u1 = 0.25 γH in the slope and
  λ c_u1 below; circular slip surfaces give F = 2.032 for λ >= 1.5 (the circle stays in the
  slope) and 1.448 for λ = 1 (read from a figure; the exact circle of that geometry is 1.6 %
  above it: 2 % allowed).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from granular_material.errors import ParameterError
from granular_material.limit_equilibrium import (
    Ground,
    Layer,
    Surcharge,
    critical_circle,
    factor_of_safety,
    gravity_increase_factor,
)

#: a small search: enough for these slopes, each test well under a second or two
FAST = {"grid": 10, "slices": 60}


def _slope(height: float, run: float, layers: tuple[Layer, ...], crest: float = 20.0,
           toe: float = 30.0, mirrored: bool = False) -> Ground:
    """A slope of ``height`` falling over a horizontal ``run`` from a crest at y = height to
    level ground at y = 0 (to the right, or to the left when ``mirrored``)."""
    points = [(-crest, height), (0.0, height), (run, 0.0), (run + toe, 0.0)]
    if mirrored:
        points = [(-x, y) for x, y in reversed(points)]
    return Ground(surface=tuple(points), layers=layers)


def test_griffiths_and_lane_example_1_is_bishop_and_morgenstern_s_1_380():
    h, gamma = 10.0, 20e3
    ground = _slope(h, 2 * h, (Layer(-h, 0.05 * gamma * h, 20.0, gamma),))
    found = critical_circle(ground, **FAST)
    assert found.factor == pytest.approx(1.380, rel=0.015)
    # a toe circle: it leaves the ground at the toe
    assert found.result.exit == pytest.approx(2 * h, abs=0.05 * h)


@pytest.mark.parametrize("crest", [3.0, 6.0])
def test_code_aster_ssnp006_is_verruijt_s_1_534(crest):
    ground = Ground(surface=((0.0, 6.5), (crest, 6.5), (crest + 9.0, 2.0), (18.0, 2.0)),
                    layers=(Layer(0.0, 5e3, 20.0, 16e3),))
    assert critical_circle(ground, **FAST).factor == pytest.approx(1.534, rel=0.01)


@pytest.mark.parametrize(("ratio", "expected", "tolerance", "deep"),
                         [(4.0, 2.032, 0.01, False), (1.0, 1.448, 0.02, True)])
def test_a_clay_slope_on_a_foundation_as_griffiths_and_lane(ratio, expected, tolerance, deep):
    h, gamma = 10.0, 20e3
    c1 = 0.25 * gamma * h
    ground = _slope(h, 2 * h, (Layer(0.0, c1, 0.0, gamma), Layer(-h, ratio * c1, 0.0, gamma)),
                    crest=30.0, toe=40.0)
    found = critical_circle(ground, **FAST)
    assert found.factor == pytest.approx(expected, rel=tolerance)
    lowest = found.result.centre[1] - found.result.radius
    if deep:  # the circle reaches down to the firm base
        assert lowest == pytest.approx(-h, abs=0.01 * h)
    else:  # it stays in the slope, above the stronger foundation
        assert lowest > -0.01 * h


def test_undrained_quarter_circle_is_its_closed_form():
    """A vertical cut (φ = 0) and the circle centred on its crest edge with radius H: the
    quarter disc of weight γπH²/4 at lever 4H/(3π), resisted by c along πH/2:
    F = 3π c / (2 γ H)."""
    h, c, gamma = 10.0, 20e3, 18e3
    ground = Ground(surface=((-30.0, h), (0.0, h), (1e-9, 0.0), (30.0, 0.0)),
                    layers=(Layer(-h, c, 0.0, gamma),))
    result = factor_of_safety(ground, (0.0, h), h, slices=400, m_alpha_min=1e-9)
    assert result.factor == pytest.approx(3 * math.pi * c / (2 * gamma * h), rel=2e-3)
    assert result.weight == pytest.approx(gamma * math.pi * h * h / 4, rel=2e-3)
    assert (result.entry, result.exit) == pytest.approx((-h, 0.0), abs=1e-6)


def test_the_gravity_factor_brings_f_to_one_as_dividing_the_cohesion_does():
    """F depends on c/γ alone in a uniform slope: multiplying γ by g is dividing c by g, so
    the slope with c/g stands at F = 1 on the circle found."""
    h, gamma, c = 10.0, 20e3, 10e3
    ground = _slope(h, 1.5 * h, (Layer(-5.0, c, 20.0, gamma),), crest=15.0, toe=20.0)
    g, at = gravity_increase_factor(ground, grid=8, slices=40, tol=2e-3)
    assert g > 1.2
    assert at.factor == pytest.approx(1.0, abs=3e-3)
    weaker = _slope(h, 1.5 * h, (Layer(-5.0, c / g, 20.0, gamma),), crest=15.0, toe=20.0)
    same = factor_of_safety(weaker, at.result.centre, at.result.radius, slices=40)
    assert same.factor == pytest.approx(at.factor, rel=1e-9)
    # and the weight factor does not move F where there is no cohesion
    sand = _slope(h, 3 * h, (Layer(-5.0, 0.0, 35.0, gamma),))
    circle = (15.0, 30.0), 31.0
    assert factor_of_safety(sand, *circle, gravity=3.0).factor == pytest.approx(
        factor_of_safety(sand, *circle).factor, rel=1e-12)


def test_the_issue_s_embankment_matches_the_user_s_bishop_figure():
    """The embankment 10 m high at 1.5:1 on a 5 m foundation, c = 10 kPa, φ = 20°,
    γ = 20 kN/m³: the user's Bishop F was 1.142 (our search: 1.1427)."""
    ground = _slope(10.0, 15.0, (Layer(0.0, 10e3, 20.0, 20e3), Layer(-5.0, 10e3, 20.0, 20e3)),
                    crest=15.0, toe=20.0)
    assert critical_circle(ground, **FAST).factor == pytest.approx(1.142, rel=0.005)


def test_a_slope_facing_left_has_the_factor_of_its_mirror_image():
    layers = (Layer(-10.0, 10e3, 25.0, 19e3),)
    right = critical_circle(_slope(10.0, 20.0, layers), **FAST)
    left = critical_circle(_slope(10.0, 20.0, layers, mirrored=True), **FAST)
    assert left.factor == pytest.approx(right.factor, rel=1e-3)
    assert left.result.centre[0] == pytest.approx(-right.result.centre[0], abs=0.2)


def test_a_crest_surcharge_lowers_f_and_a_surcharge_off_the_mass_does_nothing():
    layers = (Layer(-10.0, 10e3, 20.0, 20e3),)
    bare = _slope(10.0, 15.0, layers)
    circle = critical_circle(bare, **FAST).result
    loaded = Ground(bare.surface, layers, (Surcharge(circle.entry, 0.0, 50e3),))
    far = Ground(bare.surface, layers, (Surcharge(-20.0, circle.entry - 1.0, 50e3),))
    f0 = factor_of_safety(bare, circle.centre, circle.radius).factor
    assert factor_of_safety(loaded, circle.centre, circle.radius).factor < 0.95 * f0
    assert factor_of_safety(far, circle.centre, circle.radius).factor == f0


def test_m_alpha_is_held_at_its_floor_where_the_circle_turns_steep():
    """The quarter circle of the vertical cut enters the crest vertically: there m_α = cos α
    (φ = 0) falls below 0.2, and holding it at 0.2 caps those slices' resistance."""
    h = 10.0
    ground = Ground(surface=((-30.0, h), (0.0, h), (1e-9, 0.0), (30.0, 0.0)),
                    layers=(Layer(-h, 20e3, 0.0, 18e3),))
    held = factor_of_safety(ground, (0.0, h), h)
    free = factor_of_safety(ground, (0.0, h), h, m_alpha_min=1e-9)
    assert held.held > 0 and free.held == 0
    assert held.factor < free.factor


@pytest.mark.parametrize(("centre", "radius"), [
    ((0.0, 50.0), 5.0),       # above the ground: it misses it
    ((-5.0, 10.0), 30.0),     # through the ends of the surface
    ((5.0, 2.0), 9.0),        # centre below the crest: the mass hangs over the circle's side
    ((10.0, 15.0), 30.0),     # below the firm base
])
def test_a_circle_with_no_admissible_mass_is_refused_naming_it(centre, radius):
    ground = _slope(10.0, 20.0, (Layer(-10.0, 10e3, 20.0, 20e3),))
    with pytest.raises(ParameterError, match="cuts no admissible sliding mass") as info:
        factor_of_safety(ground, centre, radius)
    assert info.value.field == "circle"


def test_a_cohesionless_slope_has_no_gravity_factor_and_bad_input_is_refused():
    sand = _slope(5.0, 15.0, (Layer(-5.0, 0.0, 35.0, 18e3),))
    f = critical_circle(sand, **FAST).factor
    assert f == pytest.approx(math.tan(math.radians(35)) * 3.0, rel=0.05)  # the infinite
    with pytest.raises(ParameterError, match="stands") as info:  # slope's tan φ / tan β
        gravity_increase_factor(sand, **FAST, upper=4.0)
    assert info.value.field == "gravity"
    for build, field in [
            (lambda: Ground(((0, 1), (0, 2)), (Layer(-1, 0, 30, 1),)), "surface"),
            (lambda: Ground(((0, 1), (1, 0)), (Layer(-1, 0, 30, 1), Layer(0, 0, 30, 1))),
             "layers"),
            (lambda: Layer(-1, 0, 90, 1), "friction_angle"),
            (lambda: Layer(-1, -5, 30, 1), "cohesion"),
            (lambda: Surcharge(2, 1, 10), "end"),
            (lambda: Ground(((0, 1), (1, -2)), (Layer(-1, 0, 30, 1),)), "layers"),
            (lambda: gravity_increase_factor(sand, tol=0.5), "tol"),
            (lambda: critical_circle(sand, grid=np.zeros((2, 2))), "grid"),
            (lambda: factor_of_safety(sand, (0, 20), 25, slices=2), "slices")]:
        with pytest.raises(ParameterError) as info:
            build()
        assert info.value.field == field
