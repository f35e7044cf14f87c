"""Materials by region (fem/materials/regions.py): the layered answer, the same material in
every region equal to the one material, checkpoint and restore, and the refusals."""

from __future__ import annotations

import numpy as np
import pytest

from granular_material.errors import ParameterError
from granular_material.fem import (
    Fixed,
    LinearElastic,
    MohrCoulomb,
    NewtonSettings,
    NewtonSolver,
    Pressure,
    RegionalMaterial,
    Roller,
    build_problem,
    point_regions,
    rectangle_mesh,
)

NU = 0.3
SMALL = NewtonSettings(formulation="small-strain")


def _layers(data):
    """The lower and upper halves' element indices of a rectangle mesh of height 0.5 m."""
    centre_y = data.mesh.p[1, data.mesh.t].mean(axis=0)
    return {"lower": np.flatnonzero(centre_y < 0.25), "upper": np.flatnonzero(centre_y > 0.25)}


def _column(data, p):
    return build_problem(data, [Fixed("bottom"), Roller("left", 0), Roller("right", 0),
                                Pressure("top", p)])


def _regional(problem, data, materials):
    return RegionalMaterial.from_elements(materials, _layers(data), problem.basis.nelems,
                                          problem.basis.X.shape[-1])


def test_two_layers_in_series_settle_by_the_sum_of_their_compressions():
    data = rectangle_mesh(0.2, 0.5, 2, 4, "quad8")
    p, e_lower, e_upper = 100e3, 20e6, 80e6
    problem = _column(data, p)
    material = _regional(problem, data, {"lower": LinearElastic(e_lower, NU),
                                         "upper": LinearElastic(e_upper, NU)})
    solver = NewtonSolver(problem.basis, material, problem.loading, SMALL)
    solver.run(2)
    m = (1 - NU) / ((1 + NU) * (1 - 2 * NU))  # the constrained modulus over E
    expected = -p * 0.25 / (m * e_lower) - p * 0.25 / (m * e_upper)
    assert problem.boundary_displacement("top", solver.u)[1] == pytest.approx(expected,
                                                                              rel=1e-9)
    # each point answered by its own layer: the vertical strain is p/M of its layer
    regions = material.regions
    strain = solver.kinematics.strain(solver.grad_u())[:, 1, 1]
    assert strain[regions == "lower"] == pytest.approx(-p / (m * e_lower), rel=1e-9)
    assert strain[regions == "upper"] == pytest.approx(-p / (m * e_upper), rel=1e-9)


def _mohr_coulomb():
    return MohrCoulomb(young=40e6, poisson=NU, friction_angle=15.0, cohesion=1e3,
                       initial_stress=-20e3)


def test_the_same_material_in_every_region_is_the_one_material_bit_for_bit():
    data = rectangle_mesh(0.2, 0.5, 2, 4, "quad4")
    # a pressure on top with rollers on the sides: K0 loading that yields Mohr-Coulomb
    problem = build_problem(data, [Fixed("bottom"), Roller("left", 0), Roller("right", 0),
                                   Pressure("top", 20e3, end=150e3)])
    one = NewtonSolver(problem.basis, _mohr_coulomb(), problem.loading, SMALL)
    one.run(3)
    regional = _regional(problem, data, {"lower": _mohr_coulomb(), "upper": _mohr_coulomb()})
    two = NewtonSolver(problem.basis, regional, problem.loading, SMALL)
    two.run(3)
    assert np.any(one.response.fields["plastic_shear_strain"] > 0)  # it yielded
    np.testing.assert_array_equal(one.u, two.u)
    np.testing.assert_array_equal(one.response.stress, two.response.stress)
    np.testing.assert_array_equal(one.response.tangent, two.response.tangent)
    for name, values in one.response.fields.items():
        np.testing.assert_array_equal(values, two.response.fields[name])


def test_fields_a_region_lacks_are_nan_and_costs_are_summed():
    material = RegionalMaterial({"soft": LinearElastic(10e6, NU), "mc": _mohr_coulomb()},
                                ["soft", "mc", "mc", "soft"])
    material.allocate(4)
    assert material.n_points == 4 and not material.noisy
    grad = np.zeros((4, 2, 2))
    grad[:, 1, 1] = -1e-4
    r = material.evaluate(grad)
    gamma = r.fields["plastic_shear_strain"]
    assert np.isnan(gamma[[0, 3]]).all() and np.isfinite(gamma[[1, 2]]).all()
    alone = _mohr_coulomb()
    alone.allocate(2)
    assert r.costs == dict(alone.evaluate(grad[:2]).costs)
    np.testing.assert_array_equal(r.stress[[0, 3]], _elastic_stress(grad[[0, 3]]))
    # the scikit-fem way in: the total ∇u, measured from allocate
    material.commit()
    np.testing.assert_array_equal(material.committed_grad_u, grad)
    np.testing.assert_array_equal(material.response(2 * grad).stress,
                                  material.evaluate(grad).stress)


def test_element_sets_no_material_names_are_not_used():
    sets = {"all": np.arange(3), "a": np.array([0, 2]), "b": np.array([1])}
    material = RegionalMaterial.from_elements({"a": LinearElastic(), "b": LinearElastic()},
                                              sets, n_elements=3, nqp=2)
    assert list(material.regions) == ["a", "a", "b", "b", "a", "a"]
    assert material.points_of("b").tolist() == [2, 3]


def _elastic_stress(grad):
    m = LinearElastic(10e6, NU)
    m.allocate(len(grad))
    return m.evaluate(grad).stress


def test_checkpoint_and_restore_continue_every_region_exactly(tmp_path):
    def made():
        return RegionalMaterial({"a": _mohr_coulomb(), "b": LinearElastic(30e6, NU)},
                                ["a", "b", "a", "b", "b"])

    grad = np.zeros((5, 2, 2))
    grad[:, 0, 1] = 4e-3  # shear: the Mohr-Coulomb points yield
    first = made()
    first.allocate(5)
    first.evaluate(grad)
    first.commit()
    first.checkpoint(tmp_path / "state.npz")
    again = made()
    again.restore(tmp_path / "state.npz")
    assert again.n_points == 5
    np.testing.assert_array_equal(again.committed_grad_u, first.committed_grad_u)
    a, b = first.evaluate(grad), again.evaluate(grad)
    np.testing.assert_array_equal(a.stress, b.stress)
    np.testing.assert_array_equal(a.fields["plastic_shear_strain"],
                                  b.fields["plastic_shear_strain"])
    other = RegionalMaterial({"a": _mohr_coulomb(), "c": LinearElastic(30e6, NU)},
                             ["a", "c", "a", "c", "c"])
    with pytest.raises(ValueError, match="holds the regions a, b"):
        other.restore(tmp_path / "state.npz")
    moved = RegionalMaterial({"a": _mohr_coulomb(), "b": LinearElastic(30e6, NU)},
                             ["b", "a", "a", "b", "b"])
    with pytest.raises(ValueError, match="other points' regions"):
        moved.restore(tmp_path / "state.npz")


def test_points_in_no_region_or_two_and_regions_without_material_are_refused():
    with pytest.raises(ParameterError, match="element 1 lies in two regions, 'a' and 'b'"):
        point_regions({"a": np.array([0, 1]), "b": np.array([1, 2])}, 3, 4)
    with pytest.raises(ParameterError, match=r"1 of 3 elements lie in no region \(first \[2\]"):
        point_regions({"a": np.array([0, 1])}, 3, 4)
    with pytest.raises(ParameterError, match="region 'a' holds no element"):
        point_regions({"a": np.array([], dtype=int), "b": np.arange(3)}, 3, 4)
    with pytest.raises(ParameterError, match="names element 7"):
        point_regions({"a": np.array([0, 1, 2, 7])}, 3, 4)
    assert list(point_regions({"a": np.array([1]), "b": np.array([0])}, 2, 2)) == [
        "b", "b", "a", "a"]
    with pytest.raises(ParameterError, match="point 1 lies in region 'clay', which has no "
                                             "material"):
        RegionalMaterial({"sand": LinearElastic()}, ["sand", "clay"])
    with pytest.raises(ParameterError, match="lie in no region"):
        RegionalMaterial({"sand": LinearElastic()}, ["sand", ""])
    with pytest.raises(ParameterError, match="region 'clay' holds no Gauss point"):
        RegionalMaterial({"sand": LinearElastic(), "clay": LinearElastic()}, ["sand"])
    with pytest.raises(ParameterError, match="region 'clay' is not one of the element sets"):
        RegionalMaterial.from_elements({"clay": LinearElastic()}, {"sand": np.arange(2)}, 2, 1)
    with pytest.raises(ParameterError, match="does not implement the Material protocol"):
        RegionalMaterial({"sand": object()}, ["sand"])
    material = RegionalMaterial({"sand": LinearElastic()}, ["sand", "sand"])
    with pytest.raises(ParameterError, match="must be the 2 points"):
        material.allocate(3)
