"""The minor items of issue 61: --resume into a folder with no stopped run starts the run
(as every command's does), a rerun into a finished folder leaves none of the old run's files
beside the new ones, summary.json is strict JSON, four messages that named the wrong thing,
and the calibration's note on an elastic window that reaches into plastic flow."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from run_helpers import PRESSED_BLOCK
from test_bvp_resume import _stop_at

from granular_material.cli import main
from granular_material.fem import MohrCoulomb
from granular_material.procedures.calibration import drained_point_curve
from granular_material.procedures.calibration_reading import read_parameters
from granular_material.results.writers import strict_json, write_json

SCENE = """test = "boundary-value"
steps = 2
[mesh]
{mesh}
[boundaries]
base = "y = bottom"
top = "y = top"
""" + PRESSED_BLOCK.format(base="base")
GENERATED = "size = [0.4, 0.2]\nelements = [2, 2]"


def _scene(tmp_path: Path, mesh: str = GENERATED, extra: str = "") -> Path:
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.format(mesh=mesh) + extra)
    return path


def _strict(path: Path) -> dict:
    def refuse(constant: str) -> None:
        raise AssertionError(f"{path} holds {constant}, which is no JSON")

    return json.loads(path.read_text(), parse_constant=refuse)


@pytest.mark.parametrize("state", ["absent", "empty", "finished"])
def test_resume_into_a_folder_with_no_stopped_run_starts_it(tmp_path, capsys, state):
    scene, out = _scene(tmp_path), tmp_path / "run"
    if state == "empty":
        out.mkdir()
    elif state == "finished":
        assert main(["run", str(scene), "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["run", str(scene), "--out", str(out), "--resume"]) == 0
    err = capsys.readouterr().err
    assert "holds no stopped boundary-value run" in err and "starts from the beginning" in err
    summary = _strict(out / "summary.json")
    assert summary["error"] is None and summary["resumed_from_step"] is None
    assert (out / "scene.toml").read_text() == scene.read_text()


def test_a_stopped_run_still_resumes_from_its_step(tmp_path, monkeypatch, capsys):
    scene, out = _scene(tmp_path, extra=""), tmp_path / "run"
    scene.write_text(scene.read_text().replace("steps = 2", "steps = 3"))
    with monkeypatch.context() as m:
        _stop_at(m, 2)
        assert main(["run", str(scene), "--out", str(out)]) == 130
    assert main(["run", str(scene), "--out", str(out), "--resume"]) == 0
    assert _strict(out / "summary.json")["resumed_from_step"] in (0, 1)


def test_a_rerun_into_a_finished_folder_leaves_no_old_file_beside_the_new(tmp_path):
    scene, out = _scene(tmp_path), tmp_path / "run"
    assert main(["run", str(scene), "--out", str(out)]) == 0
    assert (out / "fields.xdmf").is_file() and (out / "mechanism.png").is_file()
    # the rerun writes no fields
    scene.write_text(scene.read_text() + "[output]\nfields = false\n")
    assert main(["run", str(scene), "--out", str(out)]) == 0
    assert not (out / "fields.xdmf").exists() and not (out / "fields.h5").exists()
    assert (out / "mechanism.png").is_file()  # drawn again by this run


def test_summary_json_is_strict_json_whatever_the_numbers(tmp_path):
    data = {"a": float("nan"), "b": [1.0, float("inf"), np.float64(-np.inf)],
            "c": np.array([1.0, np.nan]), "d": {"e": np.float32(2.5), "f": np.int64(3)},
            "g": "text", "h": None, "i": True}
    assert strict_json(data) == {"a": None, "b": [1.0, None, None], "c": [1.0, None],
                                 "d": {"e": 2.5, "f": 3}, "g": "text", "h": None, "i": True}
    path = write_json(data, tmp_path / "summary.json")
    assert _strict(path)["c"] == [1.0, None]


def test_values_near_the_largest_float_end_with_strict_json(tmp_path, capsys):
    scene = _scene(tmp_path)
    scene.write_text(scene.read_text().replace("young = 60e6", "young = 1e306"))
    code = main(["run", str(scene), "--out", str(tmp_path / "run")])
    capsys.readouterr()
    summary = _strict(tmp_path / "run" / "summary.json")
    assert code in (0, 1) and "error" in summary
    for value in summary["bodies"]["top"].values():
        assert value is None or math.isfinite(value)


@pytest.mark.parametrize(("test", "meant"), [("Boundary-Value", "boundary-value"),
                                             ("boundary_value", "boundary-value"),
                                             ("Single-Element", "single-element")])
def test_a_test_name_in_another_case_is_named_as_the_fault(tmp_path, capsys, test, meant):
    scene = _scene(tmp_path)
    scene.write_text(scene.read_text().replace('"boundary-value"', f'"{test}"'))
    assert main(["run", str(scene), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert "line 1" in err and f"did you mean '{meant}'" in err and "conditions" not in err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(("make", "words"), [
    (lambda p: p.mkdir(), "is a folder, not a mesh file"),
    (lambda p: p.write_text(""), "is empty, not a mesh file"),
    (lambda p: p.write_text("hello\n"), "its content is no mesh that meshio's readers of "
                                        "its suffix .msh take"),
])
def test_a_mesh_file_that_is_no_mesh_is_named_for_what_it_is(tmp_path, capsys, make, words):
    make(tmp_path / "m.msh")
    scene = _scene(tmp_path, mesh='file = "m.msh"')
    assert main(["run", str(scene), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert words in err and "does not exist" not in err and "no reader" not in err
    assert not (tmp_path / "run").exists()


def test_a_mesh_far_from_the_origin_is_no_zero_area(tmp_path, capsys):
    import meshio
    from test_bvp_resume_files import _block

    mesh = meshio.read(_block(tmp_path / "near.msh"))
    mesh.points[:, 0] += 1e12
    meshio.write(tmp_path / "far.msh", mesh, file_format="gmsh22", binary=False)
    scene = _scene(tmp_path, mesh='file = "far.msh"')
    assert main(["run", str(scene), "--out", str(tmp_path / "run")]) == 0
    assert "area" not in capsys.readouterr().err


def test_an_elastic_window_into_plastic_flow_is_noted():
    true = {"young": 40e6, "poisson": 0.25, "friction_angle": 34.0, "dilation_angle": 8.0,
            "cohesion": 0.0, "critical_friction_angle": 28.0, "softening_strain": 0.03}
    curve = drained_point_curve(MohrCoulomb(**true, initial_stress=-100e3), 100e3, 0.02)
    fine = read_parameters(curve, 100e3)
    assert not any("elastic window" in note for note in fine.notes)
    wide = read_parameters(curve, 100e3, elastic_window=0.012)
    noted = [note for note in wide.notes if "elastic window" in note]
    assert noted and "plastic flow" in noted[0] and "narrow elastic_window" in noted[0]
    assert wide.parameters["young"] < 0.8 * fine.parameters["young"]
    with pytest.raises(ValueError, match="narrow elastic_window"):  # the whole 2 % test
        read_parameters(curve, 100e3, elastic_window=0.5)


@pytest.fixture(scope="module")
def rve16(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from granular_material.dem import save_rve
    from granular_material.procedures import prepare_packing

    path = tmp_path_factory.mktemp("rve") / "rve16.npz"
    save_rve(path, prepare_packing(n_disc=16, seed=1, pressure=100e3, device="cpu").to_data())
    return path


def _dem_scene(tmp_path: Path, rve: Path) -> Path:
    scene = tmp_path / "dem.toml"
    scene.write_text(f'test = "biaxial-dem"\nrve = "{rve}"\naxial_strain = 0.002\n'
                     'record_every = 20\ndevice = "cpu"\nprogress = false\n')
    return scene


def test_a_dem_scene_checked_for_a_resume_shows_the_switch(tmp_path, capsys, rve16):
    scene = _dem_scene(tmp_path, rve16)
    assert main(["run", str(scene), "--out", str(tmp_path / "b"), "--check", "--resume"]) == 0
    shown = capsys.readouterr().out.strip().splitlines()[-1]
    assert shown.endswith("--resume") and f"--resume {tmp_path / 'b'}" not in shown


@pytest.mark.parametrize("kind", ["dem", "fem"])
def test_a_stopped_scene_says_how_to_continue_it(tmp_path, capsys, monkeypatch, rve16, kind):
    out = tmp_path / "run"
    if kind == "dem":
        import granular_material.procedures.element_tests as element_tests

        scene = _dem_scene(tmp_path, rve16)
        real = element_tests.servo_steps
        calls = {"n": 0}

        def stop(*args, **kwargs):
            calls["n"] += 1
            if calls["n"] == 2:
                raise KeyboardInterrupt("signal")
            return real(*args, **kwargs)

        monkeypatch.setattr(element_tests, "servo_steps", stop)
    else:
        scene = tmp_path / "fem.toml"
        scene.write_text('test = "single-element"\nmaterial = "linear-elastic"\nsteps = 3\n'
                         'axial_strain = 0.002\ndevice = "cpu"\nprogress = false\n')
        _stop_at(monkeypatch, 2)
    assert main(["run", str(scene), "--out", str(out)]) == 130
    err = capsys.readouterr().err
    assert f"`granular-material run {scene} --out {out} --resume`" in err
    assert "the same options" not in err
    monkeypatch.undo()
    assert main(["run", str(scene), "--out", str(out), "--resume"]) == 0


def test_the_tables_are_flushed_a_second_apart_and_at_the_end(tmp_path, monkeypatch):
    """A boundary-value run flushes its tables (``fsync``) as a biaxial run does: with the
    first step a second after the last flush, and when it ends; not at every step."""
    import os

    from granular_material.results import writers

    flushed: list[str] = []
    real = os.fsync

    def fsync(fd: int) -> None:
        flushed.append(os.path.basename(os.readlink(f"/proc/self/fd/{fd}")))
        real(fd)

    if not os.path.isdir("/proc/self/fd"):
        pytest.skip("needs /proc to name the flushed files")
    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(writers, "SYNC_SECONDS", 1e9)  # the clock never lets one more in
    out = tmp_path / "run"
    assert main(["run", str(_scene(tmp_path)), "--out", str(out)]) == 0
    steps = [name for name in flushed if name in ("points.npy", "steps.csv")]
    # the first appended step (step 1) and the end: points before steps each time
    assert steps == ["points.npy", "points.npy", "steps.csv", "points.npy", "steps.csv"]
