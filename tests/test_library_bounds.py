"""Bounds the library keeps when called from Python (issue 47): work a user can make long is
refused before any allocation, with the estimate in the message, and values no contact law
or machine can hold are refused by the field that names them."""

from __future__ import annotations

import dataclasses
import math
import time

import pytest
from granular_material_pore_fractal.boxes import MAX_PER_OCTAVE, physical_boxes
from hypothesis import given, settings
from hypothesis import strategies as st

from granular_material.errors import ParameterError
from granular_material.multiscale.parameters import MAX_SHARDS, DEMMaterialParameters
from granular_material.procedures.packing import max_pressure, min_pressure


@pytest.mark.parametrize("per_octave", [MAX_PER_OCTAVE + 1, 10**8, 10**300, 10**400])
def test_physical_boxes_refuses_too_many_sides_before_making_them(per_octave):
    start = time.perf_counter()
    with pytest.raises(ValueError, match=r"per_octave .*candidate box sides over .* doublings"
                                         r"\) needs about ([0-9.e+]+|inf) [kMGTPE]?B"):
        physical_boxes(0.3e-3, 512, per_octave=per_octave)
    assert time.perf_counter() - start < 0.5  # nothing was made (10**8 took 33 s to fail)


def test_physical_boxes_at_the_bound_gives_every_pixel_side_once():
    sides = physical_boxes(0.3e-3, 512, per_octave=MAX_PER_OCTAVE)
    # from 8 to 128 pixels (2.4 mm to 38.4 mm at 0.3 mm): 1024 a doubling hit every integer
    assert list(sides) == list(range(128, 7, -1))


@pytest.mark.parametrize("n_pixels", [0, -4, 2.5, True])
def test_physical_boxes_names_a_bad_image_size(n_pixels):
    with pytest.raises(ValueError, match="n_pixels must be a positive integer"):
        physical_boxes(0.3e-3, n_pixels)


@given(per_octave=st.integers(1, MAX_PER_OCTAVE), n_pixels=st.integers(16, 4096))
@settings(max_examples=40, deadline=None)
def test_physical_boxes_within_the_bound_are_distinct_and_in_range(per_octave, n_pixels):
    try:
        sides = physical_boxes(0.3e-3, n_pixels, per_octave=per_octave)
    except ValueError as exc:
        assert "fewer than two sides" in str(exc)
        return
    assert len(set(sides)) == len(sides) >= 2 and all(sides[:-1] > sides[1:])
    assert sides[-1] == 8 and sides[0] <= max(8, n_pixels // 2, 128)


def test_shards_beyond_the_cap_are_refused_by_name():
    DEMMaterialParameters(shards=MAX_SHARDS)
    with pytest.raises(ParameterError, match=rf"shards must be at most {MAX_SHARDS}") as caught:
        DEMMaterialParameters(shards=10**9)
    assert caught.value.field == "shards"


@given(confining=st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                           st.integers(-10**400, 10**400)))
@settings(max_examples=200, deadline=None)
def test_confining_is_taken_only_where_a_packing_can_be_consolidated_to_it(confining):
    """Prepared packings: any number is either taken (then within the contact law's range,
    min_pressure to max_pressure of the default material) or refused naming confining."""
    p = DEMMaterialParameters().packing
    lowest, highest = min_pressure(p.meta, p.radius_range), max_pressure(p.meta, p.radius_range)
    try:
        taken = DEMMaterialParameters(confining=confining)
    except ParameterError as exc:
        assert exc.field == "confining"
        assert not lowest <= confining <= highest  # NaN compares False
        return
    assert lowest <= taken.confining <= highest


def test_confining_1e300_names_the_overlap_and_the_highest_pressure():
    with pytest.raises(ParameterError, match=r"confining 1e\+300 Pa would press the discs "
                                             r"6.67e\+292 of their radius .* at most 1.5e\+06 Pa"):
        DEMMaterialParameters(confining=1e300)


def test_confining_beside_an_rve_file_or_an_initial_stress_only_finite_and_positive(tmp_path):
    # the file's own material (or the initial stress) sets what the RVEs hold, not confining
    DEMMaterialParameters(rve=tmp_path / "rves.npz", confining=1e7)
    for bad in (math.inf, -1.0, 0.0, math.nan):
        with pytest.raises(ParameterError, match=r"confining must be a (positive|finite) number"):
            DEMMaterialParameters(rve=tmp_path / "rves.npz", confining=bad)


_ANY_VALUE = st.one_of(
    st.none(), st.booleans(), st.text(max_size=8), st.floats(),
    st.integers(-(10**400), 10**400), st.lists(st.integers(-3, 3), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2), st.binary(max_size=4))


@pytest.mark.parametrize("name", [f.name for f in dataclasses.fields(DEMMaterialParameters)])
@given(value=_ANY_VALUE)
@settings(max_examples=40, deadline=None)
def test_every_dem_parameter_takes_its_type_or_names_itself(name, value):
    """Any value of any type for one field of the DEM material's parameters is taken or is a
    ParameterError naming that field: never a TypeError, an AttributeError or an overflow."""
    try:
        DEMMaterialParameters(**{name: value})
    except ParameterError as exc:
        assert exc.field == name, (name, value, exc)
