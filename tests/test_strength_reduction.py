"""Strength reduction of Mohr–Coulomb: MohrCoulombParameters.reduced, the material's
reduce_strength (from the committed state, kept by checkpoints) and the regional material's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from granular_material.errors import ParameterError
from granular_material.fem import LinearElastic, MohrCoulomb, RegionalMaterial
from granular_material.fem.materials.mohr_coulomb import MohrCoulombParameters
from granular_material.fem.materials.mohr_coulomb_return import (
    ELASTIC,
    in_plane_principal,
    yield_function,
)

#: a stress inside the surface of φ = 30°, c = 20 kPa (f ≈ −60 kPa) but outside the surface
#: reduced by F = 2 (f ≈ +34 kPa): in-plane (σxx, σyy) and σzz [Pa]
INSIDE = np.diag([-100e3, -250e3])
INSIDE_ZZ = -150e3


def _material(**kwargs) -> MohrCoulomb:
    material = MohrCoulomb(friction_angle=30.0, dilation_angle=10.0, cohesion=20e3,
                           initial_stress=INSIDE, initial_stress_zz=INSIDE_ZZ, **kwargs)
    material.allocate(1)
    return material


def _f(stress: np.ndarray, zz: np.ndarray, parameters: MohrCoulombParameters) -> np.ndarray:
    principal = -np.sort(-in_plane_principal(stress, zz)[0], axis=1)
    return yield_function(principal, math.radians(parameters.friction_angle),
                          parameters.cohesion)


def test_reduced_divides_cohesion_and_tangents():
    p = MohrCoulombParameters(young=30e6, poisson=0.25, friction_angle=35.0,
                              dilation_angle=35.0, cohesion=12e3, critical_friction_angle=30.0,
                              softening_strain=0.02)
    r = p.reduced(1.4)
    assert r.cohesion == pytest.approx(12e3 / 1.4, rel=1e-15)
    for name in ("friction_angle", "dilation_angle", "critical_friction_angle"):
        assert math.tan(math.radians(getattr(r, name))) == pytest.approx(
            math.tan(math.radians(getattr(p, name))) / 1.4, rel=1e-13)
    assert r.dilation_angle <= r.friction_angle and r.critical_friction_angle < r.friction_angle
    assert (r.young, r.poisson, r.softening_strain) == (p.young, p.poisson, p.softening_strain)
    assert p.reduced(1.0) is p and p.reduced(1) == p
    assert p.reduced(0.5).friction_angle > p.friction_angle  # F < 1 strengthens
    tresca = MohrCoulombParameters(friction_angle=0.0, cohesion=50e3).reduced(2.0)
    assert (tresca.friction_angle, tresca.cohesion) == (0.0, 25e3)
    assert MohrCoulombParameters(dilation_angle=0.0).reduced(3.0).dilation_angle == 0.0
    for bad in (0.0, -1.0, math.inf, math.nan, "2", True, None):
        with pytest.raises(ParameterError) as info:
            p.reduced(bad)
        assert info.value.field == "factor"


def test_reduce_strength_returns_the_committed_stress_onto_the_reduced_surface():
    material = _material()
    original = material.parameters
    assert material.strength_factor == 1.0
    assert _f(material.stress, material.stress_zz, original)[0] < -50e3
    before = material.evaluate(np.zeros((1, 2, 2)))  # inside the original surface: elastic
    assert before.fields["return_region"][0] == ELASTIC
    np.testing.assert_array_equal(before.stress, material.stress)
    material.reduce_strength(2.0)
    assert material.strength_factor == 2.0 and material.parameters == original
    reduced = original.reduced(2.0)
    assert _f(material.stress, material.stress_zz, reduced)[0] > 30e3  # now outside
    np.testing.assert_array_equal(material.stress, INSIDE[None])  # committed state kept
    assert material.plastic_shear_strain[0] == 0.0
    after = material.evaluate(np.zeros((1, 2, 2)))
    assert after.ok and after.fields["return_region"][0] != ELASTIC
    f = _f(after.stress, after.fields["stress_zz"], reduced)[0]
    assert abs(f) <= 1e-9 * 250e3
    assert after.fields["friction_angle"][0] == pytest.approx(reduced.friction_angle,
                                                             rel=1e-14)
    material.commit()
    assert material.plastic_shear_strain[0] > 0


def test_factor_one_is_bit_for_bit_the_unreduced_material():
    grad = np.array([[[1e-3, 2e-4], [-1e-4, -3e-3]]])
    plain, undone = _material(), _material()
    undone.reduce_strength(1.7)
    undone.reduce_strength(1.0)
    a, b = plain.evaluate(grad), undone.evaluate(grad)
    assert a.fields["return_region"][0] != ELASTIC
    np.testing.assert_array_equal(a.stress, b.stress)
    np.testing.assert_array_equal(a.tangent, b.tangent)
    for bad in (0.0, -2.0, math.inf):
        with pytest.raises(ParameterError, match="factor"):
            plain.reduce_strength(bad)
    assert plain.strength_factor == 1.0


def test_checkpoint_keeps_the_factor_and_an_old_checkpoint_restores_at_one(tmp_path):
    material = _material()
    material.reduce_strength(2.0)
    material.evaluate(np.zeros((1, 2, 2)))
    material.commit()
    material.checkpoint(tmp_path / "state.npz")
    again = _material()
    again.restore(tmp_path / "state.npz")
    assert again.strength_factor == 2.0
    grad = np.array([[[2e-4, 0.0], [0.0, -5e-4]]])
    np.testing.assert_array_equal(again.evaluate(grad).stress, material.evaluate(grad).stress)
    # a checkpoint written before strength reduction existed holds no factor: F = 1
    with np.load(tmp_path / "state.npz") as data:
        old = {k: data[k] for k in data.files if k != "strength_factor"}
    np.savez(tmp_path / "old.npz", **old)
    again.restore(tmp_path / "old.npz")
    assert again.strength_factor == 1.0
    np.testing.assert_array_equal(again.evaluate(grad).stress,
                                  _restored_plain(tmp_path, old).evaluate(grad).stress)


def _restored_plain(tmp_path, old) -> MohrCoulomb:
    """A material never reduced, restored from the same state."""
    plain = _material()
    np.savez(tmp_path / "plain.npz", **old)
    plain.restore(tmp_path / "plain.npz")
    return plain


def test_regional_material_reduces_every_mohr_coulomb_region(tmp_path):
    clay = MohrCoulomb(friction_angle=0.0, cohesion=40e3, initial_stress=-100e3)
    sand = MohrCoulomb(friction_angle=32.0, initial_stress=-100e3)
    rock = LinearElastic(young=1e9, poisson=0.2, initial_stress=-100e3)
    layers = RegionalMaterial({"clay": clay, "sand": sand, "rock": rock},
                              ["clay", "sand", "rock", "clay"])
    layers.allocate(4)
    assert layers.strength_factor == 1.0
    for bad in (0.0, math.nan):
        with pytest.raises(ParameterError) as info:
            layers.reduce_strength(bad)
        assert info.value.field == "factor"
    assert clay.strength_factor == sand.strength_factor == 1.0
    layers.reduce_strength(1.25)
    assert layers.strength_factor == clay.strength_factor == sand.strength_factor == 1.25
    layers.evaluate(np.zeros((4, 2, 2)))
    layers.commit()
    layers.checkpoint(tmp_path / "layers.npz")
    layers.reduce_strength(1.0)
    layers.restore(tmp_path / "layers.npz")
    assert layers.strength_factor == clay.strength_factor == 1.25
    elastic = RegionalMaterial({"rock": LinearElastic(young=1e9, poisson=0.2)}, ["rock"] * 2)
    with pytest.raises(ParameterError, match="no region's material") as info:
        elastic.reduce_strength(1.5)
    assert info.value.field == "factor" and elastic.strength_factor == 1.0


def test_strength_reduction_of_a_strip_load_on_clay_finds_prandtls_factor():
    """The driver's strength reduction (fem.solver.strength_reduction) on this material: a
    strip load q = 3c on weightless Tresca clay (half of it, B = 1 m) stands until
    F ≈ (2 + π) c / q (measured 1.008 × that on this 10 × 6 quad8 mesh)."""
    from granular_material.fem import (
        Fixed,
        NewtonSettings,
        NewtonSolver,
        Pressure,
        Roller,
        build_problem,
        rectangle_mesh,
        select_boundaries,
    )
    from granular_material.fem.solver.strength_reduction import strength_reduction

    c, q = 10e3, 30e3
    data = select_boundaries(rectangle_mesh(2.5, 1.5, 10, 6, "quad8", grading=(1.0, 0.3),
                                            origin=(0.0, -1.5)),
                             {"footing": "y = top and x <= 0.5"})
    problem = build_problem(data, [Fixed("bottom"), Roller("left", 0), Roller("right", 0),
                                   Pressure("footing", q)])
    material = MohrCoulomb(young=10e6, poisson=0.3, friction_angle=0.0, cohesion=c)
    solver = NewtonSolver(problem.basis, material, problem.loading,
                          NewtonSettings(formulation="small-strain", rtol=1e-8))
    solver.run(4)
    result = strength_reduction(solver, factor_end=3.0, steps=20)
    assert result.stopped_by == "collapse" and result.error is None
    ratio = result.factor_of_safety / ((2 + math.pi) * c / q)
    assert 1.0 < ratio < 1.1, ratio
    assert material.strength_factor == pytest.approx(result.factors[-1])
