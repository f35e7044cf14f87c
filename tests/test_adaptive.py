"""The adaptive material: the calibrated twin at every point, a DEM RVE where the twin is no
longer trusted (granular_material.multiscale.adaptive), and the [adaptivity] table."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import tomllib

from granular_material.dem import load_rve
from granular_material.errors import ParameterError
from granular_material.fem import MohrCoulomb
from granular_material.fem.boundary_value.continuum_start import cap_friction
from granular_material.multiscale import DEMMaterial, adaptive
from granular_material.multiscale.adaptive import (
    AdaptiveMaterial,
    adaptive_for_resume,
    twin_from_calibration,
)
from granular_material.multiscale.parameters import DEMMaterialParameters
from granular_material.multiscale.switching import SwitchCriterion, mobilised_friction
from granular_material.runs.boundary_value.spec import SCENE_KEYS, bvp_from_dict
from granular_material.runs.spec import SpecError

SOURCE = Path(__file__).parents[1] / "examples" / "scenes" / "rve64.npz"
PEAK = 30.0


def _stress(major: float, minor: float, angle: float = 0.0) -> np.ndarray:
    """An in-plane stress [Pa], tension positive, of principal compressions major >= minor
    whose major axis is turned by ``angle`` [rad] from y."""
    c, s = np.cos(angle), np.sin(angle)
    turn = np.array([[c, -s], [s, c]])
    return turn @ np.diag([-minor, -major]) @ turn.T


def _material(start: str = "stress", neighbours: str = "point", nqp: int = 1,
              fraction: float = 0.7) -> AdaptiveMaterial:
    twin = MohrCoulomb(young=60e6, poisson=0.3, friction_angle=PEAK, initial_stress=-100e3)
    dem = DEMMaterialParameters(device="cpu", shards=1, confining=100e3)
    return AdaptiveMaterial(twin, PEAK, dem, load_rve(SOURCE),
                            SwitchCriterion(fraction, neighbours=neighbours), nqp=nqp,
                            start=start)


def _biaxial(scale: np.ndarray) -> np.ndarray:
    """A step of shortening in y, lengthening in x, by ``scale`` at each point."""
    g = np.zeros((len(scale), 2, 2))
    g[:, 1, 1] = -2e-4 * scale
    g[:, 0, 0] = 1e-4 * scale
    return g


def _load_until_a_switch(material: AdaptiveMaterial, scale: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, int]:
    """Steps until some point switches (that step evaluated, not committed): its response's
    stress, the committed stress before it, and the steps committed before it."""
    committed = np.repeat(-100e3 * np.eye(2)[None], len(scale), axis=0)
    for k in range(20):
        response = material.evaluate(_biaxial(scale))
        if material.dem_points:
            return response.stress, committed, k
        material.commit()
        committed = response.stress
    raise AssertionError("no point switched")


def test_mobilised_friction_of_known_stresses():
    stress = np.stack([_stress(3e3, 1e3), _stress(3e3, 1e3, 0.7), _stress(1e3, 1e3),
                       _stress(1e3, 0.0), np.zeros((2, 2))])
    np.testing.assert_allclose(mobilised_friction(stress), [30.0, 30.0, 0.0, 90.0, 0.0],
                               atol=1e-9)


def test_a_capped_target_keeps_its_pressure_and_axes():
    # the switch's cap is the continuum start's (fem.boundary_value.continuum_start)
    stress = np.stack([_stress(3e3, 1e3, 0.4), _stress(1.5e3, 1e3)])
    capped, over = cap_friction(stress, 20.0)
    assert over.tolist() == [0]
    np.testing.assert_allclose(mobilised_friction(capped), [20.0, mobilised_friction(
        stress[1:])[0]], atol=1e-9)
    np.testing.assert_allclose(np.trace(capped, axis1=1, axis2=2),
                               np.trace(stress, axis1=1, axis2=2))
    np.testing.assert_allclose(np.linalg.eigh(capped[0])[1] @ np.diag([1, 1]),
                               np.linalg.eigh(stress[0])[1], atol=1e-12)
    np.testing.assert_array_equal(capped[1], stress[1])


@pytest.mark.parametrize("kwargs, field", [
    ({"mobilised_fraction": 0.0}, "adaptivity.mobilised_fraction"),
    ({"mobilised_fraction": 1.2}, "adaptivity.mobilised_fraction"),
    ({"mobilised_fraction": None, "shear_strain": -1e-3}, "adaptivity.shear_strain"),
    ({"mobilised_fraction": None}, "adaptivity"),
    ({"neighbours": "mesh"}, "adaptivity.neighbours"),
])
def test_the_criterion_refuses_what_cannot_act(kwargs, field):
    with pytest.raises(ParameterError) as refused:
        SwitchCriterion(**kwargs)
    assert refused.value.field == field


def test_the_shear_strain_criterion_reads_the_total_strain():
    criterion = SwitchCriterion(None, shear_strain=0.01)
    grad = np.zeros((2, 2, 2))
    grad[0, 0, 1] = 0.006  # γ = 2 εxy = 0.006
    grad[1, 0, 1] = 0.011
    stress = np.repeat(_stress(2e3, 1e3)[None], 2, axis=0)
    assert criterion.met(stress, grad, PEAK).tolist() == [False, True]


def test_a_switch_brings_the_rve_to_the_points_stress_within_the_servo_tolerance():
    material = _material("stress")
    material.allocate(3)
    _, committed, _ = _load_until_a_switch(material, np.array([0.5, 1.0, 1.5]))
    switched = material.switches[-1].points
    assert switched.size and material.is_dem[switched].all()
    # the step in which it passed the threshold: the twin's answer there would pass it
    assert not material.is_dem[np.setdiff1d(np.arange(3), switched)].any()
    assert material.switches[-1].error <= 0.01
    material.revert()  # the step's start: the RVE as the servo left it, at the point's
    answer = material.evaluate(np.zeros((3, 2, 2)))  # stress then (two free DEM steps)
    scale = np.abs(committed[switched]).max(axis=(1, 2))
    error = np.abs(answer.stress[switched] - committed[switched]).max(axis=(1, 2)) / scale
    assert (error <= 0.01 + 0.005).all(), error
    assert answer.fields["dem"].tolist() == material.is_dem.astype(float).tolist()
    assert material.switches[-1].particle_steps > 0


def test_a_point_is_dem_in_the_step_it_passes_the_threshold():
    scale = np.array([0.5, 1.0, 1.5])
    twin = MohrCoulomb(young=60e6, poisson=0.3, friction_angle=PEAK, initial_stress=-100e3)
    twin.allocate(3)
    adaptive = _material("strain")
    adaptive.allocate(3)
    _, _, steps = _load_until_a_switch(adaptive, scale)
    for _ in range(steps + 1):  # the twin alone, the same steps
        alone = twin.evaluate(_biaxial(scale))
        twin.commit()
    switched = adaptive.switches[-1].points
    assert (mobilised_friction(alone.stress[switched]) >= 0.7 * PEAK).all()
    assert (mobilised_friction(alone.stress[adaptive.is_dem == 0]) < 0.7 * PEAK).all()


def test_after_step_switching_tests_the_committed_state():
    material = AdaptiveMaterial(
        MohrCoulomb(young=60e6, poisson=0.3, friction_angle=PEAK, initial_stress=-100e3),
        PEAK, DEMMaterialParameters(device="cpu", shards=1, confining=100e3),
        load_rve(SOURCE), SwitchCriterion(0.7, neighbours="point", in_step=False))
    material.allocate(3)
    scale = np.array([0.5, 1.0, 1.5])
    for _ in range(20):
        response = material.evaluate(_biaxial(scale))
        assert not material.dem_points  # never during a step
        material.commit()
        if material.dem_points:
            break
    assert (mobilised_friction(response.stress[material.is_dem]) >= 0.7 * PEAK).all()


def test_a_strain_start_is_the_source_driven_through_the_points_deformation():
    material = _material("strain")
    material.allocate(3)
    scale = np.array([0.5, 1.0, 1.5])
    trial, _, steps = _load_until_a_switch(material, scale)
    point = material.switches[-1].points[0]
    g = _biaxial(scale)[point]
    deformation = np.linalg.matrix_power(np.eye(2) + g, steps)
    alone = DEMMaterial.holding(load_rve(SOURCE).replicate(1), material.dem)
    assert alone.evaluate((deformation - np.eye(2))[None]).ok
    alone.commit()
    np.testing.assert_array_equal(trial[point], alone.evaluate(g[None]).stress[0])


def test_an_elements_points_switch_together():
    material = _material("strain", neighbours="element", nqp=3)
    material.allocate(6)
    _load_until_a_switch(material, np.array([0.5, 0.5, 1.5, 0.5, 0.5, 0.5]))
    assert material.is_dem.tolist() == [True, True, True, False, False, False]


def test_a_restored_material_answers_as_the_one_it_was_written_from(tmp_path):
    material = _material("stress")
    material.allocate(3)
    scale = np.array([0.5, 1.0, 1.5])
    _load_until_a_switch(material, scale)
    material.commit()
    material.checkpoint(tmp_path / "state.npz")
    restored = _material("stress")
    restored.restore(tmp_path / "state.npz")
    assert restored.is_dem.tolist() == material.is_dem.tolist()
    for _ in range(3):  # both go on, switching the same points
        a, b = material.evaluate(_biaxial(scale)), restored.evaluate(_biaxial(scale))
        np.testing.assert_array_equal(a.stress, b.stress)
        np.testing.assert_array_equal(a.tangent, b.tangent)
        material.commit()
        restored.commit()
    assert restored.is_dem.tolist() == material.is_dem.tolist()


def test_a_resume_makes_the_material_from_its_checkpoint(tmp_path):
    """adaptive_for_resume: the twin from the calibration the checkpoint holds, the source
    RVE from it too; restored, it answers as the material it was written from. A checkpoint
    without a calibration (one made before it held one) gives None."""
    parameters = {"young": 60e6, "poisson": 0.3, "friction_angle": PEAK,
                  "dilation_angle": 0.0, "cohesion": 0.0, "critical_friction_angle": PEAK,
                  "softening_strain": 0.0}
    material = _material("stress")
    material.calibration = {"parameters": parameters, "pressure": 100e3, "seconds": 1.5}
    material.allocate(3)
    scale = np.array([0.5, 1.0, 1.5])
    _load_until_a_switch(material, scale)
    material.commit()
    material.checkpoint(tmp_path / "state.npz")
    sigma0 = np.repeat(-100e3 * np.eye(2)[None], 3, axis=0)
    dem = DEMMaterialParameters(device="cpu", shards=1, confining=100e3)
    made = adaptive_for_resume(tmp_path / "state.npz", dem, sigma0,
                               SwitchCriterion(0.7, neighbours="point"), nqp=1, start="stress")
    assert made is not None and made.calibration == material.calibration
    assert made.twin.parameters == material.twin.parameters
    made.restore(tmp_path / "state.npz")
    for _ in range(3):
        a, b = material.evaluate(_biaxial(scale)), made.evaluate(_biaxial(scale))
        np.testing.assert_array_equal(a.stress, b.stress)
        material.commit()
        made.commit()
    assert made.is_dem.tolist() == material.is_dem.tolist()
    material.calibration = None
    material.checkpoint(tmp_path / "older.npz")
    assert adaptive_for_resume(tmp_path / "older.npz", dem, sigma0, SwitchCriterion(0.7),
                               nqp=1) is None


def test_the_twin_of_a_calibration_file(tmp_path):
    parameters = {"young": 20e6, "poisson": 0.25, "friction_angle": 31.0,
                  "dilation_angle": 10.0, "cohesion": 0.0, "critical_friction_angle": 25.0,
                  "softening_strain": 0.05}
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps({"parameters": parameters, "pressure": 20e3}))
    twin, described = twin_from_calibration(path, np.repeat(-20e3 * np.eye(2)[None], 2, 0))
    assert twin.parameters.friction_angle == 31.0
    assert described["pressure"] == 20e3
    path.write_text(json.dumps({"parameters": {"young": 1.0}}))
    with pytest.raises(ParameterError, match="poisson"):
        twin_from_calibration(path, np.zeros((1, 2, 2)))


SCENE = """test = "boundary-value"
steps = 2
[mesh]
size = [0.4, 0.2]
elements = [2, 2]
[[conditions]]
type = "fixed"
boundary = "bottom"
[initial]
state = "uniform"
pressure = 20e3
[material]
name = "dem"
[material.parameters]
particles = 16
[adaptivity]
"""


def test_the_adaptivity_table_acts_key_by_key(tmp_path):
    (tmp_path / "calibration.json").write_text("{}")
    base = bvp_from_dict(tomllib.loads(SCENE), tmp_path)
    assert base.adaptivity.mobilised_fraction == 0.7
    changed = {"mobilised_fraction": 0.5, "shear_strain": 0.01, "neighbours": "point",
               "start": "stress", "switch": "after-step", "calibration": "calibration.json",
               "elastic_window": 1e-3}
    assert set(changed) == SCENE_KEYS["adaptivity"]
    for key, value in changed.items():
        data = tomllib.loads(SCENE)
        data["adaptivity"] = {key: value}
        spec = bvp_from_dict(data, tmp_path)
        assert spec.adaptivity != base.adaptivity, key
    only = bvp_from_dict({**tomllib.loads(SCENE), "adaptivity": {"shear_strain": 0.01}},
                         tmp_path)
    assert only.adaptivity.mobilised_fraction is None


@pytest.mark.parametrize("table, field", [
    ({"mobilised_fraction": 2.0}, "adaptivity.mobilised_fraction"),
    ({"start": "gas"}, "adaptivity.start"),
    ({"switch": "later"}, "adaptivity.switch"),
    ({"neighbours": "all"}, "adaptivity.neighbours"),
    ({"calibration": "missing.json"}, "adaptivity.calibration"),
    ({"swap": "now"}, "adaptivity.swap"),
    ({"elastic_window": 0.2}, "adaptivity.elastic_window"),
    ({"elastic_window": 1e-3, "calibration": "calibration.json"}, "adaptivity.elastic_window"),
])
def test_the_adaptivity_table_refuses_naming_the_key(tmp_path, table, field):
    if table.get("elastic_window") == 1e-3:
        (tmp_path / "calibration.json").write_text("{}")
    with pytest.raises(SpecError) as refused:
        bvp_from_dict({**tomllib.loads(SCENE), "adaptivity": table}, tmp_path)
    assert refused.value.field == field


def test_adaptivity_needs_a_dem_material():
    data = tomllib.loads(SCENE)
    data["material"] = {"name": "mohr-coulomb"}
    with pytest.raises(SpecError, match="not dem") as refused:
        bvp_from_dict(data)
    assert refused.value.field == "adaptivity"


# -- in a boundary-value scene -----------------------------------------------------------------
def _footing(tmp_path: Path, steps: int = 3, adaptivity: str = "") -> object:
    from test_bvp_resume import DEM
    from test_bvp_run import FOOTING

    calibration = tmp_path / "calibration.json"
    calibration.write_text(json.dumps({"parameters": {
        "young": 20e6, "poisson": 0.25, "friction_angle": 31.0, "dilation_angle": 10.0,
        "cohesion": 0.0, "critical_friction_angle": 25.0, "softening_strain": 0.05},
        "pressure": 20e3}))
    text = FOOTING.format(steps=steps, elements="[3, 2]", settlement=-0.0005 * steps,
                          material=DEM + "[adaptivity]\ncalibration = \"calibration.json\"\n"
                          + adaptivity)
    return bvp_from_dict(tomllib.loads(text), tmp_path)


def test_an_adaptive_footing_reports_its_dem_points(tmp_path):
    import pandas as pd

    from granular_material.results import read_points
    from granular_material.runs.boundary_value.runner import run_boundary_value

    outcome = run_boundary_value(_footing(tmp_path, adaptivity='start = "strain"\n'),
                                 out=tmp_path / "run")
    assert outcome.error is None
    steps = pd.read_csv(tmp_path / "run" / "steps.csv")
    points = read_points(tmp_path / "run")
    assert steps["dem_points"].iloc[0] == 0 and steps["dem_points"].iloc[-1] > 0
    assert steps["dem_points"].is_monotonic_increasing
    last = points[points["step"] == points["step"].max()]
    assert int(last["dem"].sum()) == steps["dem_points"].iloc[-1]
    # DEM fields where the points are DEM, the twin's where they are not
    assert last.loc[last["dem"] == 1, "void_ratio"].notna().all()
    assert last.loc[last["dem"] == 0, "void_ratio"].isna().all()
    assert last.loc[last["dem"] == 0, "plastic_shear_strain"].notna().all()
    fields = (tmp_path / "run" / "fields.xdmf").read_text()
    assert 'Name="dem"' in fields  # ParaView shows each element's model (its DEM share)
    summary = outcome.summary["adaptivity"]
    assert summary["dem_points_final"] == steps["dem_points"].iloc[-1]
    assert sum(s["points"] for s in summary["switches"]) == summary["dem_points_final"]
    assert summary["twin"]["parameters"]["friction_angle"] == 31.0
    assert steps["switch_particle_steps"].sum() == sum(
        s["particle_steps"] for s in summary["switches"])


def test_a_stopped_adaptive_run_resumes_to_the_run_that_never_stopped(tmp_path, monkeypatch):
    import pandas as pd
    from test_bvp_resume import _stop_at, _tables

    from granular_material.runs.boundary_value.runner import run_boundary_value

    whole = run_boundary_value(_footing(tmp_path), out=tmp_path / "whole")
    assert whole.error is None and whole.summary["adaptivity"]["dem_points_final"] > 0
    with monkeypatch.context() as m:
        _stop_at(m, 3)
        stopped = run_boundary_value(_footing(tmp_path), out=tmp_path / "run")
    assert "interrupted after load step 2" in stopped.error

    def made_again(*args, **kwargs):
        raise AssertionError("a resume made its twin and source RVE again")

    with monkeypatch.context() as m:  # the resume makes its material from the checkpoint
        m.setattr(adaptive, "calibrated_adaptive", made_again)
        resumed = run_boundary_value(_footing(tmp_path), out=tmp_path / "run", resume=True)
    assert resumed.error is None and 0 <= resumed.summary["resumed_from_step"] <= 2
    for a, b in zip(_tables(tmp_path / "whole"), _tables(tmp_path / "run"), strict=True):
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    np.testing.assert_array_equal(whole.u, resumed.u)


def test_a_point_whose_rve_cannot_be_driven_stays_on_the_twin():
    twin = MohrCoulomb(young=60e6, poisson=0.3, friction_angle=PEAK, initial_stress=-100e3)
    capped = DEMMaterialParameters(device="cpu", shards=1, confining=100e3, max_dem_steps=1)
    material = AdaptiveMaterial(twin, PEAK, capped, load_rve(SOURCE),
                                SwitchCriterion(0.7, neighbours="point"), start="strain")
    material.allocate(3)
    scale = np.array([0.5, 1.0, 1.5])
    with pytest.warns(UserWarning, match="stay on the twin"):
        for _ in range(12):
            response = material.evaluate(_biaxial(scale))
            assert response.ok
            material.commit()
            if material.missed.size:
                break
    assert material.missed.size and not material.dem_points
    assert material.switches[-1].particle_steps == 0  # nothing was stepped: capped at once
