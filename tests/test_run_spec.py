"""The run specification: its fields' checks, its lossless forms (JSON, TOML, flat), the
library's run() against the command line, resume against the saved spec, and scenes that
``run --check`` and ``run`` accept and refuse alike."""

from __future__ import annotations

import dataclasses
import json
import shutil
import sys
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from run_helpers import run_table

from granular_material.cli import main
from granular_material.runs import (
    MaterialSpec,
    NewtonSpec,
    OutputSpec,
    ProblemSpec,
    RunSpec,
    SpecError,
    from_dict,
    from_flat,
    load,
    run,
    save,
    to_dict,
    to_flat,
)
from granular_material.runs.serial import to_toml

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

EXAMPLES = Path(__file__).parents[1] / "examples" / "scenes"


def _elastic(**problem) -> RunSpec:
    return RunSpec(problem=ProblemSpec(test="single-element", **problem),
                   material=MaterialSpec(name="linear-elastic", parameters={"young": 50e6}))


# -- fields and their checks -----------------------------------------------------------------
@pytest.mark.parametrize(("build", "name"), [
    (lambda: ProblemSpec(test="single-element", steps=0), "steps"),
    (lambda: ProblemSpec(test="triaxial"), "test"),
    (lambda: ProblemSpec(test="biaxial", confining=-1.0), "confining"),
    (lambda: ProblemSpec(test="biaxial", axial_strain=0.7), "axial_strain"),
    (lambda: ProblemSpec(test="biaxial", element="quad5"), "element"),
    (lambda: ProblemSpec(test="biaxial", elements=(0, 3)), "elements"),
    (lambda: ProblemSpec(test="single-element", elements=(2, 2)), "elements"),
    (lambda: ProblemSpec(test="biaxial", quadrature=11), "quadrature"),
    (lambda: NewtonSpec(formulation="total-lagrangian"), "formulation"),
    (lambda: NewtonSpec(accept_correction=2.0), "accept_correction"),
    (lambda: NewtonSpec(stall_window=1), "stall_window"),
    (lambda: NewtonSpec(tangent_update="freeze"), "tangent_update"),
    (lambda: NewtonSpec(stress_tol=-1.0), "stress_tol"),
    (lambda: OutputSpec(every=0), "every"),
    (lambda: MaterialSpec(name="dem", parameters={"tangent": "secant"}), "tangent"),
    (lambda: MaterialSpec(name="dem", parameters={"E": 1e6}), "E"),
    (lambda: MaterialSpec(name="dem", parameters={"poisson": 0.3}), "poisson"),
    (lambda: MaterialSpec(name="granite"), "material"),
    (lambda: RunSpec(problem=ProblemSpec(test="biaxial"), material=MaterialSpec(name="dem"),
                     backend="threads"), "backend"),
    (lambda: RunSpec(problem=ProblemSpec(test="single-element"),
                     material=MaterialSpec(name="linear-elastic"), backend="mpi"), "backend"),
])
def test_a_value_that_cannot_run_names_its_field(build, name):
    with pytest.raises(SpecError) as caught:
        build()
    assert caught.value.field == name and str(caught.value).startswith(name)


def test_defaults_are_the_tests_own():
    element, specimen = ProblemSpec(test="single-element"), ProblemSpec(test="biaxial")
    assert (element.width, element.height) == (1.0, 1.0)
    assert (specimen.width, specimen.height) == (0.05, 0.10)
    assert specimen.mesh("cpu") == ((5, 10), 64) and specimen.mesh("cuda:0") == ((10, 15), 400)
    noisy = NewtonSpec().settings(noisy=True)
    assert noisy.stall_rtol == 2 * noisy.rtol and noisy.accept_correction == 1e-2
    assert NewtonSpec().settings(noisy=False).stall_rtol == 0.0
    assert NewtonSpec().stress_tolerance(True, 1e5) == pytest.approx(500.0)


# -- forms -----------------------------------------------------------------------------------
_specs = st.builds(
    lambda test, steps, strain, rtol, track, particles, tangent, out, elements: RunSpec(
        problem=ProblemSpec(test=test, steps=steps, axial_strain=strain,
                            elements=elements if test == "biaxial" else None),
        material=MaterialSpec(name="dem", parameters={"particles": particles,
                                                      "tangent": tangent}),
        newton=NewtonSpec(rtol=rtol),
        output=OutputSpec(out=out, track=track, map_strain=(0.01, strain))),
    st.sampled_from(["single-element", "biaxial"]), st.integers(1, 500),
    st.floats(1e-4, 0.5), st.floats(1e-6, 0.5), st.none() | st.just(("all",)),
    st.none() | st.integers(16, 900),
    st.sampled_from(["objective", "kruyt-rothenburg", "condensed"]),
    st.none() | st.just(Path("out/run")),
    st.none() | st.tuples(st.integers(1, 20), st.integers(1, 20)))


@settings(max_examples=40, deadline=None)
@given(_specs)
def test_json_toml_and_flat_forms_are_lossless(spec):
    assert from_dict(json.loads(json.dumps(to_dict(spec)))) == spec
    assert from_dict(tomllib.loads(to_toml(spec))) == spec
    assert from_flat(to_flat(spec)) == spec


def test_saved_spec_reads_back(tmp_path):
    spec = _elastic(steps=4)
    for name in ("spec.json", "spec.toml"):
        save(spec, tmp_path / name)
        assert load(tmp_path / name) == spec


def test_an_unknown_field_is_named():
    with pytest.raises(SpecError, match="stepz"):
        from_flat({"material": "linear-elastic", "test": "single-element", "stepz": 3})
    with pytest.raises(SpecError, match="solver"):
        from_dict({"problem": {"test": "biaxial"}, "material": {"name": "dem"},
                   "solver": {}})


# -- the library's run() is the command's ----------------------------------------------------
def test_library_run_gives_the_command_s_tables(tmp_path, capsys):
    spec = _elastic(steps=3, axial_strain=0.01)
    spec = spec.replace(output=OutputSpec(out=tmp_path / "library"))
    outcome = run(spec)
    assert outcome.result.error is None and len(outcome.result.steps) == 4
    code = main(["single-element", "--material", "linear-elastic", "--young", "50e6", "--steps",
                 "3", "--axial-strain", "0.01", "--out", str(tmp_path / "cli"),
                 "--no-progress"])
    assert code == 0
    for table in ("steps.csv", "points.csv"):
        a, b = (run_table(tmp_path / d, table).drop(columns=["wall_time"], errors="ignore")
                for d in ("library", "cli"))
        pd.testing.assert_frame_equal(a, b)
    summary = json.loads((tmp_path / "library" / "summary.json").read_text())
    assert summary["steps_completed"] == 3 and summary["out"] == str(tmp_path / "library")


def test_resume_compares_the_saved_spec_field_by_field(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["single-element", "--material", "linear-elastic", "--steps", "3",
            "--axial-strain", "0.01", "--no-progress"]
    assert main([*argv, "--out", str(out)]) == 0
    saved = json.loads((out / "checkpoint" / "options.json").read_text())
    assert from_dict(saved["spec"]).problem.steps == 3
    capsys.readouterr()
    assert main([*argv[:-1], "--young", "70e6", "--resume", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--young 70000000.0 (the run had 60000000.0)" in err
    # Newton's options are compared as the run resolved them (its record keeps them)
    assert main([*argv, "--relaxation", "aitken", "--resume", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--relaxation 'aitken' (the run had 'none')" in err
    assert main([*argv, "--resume", str(out)]) == 0
    # an option left to the material's default is named as such, not as None
    assert main([*argv, "--quadrature", "3", "--resume", str(out)]) == 2
    assert "(the run did not give it)" in capsys.readouterr().err


def test_a_default_changed_since_the_run_started_is_refused_by_name(tmp_path, capsys):
    """A run left an option to the commands' default, which a later version changed: its
    resume is refused (it would mix two settings in one run), naming the option; given
    the run's value explicitly, it resumes."""
    out = tmp_path / "run"
    argv = ["single-element", "--material", "linear-elastic", "--steps", "3",
            "--axial-strain", "0.01", "--no-progress"]
    assert main([*argv, "--out", str(out)]) == 0
    options = out / "checkpoint" / "options.json"
    record = json.loads(options.read_text())
    assert record["newton"]["relaxation"] == "none" and record["spec"]["newton"][
        "relaxation"] is None
    record["newton"]["relaxation"] = "aitken"  # what an older version's default made of it
    from granular_material.runs import RunCheckpoint

    (out / "checkpoint" / "state.npz").unlink()  # as if killed before it saved a step
    RunCheckpoint(out / "checkpoint").write_options(record)
    capsys.readouterr()
    assert main([*argv, "--resume", str(out)]) == 2
    assert "--relaxation 'none' by default (the run had 'aitken')" in capsys.readouterr().err
    assert main([*argv, "--relaxation", "aitken", "--resume", str(out)]) == 0


def test_a_checkpoint_of_the_options_era_resumes(tmp_path, capsys):
    """A checkpoint whose record holds the command's options (before specs) is compared
    through the spec they make."""
    out = tmp_path / "run"
    # --rtol given: the era's default (0.01) is no longer a smooth material's (1e-4)
    argv = ["single-element", "--material", "linear-elastic", "--steps", "3",
            "--axial-strain", "0.01", "--convergence", "displacement", "--rtol", "0.01",
            "--no-progress"]
    assert main([*argv, "--out", str(out)]) == 0
    options = out / "checkpoint" / "options.json"
    old = {"command": "single-element", "material": "linear-elastic", "E": 60e6, "nu": 0.3,
           "steps": 3, "axial_strain": 0.01, "confining": 100e3, "rtol": 1e-2,
           "convergence": "displacement", "formulation": "updated-lagrangian",
           "postprocess": ["pore-fractal"], "track": None, "preset": None, "json": False,
           "accept_correction": None, "stall_rtol": None, "stress_tol": None}
    from granular_material.runs import RunCheckpoint

    def started_with(record: dict) -> None:  # a run killed before it saved a step
        (out / "checkpoint" / "state.npz").unlink(missing_ok=True)
        RunCheckpoint(out / "checkpoint").write_options(record)

    started_with({**old, "steps": 4})
    assert main([*argv, "--resume", str(out)]) == 2
    assert "--steps 3 (the run had 4)" in capsys.readouterr().err
    started_with(old)
    assert main([*argv, "--resume", str(out)]) == 0
    assert "holds no saved step yet" in capsys.readouterr().err
    assert "spec" in json.loads(options.read_text())  # the fresh start records its spec


# -- scenes: run --check refuses what run refuses --------------------------------------------
_BAD_SCENES = {
    "contact-young-with-linear-elastic": 'material = "linear-elastic"\ncontact_young = 6e8\n',
    "reuse-with-displacement-test": "reuse_tol = 1e-4\n",
    "too-few-discs": "particles = 5\n",
    "track-missing-point": "track = [\"7\"]\n",
    "kn-with-an-rve-file": 'rve = "rve64.npz"\nkn = 1e6\n',
    "preset-with-linear-elastic": 'material = "linear-elastic"\npreset = "quick"\n',
}


@pytest.mark.parametrize("name", sorted(_BAD_SCENES))
def test_check_and_run_refuse_the_same_bad_scene(name, tmp_path, capsys):
    shutil.copy(EXAMPLES / "rve64.npz", tmp_path / "rve64.npz")
    scene = tmp_path / f"{name}.toml"
    scene.write_text('test = "single-element"\nsteps = 2\naxial_strain = 0.002\n'
                     'device = "cpu"\n' + _BAD_SCENES[name])
    assert main(["run", str(scene), "--check"]) == 2
    checked = capsys.readouterr().err
    assert main(["run", str(scene), "--out", str(tmp_path / "run")]) == 2
    ran = capsys.readouterr().err
    assert checked.split("error: ", 1)[1] == ran.split("error: ", 1)[1]
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("scene", sorted(
    p.name for p in EXAMPLES.glob("*.toml")
    if 'test = "boundary-value"' not in p.read_text()))  # those: tests/test_bvp_run.py
def test_every_example_scene_passes_check(scene, capsys):
    assert main(["run", str(EXAMPLES / scene), "--check"]) == 0
    assert capsys.readouterr().out.startswith("granular-material ")


# -- a spec file is a scene; a spec is a command line ----------------------------------------
def test_a_spec_s_command_line_makes_the_same_spec():
    import shlex

    from granular_material.cli import build_parser
    from granular_material.cli.fem import command_line, spec_from_args

    spec = from_flat({"test": "biaxial", "material": "dem", "elements": (3, 6), "steps": 7,
                      "element": "quad8", "rtol": 0.02, "tangent": "condensed",
                      "track": ("all",), "map_strain": (0.01, 0.03), "kn": 2e6,
                      "device": "cpu", "progress": False, "out": Path("somewhere"),
                      "points_csv": True, "figures": False})
    words = shlex.split(command_line(spec))[1:]
    assert "--no-figures" in words and "--points-csv" in words
    assert spec_from_args(build_parser().parse_args([*words, "--no-progress"])) == spec
    shown = dataclasses.replace(spec, output=dataclasses.replace(spec.output, progress=True))
    words = shlex.split(command_line(shown))[1:]
    assert "--progress" in words and "--no-progress" not in words
    assert spec_from_args(build_parser().parse_args(words)) == shown
    element = _elastic(steps=2)
    words = shlex.split(command_line(element))[1:]
    assert spec_from_args(build_parser().parse_args([*words, "--no-progress"])) == element


def test_a_saved_spec_runs_as_a_scene(tmp_path, capsys):
    spec = _elastic(steps=2, axial_strain=0.01)
    save(spec, tmp_path / "spec.toml")
    assert main(["run", str(tmp_path / "spec.toml"), "--check"]) == 0
    assert capsys.readouterr().out.startswith("granular-material single-element --material "
                                              "linear-elastic")
    assert main(["run", str(tmp_path / "spec.toml"), "--out", str(tmp_path / "run")]) == 0
    steps = pd.read_csv(tmp_path / "run" / "steps.csv")
    assert len(steps) == 3
    (tmp_path / "bad.toml").write_text(
        to_toml(spec).replace("steps = 2", "steps = 0"))
    assert main(["run", str(tmp_path / "bad.toml"), "--check"]) == 2
    assert "bad.toml, line" in capsys.readouterr().err


def test_isotropic_start_is_a_spec_field_and_a_flag():
    from granular_material.cli import build_parser
    from granular_material.cli.fem import spec_from_args

    args = build_parser().parse_args(["single-element", "--isotropic", "--particles", "32",
                                      "--steps", "1", "--axial-strain", "0.001",
                                      "--device", "cpu", "--no-progress"])
    spec = spec_from_args(args)
    assert spec.material.parameters.isotropic
    shear = {}
    for isotropic in (False, True):
        element = spec.replace(material=MaterialSpec(
            name="dem", parameters={"particles": 32, "isotropic": isotropic}))
        first = run(element).result.steps.iloc[0]
        shear[isotropic] = abs(first["sxy"]) / element.problem.confining
    assert shear[True] < 0.01 < shear[False]
