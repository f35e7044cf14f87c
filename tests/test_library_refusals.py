"""Refusals handed over by the hostile retry of issue 47: each a field-naming ValueError, not
a traceback of another kind, and before any work."""

from __future__ import annotations

import numpy as np
import pytest

from granular_material import runs
from granular_material.errors import ParameterError
from granular_material.fem.materials.mohr_coulomb import MohrCoulomb
from granular_material.fem.materials.protocol import create_material


def test_a_spec_nested_too_deep_is_no_spec(tmp_path):
    path = tmp_path / "deep.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ValueError, match="nested too deep"):
        runs.load(path)


@pytest.mark.parametrize("value", ["30", b"30", True])
def test_mohr_coulomb_takes_numbers_not_text(value):
    with pytest.raises(ParameterError) as refused:
        MohrCoulomb(friction_angle=value)
    assert refused.value.field == "friction_angle"


def test_a_checkpoint_of_other_points_is_refused(tmp_path):
    small = MohrCoulomb(initial_stress=-1e5)
    small.allocate(2)
    small.checkpoint(tmp_path / "two.npz")
    large = MohrCoulomb(initial_stress=-1e5)
    large.allocate(5)
    with pytest.raises(ValueError, match="holds 2 points"):
        large.restore(tmp_path / "two.npz")
    assert large.n_points == 5
    fresh = MohrCoulomb(initial_stress=-1e5)
    fresh.restore(tmp_path / "two.npz")  # not allocated: it takes the checkpoint's points
    assert fresh.n_points == 2 and np.allclose(fresh.stress, -1e5 * np.eye(2))


def test_an_unknown_keyword_of_a_material_is_named():
    with pytest.raises(ParameterError) as refused:
        create_material("linear-elastic", yung=60e6)
    assert refused.value.field == "yung" and "E" in str(refused.value)


def test_run_of_no_spec_is_a_value_error():
    with pytest.raises(ValueError, match="takes a RunSpec"):
        runs.run(None)


@pytest.mark.parametrize(("keywords", "field"), [
    ({"confining": 1e300}, "confining"), ({"device": 3}, "device"),
    ({"elastic_window": "x"}, "elastic_window"), ({"frob": 0.1}, "frob"),
    ({"dtype": "float16"}, "dtype")])
def test_a_calibration_is_refused_before_its_dem_tests(tmp_path, keywords, field, monkeypatch):
    from granular_material.dem import RVEData, RVEMeta
    from granular_material.procedures import calibration

    rng = np.random.default_rng(1)
    data = RVEData(radius=rng.uniform(3e-3, 7e-3, (1, 16)),
                   position=rng.uniform(0, 0.05, (1, 16, 2)),
                   cell=np.array([[[0.05, 0.0], [0.0, 0.05]]]),
                   velocity=np.zeros((1, 16, 2)), angular_velocity=np.zeros((1, 16)),
                   meta=RVEMeta())

    def no_dem(*args, **kwargs):  # the refusal comes before any DEM batch is built
        raise AssertionError("a DEM batch was built")

    monkeypatch.setattr("granular_material.dem.DEMBatch", no_dem)
    arguments = {"confining": 100e3, **keywords}
    with pytest.raises(ParameterError) as refused:
        calibration.calibrate_mohr_coulomb(data, **arguments)
    assert refused.value.field == field


def test_an_rve_file_relaxed_beyond_its_contact_law_is_refused_before_work(tmp_path):
    from granular_material.dem import RVEData, RVEMeta, save_rve

    rng = np.random.default_rng(2)
    path = tmp_path / "rve.npz"
    save_rve(path, RVEData(radius=rng.uniform(3e-3, 7e-3, (1, 16)),
                           position=rng.uniform(0, 0.05, (1, 16, 2)),
                           cell=np.array([[[0.05, 0.0], [0.0, 0.05]]]),
                           velocity=np.zeros((1, 16, 2)), angular_velocity=np.zeros((1, 16)),
                           meta=RVEMeta()))
    material = create_material("dem", rve=str(path), isotropic=True, confining=1e300,
                               device="cpu")
    with pytest.raises(ParameterError) as refused:
        material.allocate(1)
    assert refused.value.field == "confining"
