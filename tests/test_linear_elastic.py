"""LinearElastic: per-point initial stress, non-finite input, whole-file checkpoints
(fem/materials/linear_elastic.py)."""

from __future__ import annotations

import numpy as np
import pytest

from granular_material.errors import ParameterError
from granular_material.fem.materials.linear_elastic import (
    LinearElastic,
    LinearElasticParameters,
    isotropic_tangent,
)
from granular_material.fem.materials.protocol import FailureReason, PointStatus

RNG = np.random.default_rng(44)
E, NU = 60e6, 0.3


def _sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + np.swapaxes(a, -1, -2))


def test_a_number_gives_the_same_stress_as_before():
    material = LinearElastic(E, NU, initial_stress=-100e3)
    material.allocate(6)
    g = RNG.normal(scale=1e-3, size=(6, 2, 2))
    c = isotropic_tangent(*material.parameters.lame)
    expected = np.einsum("ijkl,nkl->nij", c, np.zeros((6, 2, 2)) + _sym(g))
    expected += -100e3 * np.eye(2)
    np.testing.assert_array_equal(material.evaluate(g).stress, expected)
    assert isinstance(material.parameters.initial_stress, float)


def test_per_point_and_tensor_initial_stress():
    n = 5
    sigma0 = _sym(RNG.normal(scale=1e5, size=(n, 2, 2)))
    material = LinearElastic(E, NU, initial_stress=sigma0)
    material.allocate(n)
    np.testing.assert_array_equal(material.evaluate(np.zeros((n, 2, 2))).stress, sigma0)
    g = RNG.normal(scale=1e-3, size=(n, 2, 2))
    c = isotropic_tangent(*material.parameters.lame)
    np.testing.assert_allclose(material.evaluate(g).stress,
                               sigma0 + np.einsum("ijkl,nkl->nij", c, _sym(g)), rtol=1e-14)
    one = np.array([[-50e3, 2e3], [2e3, -80e3]])
    tensor = LinearElastic(E, NU, initial_stress=one)
    tensor.allocate(3)
    np.testing.assert_array_equal(tensor.evaluate(np.zeros((3, 2, 2))).stress,
                                  np.broadcast_to(one, (3, 2, 2)))
    sigma0[0, 0, 0] = 1.0  # the material keeps its own copy
    assert material.initial_stress[0, 0, 0] != 1.0
    assert not material.initial_stress.flags.writeable


def test_initial_stress_is_checked():
    with pytest.raises(ParameterError, match="holds 4 points' stresses, the material has 3"):
        LinearElastic(initial_stress=np.zeros((4, 2, 2))).allocate(3)
    with pytest.raises(ParameterError, match="symmetric"):
        LinearElastic(initial_stress=np.array([[0.0, 1e3], [0.0, 0.0]]))
    with pytest.raises(ParameterError, match="shape"):
        LinearElastic(initial_stress=np.zeros((3, 3)))
    with pytest.raises(ParameterError, match="finite"):
        LinearElastic(initial_stress=np.full((2, 2), np.nan))
    with pytest.raises(ParameterError, match="young"):
        LinearElastic(young=-1.0)
    a = LinearElasticParameters(E, NU, np.eye(2))
    assert a == LinearElasticParameters(E, NU, np.eye(2))
    assert a != LinearElasticParameters(E, NU, 1.0)
    assert LinearElasticParameters(E, NU, -1.0) == LinearElasticParameters(E, NU, -1.0)


def test_checkpoint_keeps_a_per_point_initial_stress(tmp_path):
    n = 4
    sigma0 = _sym(RNG.normal(scale=1e5, size=(n, 2, 2)))
    material = LinearElastic(E, NU, initial_stress=sigma0)
    material.allocate(n)
    g = RNG.normal(scale=1e-3, size=(n, 2, 2))
    material.evaluate(g)
    material.commit()
    material.checkpoint(tmp_path / "le.npz")
    other = LinearElastic(E, NU, initial_stress=sigma0.copy())
    other.restore(tmp_path / "le.npz")
    h = RNG.normal(scale=1e-3, size=(n, 2, 2))
    np.testing.assert_array_equal(other.evaluate(h).stress, material.evaluate(h).stress)
    with pytest.raises(ValueError, match="parameters"):
        LinearElastic(E, NU, initial_stress=sigma0 * 2).restore(tmp_path / "le.npz")
    with pytest.raises(ValueError, match="parameters"):
        LinearElastic(E, NU, initial_stress=-1e5).restore(tmp_path / "le.npz")
    # a number survives the round trip as a number (older checkpoints hold a 0-d array too)
    plain = LinearElastic(E, NU, initial_stress=-1e5)
    plain.allocate(2)
    plain.checkpoint(tmp_path / "plain.npz")
    back = LinearElastic(E, NU, initial_stress=-1e5)
    back.restore(tmp_path / "plain.npz")
    assert back.n_points == 2


def test_a_failed_checkpoint_write_keeps_the_previous_file(tmp_path, monkeypatch):
    material = LinearElastic(E, NU)
    material.allocate(3)
    path = tmp_path / "le.npz"
    material.checkpoint(path)
    before = path.read_bytes()
    material.evaluate(RNG.normal(scale=1e-3, size=(3, 2, 2)))
    material.commit()

    def broken(fh, **arrays):
        fh.write(b"half a file")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", broken)
    with pytest.raises(OSError, match=r"le\.npz"):
        material.checkpoint(path)
    assert path.read_bytes() == before
    assert list(tmp_path.iterdir()) == [path]


def test_non_finite_gradient_fails_the_point_and_keeps_its_committed_state():
    material = LinearElastic(E, NU, initial_stress=-1e5)
    material.allocate(3)
    g = RNG.normal(scale=1e-3, size=(3, 2, 2))
    material.evaluate(g)
    material.commit()
    committed = material.evaluate(np.zeros((3, 2, 2))).stress
    bad = RNG.normal(scale=1e-3, size=(3, 2, 2))
    bad[1, 0, 1] = np.nan
    bad[2, 1, 1] = np.inf
    response = material.evaluate(bad)
    assert response.status.tolist() == [PointStatus.OK, PointStatus.FAILED, PointStatus.FAILED]
    assert list(response.reasons) == ["", FailureReason.NON_FINITE_INPUT.value,
                                      FailureReason.NON_FINITE_INPUT.value]
    assert np.isfinite(response.stress).all()
    np.testing.assert_array_equal(response.stress[1:], committed[1:])
    assert response.failed_points().tolist() == [1, 2]
    material.commit()  # the failed points stay committed where they were
    strain = material.strain
    assert np.isfinite(strain).all() and np.isfinite(material.committed_grad_u).all()
    np.testing.assert_array_equal(material.evaluate(np.zeros((3, 2, 2))).stress[1:],
                                  committed[1:])
    assert not np.array_equal(strain[0], _sym(g)[0])
