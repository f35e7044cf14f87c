"""Cross-runs with Debian's yade (2023.02a): skipped where the ``yade`` executable is absent."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from granular_material_validation import yade_runner

from granular_material.dem.rve.file import RVEData, RVEMeta

needs_yade = pytest.mark.skipif(shutil.which("yade") is None, reason="needs Debian's yade")
pytestmark = [pytest.mark.yade]


def two_disc_rve(law: dict, overlap: float, r1: float = 5e-3, r2: float = 4e-3) -> RVEData:
    """Two discs on a horizontal line overlapping by ``overlap`` [m] in a 0.1 m square cell."""
    d = r1 + r2 - overlap
    position = np.array([[[0.03, 0.05], [0.03 + d, 0.05]]])
    return RVEData(radius=np.array([[r1, r2]]), position=position,
                   cell=np.array([[[0.1, 0.0], [0.0, 0.1]]]), velocity=np.zeros((1, 2, 2)),
                   angular_velocity=np.zeros((1, 2)),
                   meta=RVEMeta(stiffness=law, friction_angle=0.5, timestep=1e-6))


@pytest.fixture(scope="module")
def guo_zhao_seed1(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, RVEData, dict]:
    if shutil.which("yade") is None:
        pytest.skip("needs Debian's yade")
    work = tmp_path_factory.mktemp("gz")
    data, info = yade_runner.yade_prepare_guo_zhao(work / "gz1.npz", seed=1, workdir=work)
    return work / "gz1.npz", data, info


@needs_yade
def test_yade_is_debian_2023_02a() -> None:
    assert yade_runner.yade_version().startswith("2023.02")


@needs_yade
@pytest.mark.parametrize("law", [{"law": "frictmat", "young": 6e8, "kt_over_kn": 0.8},
                                 {"law": "constant", "kn": 3e6, "kt": 2.4e6}])
def test_round_trip_through_yade_is_exact_and_kn_matches(tmp_path: Path, law: dict) -> None:
    """Export → YADE scene → back: every disc bit for bit; YADE's stress gives kn.

    One contact of overlap δ along x in a cell of area A and thickness t: Love's stress
    σxx = −kn·δ·d/(A·t), d = r1 + r2 − δ; kn = 2E·r1·r2/(r1 + r2) for frictmat
    (docs/design.md#guo-zhao-rve), kn itself for the constant law.
    """
    r1, r2, delta = 5e-3, 4e-3, 1e-5
    data = two_disc_rve(law, delta, r1, r2)
    back, stress = yade_runner.yade_round_trip(data, tmp_path)
    for name in ("radius", "position", "cell", "velocity", "angular_velocity"):
        np.testing.assert_array_equal(getattr(back, name), getattr(data, name), err_msg=name)
    assert back.meta == data.meta
    kn = 2 * 6e8 * r1 * r2 / (r1 + r2) if law["law"] == "frictmat" else 3e6
    expected = -kn * delta * (r1 + r2 - delta) / (0.1 * 0.1 * 0.1)
    assert stress[0] == pytest.approx(expected, rel=1e-9)
    assert abs(stress[1]) < 1e-9 * abs(expected)


@needs_yade
def test_round_trip_of_a_moving_packing_is_exact(tmp_path: Path) -> None:
    """Sheared cell, 36 moving and spinning discs (no contacts): every array comes back."""
    rng = np.random.default_rng(4)
    cell = np.array([[0.1, 0.003], [0.0, 0.1]])
    frac = (np.stack(np.meshgrid(np.arange(6), np.arange(6)), -1).reshape(-1, 2) + 0.5) / 6
    data = RVEData(radius=rng.uniform(3e-3, 7e-3, (1, 36)) * 0.9, position=(frac @ cell.T)[None],
                   cell=cell[None], velocity=rng.normal(0, 1e-3, (1, 36, 2)),
                   angular_velocity=rng.normal(0, 0.1, (1, 36)), meta=RVEMeta(seed=4))
    back, _ = yade_runner.yade_round_trip(data, tmp_path)
    for name in ("radius", "position", "cell", "velocity", "angular_velocity"):
        np.testing.assert_array_equal(getattr(back, name), getattr(data, name), err_msg=name)


def test_guo_zhao_packing_matches_design_figures(guo_zhao_seed1) -> None:
    """docs/design.md#yade-anchors, measured with Debian yade 2023.02a, seed 1: e0 = 0.175,
    cell 0.198 × 0.197 m, coordination 4.16, isotropic 100 kPa (PeriTriaxController
    relStressTol 1e-3)."""
    _, data, info = guo_zhao_seed1
    assert data.n_disc == 400
    assert data.radius.min() >= 3e-3 and data.radius.max() <= 7e-3
    assert info["void_ratio"] == pytest.approx(0.175, abs=5e-4)
    assert info["coordination"] == pytest.approx(4.16, abs=0.01)
    assert np.diag(data.cell[0]) == pytest.approx([0.198, 0.197], abs=1e-3)
    sxx, syy, _ = info["stress"]
    assert sxx == pytest.approx(-1e5, rel=2e-3) and syy == pytest.approx(-1e5, rel=2e-3)
    assert data.meta.stiffness == {"law": "frictmat", "young": 6e8, "kt_over_kn": 0.8}
    assert data.meta.friction_angle == 0.5 and data.meta.damping == 0.1
    assert data.meta.timestep is not None and 0 < data.meta.timestep < 1e-4
    assert not data.velocity.any()


def test_yade_biaxial_reproduces_design_anchors(guo_zhao_seed1, tmp_path: Path) -> None:
    """docs/design.md#yade-anchors (seed 1): peak σ1/σ3 = 2.90 near 2 % axial strain, largest
    contraction εv = −0.45 % near 0.9 %. Run to 3 % here; σxx held at −100 kPa."""
    from granular_material_validation.metrics import PEAK_WINDOW, find_peak, stress_ratio

    rve, _, _ = guo_zhao_seed1
    curve, summary = yade_runner.yade_biaxial(rve, axial_strain=0.03, workdir=tmp_path)
    assert curve["axial_strain"].iloc[-1] == pytest.approx(0.03, abs=1e-4)
    assert np.abs(curve["sxx"] + 1e5).max() < 0.03 * 1e5
    i, peak = find_peak(curve["axial_strain"].to_numpy(), stress_ratio(curve), PEAK_WINDOW)
    assert peak == pytest.approx(2.90, abs=0.05)
    assert curve["axial_strain"].iloc[i] == pytest.approx(0.02, abs=0.005)
    j = int(curve["volumetric_strain"].idxmin())
    assert curve["volumetric_strain"].iloc[j] == pytest.approx(-0.0045, abs=3e-4)
    assert curve["axial_strain"].iloc[j] == pytest.approx(0.009, abs=0.002)
    # PeriTriaxController caps the logarithmic strain rate at 1e-5 a step
    assert 0 <= summary["steps"] - math.ceil(-math.log(0.97) / 1e-5) <= 10


def test_yade_drive_follows_shear2d_and_tangent_rule(guo_zhao_seed1, tmp_path: Path) -> None:
    """∇u = diag(+0.2 %, −0.2 %) in 2 increments: n = max(1e5·1e-3, 2) = 100 steps each
    (Guo & Zhao's shear2D). At increment 0 no contact has a shear force, so YADE's tangent
    has only kn terms, S = (1/V) Σ kn n_i l_j n_k l_l, for which S_xxyy = S_xyxy exactly."""
    rve, _, _ = guo_zhao_seed1
    path, summary = yade_runner.yade_drive(rve, [0.002, 0.0, 0.0, -0.002], 2,
                                           tangent_at=[0, 2], workdir=tmp_path)
    assert summary["steps_per_increment"] == 100
    assert path["steps"].tolist() == [0, 100, 200]
    assert path["Gxx"].tolist() == pytest.approx([0.0, 0.001, 0.002])
    assert path["sxx"].iloc[0] == pytest.approx(-1e5, rel=2e-3)
    assert path["syy"].iloc[2] < path["syy"].iloc[0] < path["sxx"].iloc[2]
    assert np.isnan(path["D_xx_xx"].iloc[1]) and path["D_xx_xx"].iloc[2] > 0
    assert path["D_xx_yy"].iloc[0] == pytest.approx(path["D_xy_xy"].iloc[0], rel=1e-12)
    assert path["D_xy_xy"].iloc[2] > 1.2 * path["D_xx_yy"].iloc[2]  # kt terms now present


def test_yade_drive_kinematics_exact_and_shear2d(guo_zhao_seed1, tmp_path: Path) -> None:
    """Pure shear G = diag(+0.2 %, −0.2 %): with F = I + G the area changes by
    det F = 1.002·0.998 = 1 − 4e-6, so 1 + e scales by it; Guo & Zhao's L = ΔG/(n·dt) is
    trace-free, the area stays (forward Euler: (1 − (1e-5)²)^200 ≈ 1 − 2e-8)."""
    rve, _, _ = guo_zhao_seed1
    exact, s_exact = yade_runner.yade_drive(rve, [0.002, 0.0, 0.0, -0.002], 2,
                                            kinematics="exact", workdir=tmp_path / "exact")
    g_z, _ = yade_runner.yade_drive(rve, [0.002, 0.0, 0.0, -0.002], 2,
                                    workdir=tmp_path / "shear2d")
    e0 = exact["void_ratio"].iloc[0]
    # YADE integrates the cell explicitly: O((L·dt)²) = 1e-10 a step, 200 steps
    assert 1 + exact["void_ratio"].iloc[-1] == pytest.approx((1 + e0) * 1.002 * 0.998,
                                                             rel=5e-8)
    assert abs(g_z["void_ratio"].iloc[-1] - e0) < 1e-7
    assert s_exact["kinematics"] == "exact"
    with pytest.raises(ValueError, match="kinematics"):
        yade_runner.yade_drive(rve, [0.002, 0.0, 0.0, -0.002], 2, kinematics="log")


def test_yade_throughput_is_measured(guo_zhao_seed1) -> None:
    """docs/design.md#yade-anchors: one YADE core ran 2.3–2.6e6 particle-steps/s on this RVE
    (2-core machine); a loaded CI machine may be several times slower, so only the order of
    magnitude is held."""
    rve, _, _ = guo_zhao_seed1
    rate = yade_runner.yade_throughput(rve, steps=2000)
    assert rate is not None and 1e5 < rate < 1e8


@needs_yade
def test_failing_yade_script_reports_its_log(tmp_path: Path) -> None:
    with pytest.raises(yade_runner.YadeError, match="No such file"):
        yade_runner.run_script("echo_scene.py", {"scene": str(tmp_path / "missing.json"),
                                                 "out": str(tmp_path / "o.json")}, tmp_path)


@needs_yade
def test_smoke_case_through_the_command_line(tmp_path: Path) -> None:
    """``validate-yade --cases smoke``: YADE and our engine from the same Guo & Zhao RVE."""
    from granular_material_validation.engine_runner import engine_available

    from granular_material.cli import main

    if not engine_available():
        pytest.skip("our DEM commands are not built yet")
    code = main(["validate-yade", "--cases", "smoke", "--out", str(tmp_path), "--device",
                 "cpu"])
    results = json.loads((tmp_path / "results.json").read_text())
    (entry,) = results["cases"]
    assert (tmp_path / "report.md").read_text().count("| smoke |") >= 2
    assert (tmp_path / "plots" / "smoke.png").stat().st_size > 10_000
    seed = entry["per_seed"][0]
    comparison = seed["comparison"]
    assert comparison["strain_max"] == pytest.approx(0.03, abs=1e-4)
    assert seed["yade_wall_s"] > 0 and seed["ours_wall_s"] > 0
    assert code == (0 if entry["passed"] else 1)
    # Acceptance (issue 5): peak σ1/σ3 within 5 %, its strain within 0.5 % strain.
    assert comparison["peak_ratio_diff"] <= 0.05
    assert comparison["strain_at_peak_diff"] <= 0.005
    # Before 1 % axial strain both codes follow the same deterministic path (measured here:
    # 0.56 % of the peak stress for seed 1); chaos only sets in towards the peak, so a
    # systematic difference shows up here first.
    import pandas as pd

    run = tmp_path / "runs" / "smoke" / "seed1"
    yade, ours = pd.read_csv(run / "yade_curve.csv"), pd.read_csv(run / "ours_curve.csv")
    early = yade["axial_strain"] <= 0.01
    x = yade.loc[early, "axial_strain"]
    worst = max(np.abs(np.interp(x, ours["axial_strain"], ours[c]) - yade.loc[early, c]).max()
                for c in ("sxx", "syy", "sxy"))
    assert worst <= 0.01 * comparison["stress_scale"]


def test_single_element_case_at_smoke_size(tmp_path: Path) -> None:
    """gz-single-element at smoke size (seed 1, 3 % axial strain in 30 load steps of 0.1 %):
    our FEM × DEM element against YADE's pure-DEM biaxial test of the same Guo & Zhao RVE.

    Measured here (seed 1): peak σ1/σ3 2.883 against YADE's 2.890; up to 1 % axial strain
    σxx, σyy within 0.7 % of the peak stress and σ1/σ3 within 0.9 %. σxy differs by design:
    the element's sides carry no shear traction (its mean σxy stays below 1 kPa) while YADE's
    periodic cell keeps its shape and builds σxy up (4.6 kPa before the peak).
    """
    from granular_material_validation.cases import CASES, run_case
    from granular_material_validation.engine_runner import engine_available
    from granular_material_validation.metrics import stress_ratio

    if shutil.which("yade") is None:
        pytest.skip("needs Debian's yade")
    if not engine_available():
        pytest.skip("our DEM commands are not built yet")
    from dataclasses import replace

    case = replace(CASES["gz-single-element"], seeds=(1,), axial_strain=0.03, steps=30)
    entry = run_case(case, tmp_path, device="cpu")
    (run,) = entry["_runs"]
    seed = entry["per_seed"][0]
    assert seed["fem"]["steps_completed"] == 30
    assert run.ours["axial_strain"].iloc[-1] == pytest.approx(0.03, rel=1e-12)
    assert len(run.ours) == 31 and seed["ours_wall_s"] > 0 and seed["yade_wall_s"] > 0
    comparison = seed["comparison"]
    assert comparison["peak_ratio_diff"] <= 0.05  # acceptance: peak σ1/σ3 within 5 %
    assert comparison["peak_inside"]
    # The curves overlap before the peak: normal stresses and σ1/σ3 up to 1 % axial strain
    yade, fem = run.yade, run.ours
    early = (yade["axial_strain"] <= 0.01).to_numpy()
    x = yade.loc[early, "axial_strain"]
    scale = comparison["stress_scale"]
    for column in ("sxx", "syy"):
        diff = np.interp(x, fem["axial_strain"], fem[column]) - yade.loc[early, column]
        assert np.abs(diff).max() <= 0.02 * scale, column
    ratio = np.interp(x, fem["axial_strain"], stress_ratio(fem))
    assert np.abs(ratio / stress_ratio(yade)[early] - 1).max() <= 0.02
    shear = seed["shear_stress"]
    assert shear["max_abs_sxy_fem"] < 0.01 * scale < shear["max_abs_sxy_yade"]
    # the element's lateral stress is the confining traction (Newton's stress tolerance 0.5 %)
    assert seed["servo_error_ours"] < 0.02
