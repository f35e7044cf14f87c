"""Material protocol, entry-point lookup, layout adapter and the linear-elastic material."""

from __future__ import annotations

import numpy as np
import pytest
from skfem import Basis, ElementQuad1, ElementVector, MeshQuad

from granular_material.fem import (
    LinearElastic,
    Material,
    MaterialResponse,
    PointStatus,
    available_materials,
    create_material,
    to_points,
    to_quadrature,
)

RNG = np.random.default_rng(7)


def test_entry_points_list_both_materials():
    assert {"linear-elastic", "dem"} <= set(available_materials())
    material = create_material("linear-elastic", young=1e6, poisson=0.2)
    assert isinstance(material, LinearElastic) and isinstance(material, Material)


def test_unknown_material_names_the_choices():
    with pytest.raises(ValueError, match="linear-elastic"):
        create_material("no-such-law")


@pytest.mark.parametrize(("field", "value"), [("young", -1.0), ("poisson", 0.5)])
def test_parameters_are_validated(field, value):
    with pytest.raises(ValueError, match=field):
        LinearElastic(**{field: value})


def test_layout_round_trip_and_point_numbering():
    basis = Basis(MeshQuad().refined(1), ElementVector(ElementQuad1()), intorder=2)
    nelems, nqp = basis.nelems, basis.X.shape[-1]
    assert nqp == 4  # intorder=2 gives 2x2 Gauss points on Q1 quads
    field = RNG.normal(size=(2, 2, nelems, nqp))
    points = to_points(field)
    assert points.shape == (nelems * nqp, 2, 2)
    e, q = 2, 3
    np.testing.assert_array_equal(points[e * nqp + q], field[:, :, e, q])
    np.testing.assert_array_equal(to_quadrature(points, nqp), field)
    with pytest.raises(ValueError, match="nqp"):
        to_quadrature(points[:-1], nqp)


def test_response_checks_shapes():
    with pytest.raises(ValueError, match="tangent"):
        MaterialResponse(np.zeros((3, 2, 2)), np.zeros((2, 2, 2, 2, 2)),
                         np.zeros(3, dtype=np.int8))
    bad = MaterialResponse(np.full((2, 2, 2), np.nan), np.zeros((2, 2, 2, 2, 2)),
                           np.zeros(2, dtype=np.int8))
    assert not bad.ok and bad.failed_points().tolist() == [0, 1]


def test_response_costs_are_numbers_by_name():
    """Costs are free-form (the material's names), default empty; NumPy scalars become
    Python numbers, anything but a real number under a string is refused."""
    arrays = (np.zeros((2, 2, 2)), np.zeros((2, 2, 2, 2, 2)), np.zeros(2, dtype=np.int8))
    assert MaterialResponse(*arrays).costs == {}
    costs = MaterialResponse(*arrays, costs={"calls": np.int64(3), "work": np.float32(0.5),
                                             "steps": 7}).costs
    assert costs == {"calls": 3, "work": 0.5, "steps": 7}
    assert [type(v) for v in costs.values()] == [int, float, int]
    for bad in ({"on": True}, {"x": "1"}, {"x": None}, {1: 2}):
        with pytest.raises(ValueError, match="cost"):
            MaterialResponse(*arrays, costs=bad)
    elastic = LinearElastic()
    elastic.allocate(2)
    assert elastic.evaluate(np.zeros((2, 2, 2))).costs == {}  # a closed-form law counts none


def test_linear_elastic_plane_strain_constants():
    # plane strain: σ_yy = E(1−ν)/((1+ν)(1−2ν)) ε_yy and σ_xx = Eν/((1+ν)(1−2ν)) ε_yy
    # for ε = ε_yy e_y ⊗ e_y (closed form of isotropic Hooke's law)
    e, nu, eps = 70e6, 0.3, 1e-3
    material = LinearElastic(young=e, poisson=nu)
    material.allocate(1)
    g = np.array([[[0.0, 0.0], [0.0, eps]]])
    s = material.evaluate(g).stress[0]
    factor = e / ((1 + nu) * (1 - 2 * nu))
    np.testing.assert_allclose(s, [[factor * nu * eps, 0.0], [0.0, factor * (1 - nu) * eps]],
                               rtol=1e-14, atol=1e-9)
    # a rigid rotation (antisymmetric ∇u) carries no stress
    w = np.array([[[0.0, -0.01], [0.01, 0.0]]])
    np.testing.assert_allclose(material.evaluate(w).stress, 0.0, atol=1e-9)


def test_evaluate_is_idempotent_and_commit_revert_restore_state(tmp_path):
    material = LinearElastic(initial_stress=-100e3)
    material.allocate(5)
    g1, g2 = RNG.normal(scale=1e-3, size=(2, 5, 2, 2))
    first = material.evaluate(g1).stress
    np.testing.assert_array_equal(material.evaluate(g1).stress, first)
    material.commit()
    committed = material.strain
    after_g2 = material.evaluate(g2).stress
    material.revert()
    np.testing.assert_array_equal(material.strain, committed)
    np.testing.assert_array_equal(material.evaluate(g2).stress, after_g2)
    material.checkpoint(tmp_path / "le.npz")
    other = LinearElastic(initial_stress=-100e3)
    other.restore(tmp_path / "le.npz")
    np.testing.assert_array_equal(other.evaluate(g2).stress, after_g2)
    assert (other.evaluate(g2).status == PointStatus.OK).all()
    with pytest.raises(ValueError, match="parameters"):
        LinearElastic(young=1.0).restore(tmp_path / "le.npz")
