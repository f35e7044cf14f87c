"""The library keeps the command line's promises (issue 47), one test per kind: a stopped
run's checkpoint is never thrown away unasked, no run from the command line writes nothing,
every file the library writes is whole or left as it was, a material refuses another's
checkpoint by name, an allocation is refused before it is taken, a ∇u that is not a real
finite array is a failure or an error and never a NaN stress, and a list a user can make
long is bounded before any work."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import numpy as np
import pytest
from run_helpers import StopAfterRecord

from granular_material.cli import main
from granular_material.errors import ParameterError
from granular_material.fem import LinearElastic
from granular_material.fem.materials.mohr_coulomb import MohrCoulomb
from granular_material.runs import (
    MaterialSpec,
    OutputSpec,
    ProblemSpec,
    RunSpec,
    SpecError,
    check,
    load,
    run,
    save,
)


def _elastic(out: Path | None, steps: int = 6) -> RunSpec:
    return RunSpec(problem=ProblemSpec(test="single-element", steps=steps, axial_strain=0.006),
                   material=MaterialSpec(name="linear-elastic", parameters={"young": 50e6}),
                   output=OutputSpec(out=out, checkpoint_every=1), device="cpu")


def _files(folder: Path) -> dict[Path, bytes]:
    return {p: p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# -- a stopped run's work is never lost unasked ----------------------------------------------
def test_a_run_into_a_stopped_runs_folder_is_refused_unless_resumed_or_fresh(tmp_path):
    spec = _elastic(tmp_path / "run")
    stopped = run(spec, StopAfterRecord(3))
    assert stopped.interrupt is not None and len(stopped.result.steps) == 4
    before = _files(tmp_path / "run")
    with pytest.raises(ParameterError, match=r"stopped after load step [23] of 6.*resume=True"):
        run(spec)
    assert _files(tmp_path / "run") == before  # nothing in the folder changed
    with pytest.raises(ParameterError, match="exclude each other"):
        run(spec, resume=True, fresh=True)
    resumed = run(spec, resume=True)
    assert resumed.summary["resumed_from_step"] in (2, 3) and len(resumed.result.steps) == 7
    run(spec, StopAfterRecord(2))
    again = run(spec, fresh=True)  # asked for explicitly: starts from step 0
    assert again.summary["resumed_from_step"] is None and len(again.result.steps) == 7
    assert run(spec).interrupt is None  # a finished run's folder may be run again


def test_a_spec_file_without_an_output_folder_writes_into_its_named_folder(
        tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    save(_elastic(None, steps=2), tmp_path / "plain.toml")
    assert main(["run", "plain.toml"]) == 0
    assert "names no output folder" in capsys.readouterr().err
    summary = json.loads((tmp_path / "plain" / "summary.json").read_text())
    assert Path(summary["out"]).name == "plain"
    assert len((tmp_path / "plain" / "steps.csv").read_text().splitlines()) == 4  # + header


# -- every file whole or as it was -----------------------------------------------------------
def _full_disk(monkeypatch) -> None:
    """Every write of a temporary ``.part`` file fails as on a full disk, after a few bytes."""
    real_open = open

    class Full:
        def __init__(self, fh):
            self.fh = fh

        def write(self, data):
            self.fh.write(data[:3])
            raise OSError(errno.ENOSPC, "No space left on device")

        def __getattr__(self, name):
            return getattr(self.fh, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

    def failing_open(file, mode="r", *args, **kwargs):
        fh = real_open(file, mode, *args, **kwargs)
        return Full(fh) if str(file).endswith(".part") and "w" in mode else fh

    monkeypatch.setattr("builtins.open", failing_open)
    real_write_text = Path.write_text

    def failing_write_text(self, data, *args, **kwargs):
        if self.name.endswith(".part"):
            real_write_text(self, data[:3], *args, **kwargs)
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_write_text(self, data, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", failing_write_text)


@pytest.mark.parametrize("name", ["spec.toml", "spec.json", "le.npz", "mc.npz"])
def test_a_full_disk_keeps_the_previous_file(tmp_path, monkeypatch, name):
    path = tmp_path / name
    materials = {"le.npz": LinearElastic, "mc.npz": MohrCoulomb}

    def write():
        if name.startswith("spec"):
            save(_elastic(None), path)
        else:
            material = materials[name](initial_stress=-1e5)
            material.allocate(3)
            material.checkpoint(path)

    write()
    good = path.read_bytes()
    with monkeypatch.context() as m:
        _full_disk(m)
        with pytest.raises(OSError, match=str(path)):
            write()
    assert path.read_bytes() == good
    assert os.listdir(tmp_path) == [name]  # no .part left
    if name.startswith("spec"):
        assert load(path) == _elastic(None)


# -- another material's checkpoint is refused by name ----------------------------------------
def test_a_checkpoint_of_another_material_is_refused_by_name(tmp_path):
    from granular_material.multiscale import DEMMaterial

    elastic, plastic = LinearElastic(), MohrCoulomb()
    for material, name in ((elastic, "le.npz"), (plastic, "mc.npz")):
        material.allocate(2)
        material.checkpoint(tmp_path / name)
    with pytest.raises(ValueError, match="checkpoint of the mohr-coulomb material, not"):
        LinearElastic().restore(tmp_path / "mc.npz")
    with pytest.raises(ValueError, match="checkpoint of the linear-elastic material, not"):
        MohrCoulomb().restore(tmp_path / "le.npz")
    with pytest.raises(ValueError, match="checkpoint of the linear-elastic material, not"):
        DEMMaterial(particles=64, device="cpu").restore(tmp_path / "le.npz")
    np.savez(tmp_path / "rve.npz", radius=np.ones((1, 4)), meta=np.array("{}"))
    with pytest.raises(ValueError, match="looks like an RVE file"):
        LinearElastic().restore(tmp_path / "rve.npz")
    (tmp_path / "text.npz").write_text("not an archive")
    for material in (LinearElastic(), MohrCoulomb()):
        with pytest.raises(ValueError, match="not a checkpoint") as info:
            material.restore(tmp_path / "text.npz")
        assert "allow_pickle" not in str(info.value)


# -- allocations refused before they are taken -----------------------------------------------
@pytest.mark.parametrize("make", [LinearElastic, MohrCoulomb,
                                  lambda: __import__("granular_material.multiscale",
                                                     fromlist=["DEMMaterial"]).DEMMaterial(
                                      particles=64, device="cpu")])
def test_an_allocation_too_large_is_refused_before_it_is_taken(make):
    material = make()
    with pytest.raises(ParameterError, match=r"n_points is too many: .* needs about .* of "
                                             "memory") as info:
        material.allocate(10**9)
    assert info.value.field == "n_points"
    for bad in (2.5, "3", True, 0, -1):
        with pytest.raises(ParameterError, match="n_points"):
            material.allocate(bad)
    assert material.n_points == 0


# -- ∇u that is not a real finite array ------------------------------------------------------
@pytest.mark.parametrize("make", [LinearElastic, MohrCoulomb])
def test_a_bad_grad_u_is_a_failure_or_an_error_never_a_nan_stress(make):
    material = make(initial_stress=-1e5)
    material.allocate(3)
    for bad in (np.nan, np.inf, -np.inf):
        grad = np.zeros((3, 2, 2))
        grad[1, 0, 1] = bad
        response = material.evaluate(grad)
        assert np.isfinite(response.stress).all() and np.isfinite(response.tangent).all()
        assert list(response.reasons) == ["", "non_finite_input", ""]
        total = material.response(grad)  # the total form too
        assert np.isfinite(total.stress).all()
    for bad in (None, np.zeros((3, 2, 2), dtype=complex) + 1e-3j, np.full((3, 2, 2), "a"),
                np.zeros((3, 2))):
        with pytest.raises(ValueError, match="grad_u"):
            material.evaluate(bad)
        with pytest.raises(ValueError, match="grad_u"):
            material.response(bad)
    # a failed point never commits a non-finite state: the linear-elastic material keeps
    # its committed state there, the Mohr-Coulomb material refuses the commit
    grad = np.full((3, 2, 2), 1e-4)
    grad[0] = np.nan
    material.evaluate(grad)
    if isinstance(material, MohrCoulomb):
        with pytest.raises(RuntimeError, match="refuses"):
            material.commit()
        material.revert()
    else:
        material.commit()
        assert np.array_equal(material.strain[0], np.zeros((2, 2)))
    assert np.isfinite(material.committed_grad_u).all()
    assert np.isfinite(material.evaluate(np.zeros((3, 2, 2))).stress).all()


# -- lists a user can make long --------------------------------------------------------------
def test_long_lists_are_bounded_before_any_work(tmp_path):
    with pytest.raises(SpecError, match=r"500 strains, at most 20.*~750 s"):
        OutputSpec(map_strain=[0.01] * 500)
    spec = RunSpec(problem=ProblemSpec(test="biaxial", elements=(10, 10), steps=5000),
                   material=MaterialSpec(name="dem", parameters={"particles": 64}),
                   output=OutputSpec(track=("all",)), device="cpu")
    with pytest.raises(SpecError, match=r"track would post-process \d+ RVEs \(400 points"):
        check(spec)


def test_fractal_per_octave_is_bounded_before_any_work(small_rve_path, capsys):
    argv = ["fractal", str(small_rve_path), "--box-rule", "physical", "--per-octave",
            "100000000"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--per-octave 100000000 asks for about 4e+08 box sides" in err
    assert main(["fractal", str(small_rve_path), "--box-min", "0.003"]) == 2
    assert "--box-rule cell would ignore it" in capsys.readouterr().err


def test_a_newton_bound_is_a_field_error_not_an_overflow(capsys):
    from granular_material.runs import NewtonSpec

    with pytest.raises(SpecError, match="max_cutbacks must be at most 50"):
        NewtonSpec(max_cutbacks=100_000)
    argv = ["single-element", "--material", "linear-elastic", "--steps", "1", "--device",
            "cpu", "--no-progress", "--max-cutbacks", "100000"]
    assert main(argv) == 2
    assert "--max-cutbacks must be at most 50" in capsys.readouterr().err


def test_the_dem_material_never_commits_a_failed_point(small_rve_path):
    from granular_material.multiscale import DEMMaterial

    material = DEMMaterial(rve=small_rve_path, device="cpu")
    material.allocate(2)
    grad = np.zeros((2, 2, 2))
    grad[0, 0, 0] = np.nan
    response = material.evaluate(grad)
    assert np.isfinite(response.stress).all()
    assert response.reasons[0] == "non_finite_input"
    with pytest.raises(RuntimeError, match="refuses"):
        material.commit()
    assert np.isfinite(material.committed_grad_u).all()
    for bad in (None, np.zeros((2, 2, 2), dtype=complex)):
        with pytest.raises(ValueError, match="grad_u"):
            material.evaluate(bad)
    material.revert()
    material.evaluate(np.zeros((2, 2, 2)))
    material.commit()
    assert np.array_equal(material.committed_grad_u, np.zeros((2, 2, 2)))


def test_a_dangling_link_or_a_pipe_is_named_for_what_it_is(tmp_path, capsys):
    (tmp_path / "link").symlink_to(tmp_path / "nowhere" / "run")
    argv = ["single-element", "--material", "linear-elastic", "--steps", "1",
            "--device", "cpu", "--no-progress", "--out", str(tmp_path / "link")]
    assert main(argv) == 2
    assert "is a symbolic link to" in capsys.readouterr().err
    save(_elastic(None, steps=1), tmp_path / "spec.toml")
    read, write = os.pipe()
    os.write(write, (tmp_path / "spec.toml").read_bytes())
    os.close(write)
    try:
        assert main(["run", f"/dev/fd/{read}"]) == 2
    finally:
        os.close(read)
    assert "names no output folder" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "spec.toml"]


@pytest.mark.parametrize(("make", "field"), [
    (lambda: LinearElastic(young="60e6"), "young"),
    (lambda: LinearElastic(poisson=None), "poisson"),
    (lambda: LinearElastic(initial_stress="-1e5"), "initial_stress"),
    (lambda: LinearElastic(initial_stress=[[1.0, 2.0], [3.0]]), "initial_stress"),
    (lambda: MohrCoulomb(friction_angle=None), "friction_angle"),
    (lambda: __import__("granular_material.multiscale", fromlist=["DEMMaterial"])
     .DEMMaterial(device=3), "device"),
    (lambda: __import__("granular_material.multiscale", fromlist=["DEMMaterial"])
     .DEMMaterial(rve=5), "rve"),
    (lambda: __import__("granular_material.multiscale", fromlist=["DEMMaterial"])
     .DEMMaterial(particles="64"), "particles"),
])
def test_a_material_built_in_python_names_a_parameter_of_the_wrong_type(make, field):
    with pytest.raises(ParameterError) as info:
        make()
    assert info.value.field == field


def test_a_stray_part_folder_is_refused_before_any_work(tmp_path):
    from granular_material.filesafe import write_whole

    (tmp_path / "run" / "steps.csv.part").mkdir(parents=True)
    with pytest.raises(ParameterError, match=r"holds the folder steps.csv.part"):
        run(_elastic(tmp_path / "run", steps=2))
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["steps.csv.part"]
    with pytest.raises(IsADirectoryError, match="is a folder in the way"):
        write_whole(tmp_path / "run" / "steps.csv", lambda tmp: tmp.write_text("x"))


def test_particles_beside_an_rve_file_is_refused(small_rve_path):
    spec = RunSpec(problem=ProblemSpec(test="single-element", steps=1),
                   material=MaterialSpec(name="dem", parameters={"rve": small_rve_path,
                                                                 "particles": 64}),
                   device="cpu")
    with pytest.raises(ParameterError, match="particles sets the material") as info:
        check(spec)
    assert info.value.field == "particles" and "--" not in str(info.value)
