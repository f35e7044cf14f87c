"""The DEM runs on the run specification (issue 57): ``prepare``, ``biaxial-dem`` and
``dem-drive`` as specs with dict/JSON/TOML forms, run by ``runs.run(spec)``, checked before
any work, and a stopped biaxial test or path resumed to the very table an uninterrupted run
writes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import granular_material.procedures.driven_path as driven_path
import granular_material.procedures.element_tests as element_tests
from granular_material.cli import main
from granular_material.dem import load_rve, save_rve
from granular_material.errors import ParameterError
from granular_material.procedures import prepare_packing
from granular_material.runs import SpecError, check, run
from granular_material.runs.dem import (
    BiaxialDemSpec,
    DriveSpec,
    PrepareSpec,
    checkpoint_folder,
    from_dict,
    load,
    save,
    to_dict,
)
from granular_material.runs.resume import StoppedRunError


@pytest.fixture(scope="module")
def rve64(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rve") / "rve64.npz"
    save_rve(path, prepare_packing(n_disc=64, seed=1, pressure=100e3, device="cpu").to_data())
    return path


def _interrupt_on_call(monkeypatch, module, name: str, call: int) -> None:
    """``module.name`` raises KeyboardInterrupt on its ``call``-th call (as Ctrl-C would)."""
    real = getattr(module, name)
    calls = {"n": 0}

    def wrapped(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == call:
            raise KeyboardInterrupt("signal")
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, wrapped)


def _specs(rve: Path, tmp_path: Path) -> list:
    return [PrepareSpec(particles=32, seed=4, contact_friction_angle=0.3, law="frictmat",
                        contact_young=2e8, target_void_ratio=0.2, out=tmp_path / "r.npz"),
            BiaxialDemSpec(rve=rve, axial_strain=0.02, out=tmp_path / "c.csv",
                           plot=tmp_path / "c.png", device="cpu", dtype="float32"),
            DriveSpec(rve=rve, grad_u=(0.0, 1e-3, 0.0, -2e-3), increments=3)]


@pytest.mark.parametrize("suffix", [".json", ".toml"])
def test_the_specs_round_trip_through_dict_json_and_toml(rve64, tmp_path, suffix):
    for spec in _specs(rve64, tmp_path):
        assert from_dict(to_dict(spec)) == spec
        assert from_dict(json.loads(json.dumps(to_dict(spec)))) == spec
        path = tmp_path / f"{spec.test}{suffix}"
        save(spec, path)
        assert load(path) == spec


@pytest.mark.parametrize(("make", "field"), [
    (lambda rve: PrepareSpec(particles=0), "particles"),
    (lambda rve: PrepareSpec(pressure=-5.0), "pressure"),
    (lambda rve: PrepareSpec(law="hertz"), "law"),
    (lambda rve: PrepareSpec(contact_young=float("nan")), "contact_young"),
    (lambda rve: BiaxialDemSpec(rve=rve, confining=0.0), "confining"),
    (lambda rve: BiaxialDemSpec(rve=rve, dtype="float16"), "dtype"),
    (lambda rve: DriveSpec(rve=rve, grad_u=(0.0, 1.0, 0.0)), "grad_u"),
    (lambda rve: from_dict({"problem": {"test": "biaxial-dem", "rve": str(rve), "steps": 3}}),
     "steps"),
    (lambda rve: from_dict({"problem": {"test": "dem-drive", "rve": str(rve)}}), "grad_u"),
    (lambda rve: from_dict({"problem": {"test": "biaxial"}}), "test"),
    (lambda rve: from_dict({"problem": {"test": "prepare", "out": "r.npz"}}), "out"),
    (lambda rve: from_dict({"problem": {"test": "biaxial-dem", "rve": str(rve)},
                            "material": {"kn": 1.0}}), "material"),
    (lambda rve: from_dict({"problem": {"test": "prepare"}, "output": 3}), "output"),
])
def test_a_refused_spec_names_its_field(rve64, make, field):
    with pytest.raises(SpecError) as caught:
        make(rve64)
    assert caught.value.field == field


def test_the_checks_before_any_work_name_the_spec_fields(rve64, tmp_path):
    with pytest.raises(ParameterError) as caught:
        check(PrepareSpec(contact_friction_angle=2.0, out=tmp_path / "r.npz"))
    assert caught.value.field == "contact_friction_angle"
    with pytest.raises(ParameterError, match="axial_strain"):
        check(BiaxialDemSpec(rve=rve64, axial_strain=0.95))
    with pytest.raises(ParameterError, match="max_dem_steps"):
        check(DriveSpec(rve=rve64, grad_u=(0.0, 0.001, 0.0, 0.0), increments=600000))
    assert not list(tmp_path.iterdir())
    # the command line names the same refusal by its option
    assert main(["prepare", "--friction-angle", "2", "--out", str(tmp_path / "r.npz"),
                 "--device", "cpu"]) == 2


def test_prepare_from_python_is_the_command_and_a_resume_starts_from_its_seed(tmp_path,
                                                                                capsys):
    spec = PrepareSpec(particles=24, seed=2, out=tmp_path / "py.npz", device="cpu")
    outcome = run(spec)
    assert outcome.error is None and outcome.report["out"] == str(spec.out)
    again = run(spec.replace(out=tmp_path / "again.npz"), resume=True)
    assert again.error is None
    assert main(["prepare", "--particles", "24", "--seed", "2", "--out",
                 str(tmp_path / "cli.npz"), "--device", "cpu", "--no-progress"]) == 0
    capsys.readouterr()
    arrays = [np.load(tmp_path / name) for name in ("py.npz", "again.npz", "cli.npz")]
    for other in arrays[1:]:
        assert sorted(other.files) == sorted(arrays[0].files)
        for key in arrays[0].files:
            assert np.array_equal(arrays[0][key], other[key]), key
    assert not checkpoint_folder(spec.out).exists()


def _cli(capsys, *argv: str) -> tuple[int, dict, str]:
    code = main([*argv, "--json", "--device", "cpu", "--no-progress"])
    captured = capsys.readouterr()
    return code, json.loads(captured.out) if captured.out.strip() else {}, captured.err


def test_a_stopped_biaxial_dem_resumes_to_the_same_curve(rve64, tmp_path, monkeypatch,
                                                          capsys):
    common = ["biaxial-dem", str(rve64), "--axial-strain", "0.01", "--record-every", "50"]
    whole = tmp_path / "whole.csv"
    assert _cli(capsys, *common, "--out", str(whole))[0] == 0
    assert not checkpoint_folder(whole).exists()  # a finished run leaves no checkpoint

    csv = tmp_path / "curve.csv"
    with monkeypatch.context() as patch:  # Ctrl-C in the 4th chunk of 50 DEM steps
        _interrupt_on_call(patch, element_tests, "servo_steps", 4)
        code, report, err = _cli(capsys, *common, "--out", str(csv))
    assert code == 130 and report["steps"] == 150 and "--resume" in err
    assert (checkpoint_folder(csv) / "state.npz").is_file()

    # a fresh run over it is refused, and so is a resume with another option
    code, _, err = _cli(capsys, *common, "--out", str(csv))
    assert code == 2 and "--out" in err and "--resume" in err and "--fresh" in err
    code, _, err = _cli(capsys, *common, "--confining", "200000", "--out", str(csv),
                        "--resume")
    assert code == 2 and "--confining 200000.0 (the run had 100000.0)" in err
    code, _, err = _cli(capsys, *common, "--out", str(csv), "--resume", "--fresh")
    assert code == 2 and "exclude each other" in err

    code, report, _ = _cli(capsys, *common, "--out", str(csv), "--resume")
    assert code == 0 and report["error"] is None and report["steps"] == 1006
    assert 0 < report["resumed_from_step"] <= 150
    assert csv.read_bytes() == whole.read_bytes()
    assert not checkpoint_folder(csv).exists()


def test_fresh_starts_over_a_stopped_run(rve64, tmp_path, monkeypatch, capsys):
    spec = BiaxialDemSpec(rve=rve64, axial_strain=0.005, record_every=50,
                          out=tmp_path / "c.csv", device="cpu")
    with monkeypatch.context() as patch:
        _interrupt_on_call(patch, element_tests, "servo_steps", 3)
        assert run(spec).interrupt is not None
    with pytest.raises(StoppedRunError) as caught:
        run(spec)
    assert caught.value.field == "out"
    outcome = run(spec, fresh=True)
    assert outcome.error is None and outcome.resumed_from is None
    whole = run(spec.replace(out=tmp_path / "whole.csv"))
    assert (tmp_path / "c.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()
    assert whole.resumed_from is None


def test_a_stopped_path_resumes_from_python_to_the_same_table(rve64, tmp_path,
                                                              monkeypatch):
    spec = DriveSpec(rve=rve64, grad_u=(0.0, 0.002, 0.0, 0.0), increments=5,
                     out=tmp_path / "path.csv", device="cpu")
    with monkeypatch.context() as patch:
        _interrupt_on_call(patch, driven_path, "drive_grad_u", 3)
        stopped = run(spec)
    assert stopped.interrupt is not None and stopped.report["increments_completed"] == 2
    with pytest.raises(ParameterError) as caught:
        run(spec.replace(increments=6), resume=True)
    assert caught.value.field == "resume" and "`increments` 6" in str(caught.value.message)
    resumed = run(spec, resume=True)
    assert resumed.error is None and resumed.resumed_from is not None
    assert resumed.report["resumed_from_increment"] == resumed.resumed_from
    whole = run(spec.replace(out=tmp_path / "whole.csv"))
    assert resumed.report["steps"] == whole.report["steps"]
    assert (tmp_path / "path.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()


def test_a_resume_checks_the_rve_file(rve64, tmp_path, monkeypatch):
    rve = tmp_path / "rve.npz"
    rve.write_bytes(rve64.read_bytes())
    spec = BiaxialDemSpec(rve=rve, axial_strain=0.005, record_every=50,
                          out=tmp_path / "c.csv", device="cpu")
    with monkeypatch.context() as patch:
        _interrupt_on_call(patch, element_tests, "servo_steps", 3)
        run(spec)
    data = load_rve(rve64)
    data.radius[0, 0] *= 1.01
    save_rve(rve, data)
    with pytest.raises(ParameterError, match="`rve`"):
        run(spec, resume=True)


def test_a_dem_scene_resumes(rve64, tmp_path, monkeypatch, capsys):
    scene = tmp_path / "b.toml"
    scene.write_text(f'test = "biaxial-dem"\nrve = "{rve64}"\naxial-strain = 0.005\n'
                     'record-every = 50\ndevice = "cpu"\nprogress = false\n')
    with monkeypatch.context() as patch:
        _interrupt_on_call(patch, element_tests, "servo_steps", 3)
        assert main(["run", str(scene), "--out", str(tmp_path / "b")]) == 130
    assert main(["run", str(scene), "--out", str(tmp_path / "b")]) == 2
    assert main(["run", str(scene), "--out", str(tmp_path / "b"), "--resume"]) == 0
    assert main(["run", str(scene), "--out", str(tmp_path / "w")]) == 0
    capsys.readouterr()
    assert ((tmp_path / "b" / "curve.csv").read_bytes()
            == (tmp_path / "w" / "curve.csv").read_bytes())
    assert main(["run", str(scene), "--out", str(tmp_path / "c"), "--check"]) == 0


def test_run_takes_no_observer_for_a_dem_spec(rve64):
    with pytest.raises(ParameterError) as caught:
        run(BiaxialDemSpec(rve=rve64), observer=object())
    assert caught.value.field == "observer"


def test_a_damaged_checkpoint_is_refused_and_left_as_it_was(rve64, tmp_path, monkeypatch,
                                                            capsys):
    spec = BiaxialDemSpec(rve=rve64, axial_strain=0.005, record_every=50,
                          out=tmp_path / "c.csv", device="cpu")
    with monkeypatch.context() as patch:
        _interrupt_on_call(patch, element_tests, "servo_steps", 3)
        run(spec)
    state = checkpoint_folder(spec.out) / "state.npz"
    state.write_bytes(state.read_bytes()[:100])
    before = {p.name: p.read_bytes() for p in checkpoint_folder(spec.out).iterdir()}
    with pytest.raises(ParameterError) as caught:
        run(spec, resume=True)
    assert caught.value.field == "resume" and "state.npz" in caught.value.message
    assert {p.name: p.read_bytes() for p in checkpoint_folder(spec.out).iterdir()} == before


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
def test_a_killed_biaxial_dem_resumes_to_the_same_curve(rve64, tmp_path, capsys):
    """kill -9 once a record is saved: --resume ends with the uninterrupted curve."""
    argv = ["biaxial-dem", str(rve64), "--axial-strain", "0.01", "--strain-per-step", "1e-6",
            "--record-every", "100", "--device", "cpu", "--no-progress", "--json"]
    csv = tmp_path / "curve.csv"
    process = subprocess.Popen([sys.executable, "-m", "granular_material.cli", *argv,
                                "--out", str(csv)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    state = checkpoint_folder(csv) / "state.npz"
    deadline = time.monotonic() + 120
    while not state.is_file() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    process.kill()
    process.wait()
    if not state.is_file():
        pytest.skip("the run ended before its first save")
    assert main([*argv, "--out", str(csv)]) == 2  # a stopped run: refused
    assert main([*argv, "--out", str(csv), "--resume"]) == 0
    assert main([*argv, "--out", str(tmp_path / "whole.csv")]) == 0
    capsys.readouterr()
    assert csv.read_bytes() == (tmp_path / "whole.csv").read_bytes()
    assert not checkpoint_folder(csv).exists()


def test_run_takes_a_dem_spec_file(rve64, tmp_path, capsys, monkeypatch):
    """``granular-material run SPEC.toml`` of a saved DEM spec: checked whole (a refused
    field named with its line), shown as the command line with --check, and run."""
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "drive.toml"
    save(DriveSpec(rve=rve64, grad_u=(0.0, 1e-3, 0.0, 0.0), increments=2, device="cpu"),
         path)
    assert main(["run", str(path), "--check"]) == 0
    shown = capsys.readouterr().out
    assert "dem-drive" in shown and "--grad-u=0.0,0.001,0.0,0.0" in shown
    assert main(["run", str(path), "--out", str(tmp_path / "d")]) == 0
    capsys.readouterr()
    assert (tmp_path / "d" / "path.csv").is_file()
    path.write_text(path.read_text().replace("increments = 2", "increments = 0"))
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err
    assert "line" in err and "increments must be >= 1" in err
