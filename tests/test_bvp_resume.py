"""A boundary-value run stopped part-way resumes to the run that never stopped
(granular_material.runs.boundary_value.resume), and a fresh run into its folder is refused."""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd
import pytest
from test_bvp_run import FOOTING

from granular_material.cli import main
from granular_material.fem.solver.newton import NewtonSolver
from granular_material.results import read_points
from granular_material.runs.boundary_value.resume import scene_record
from granular_material.runs.boundary_value.runner import run_boundary_value
from granular_material.runs.boundary_value.spec import bvp_from_dict
from granular_material.runs.checkpoint import RunCheckpoint
from granular_material.runs.spec import SpecError

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10
    import tomli as tomllib

MOHR_COULOMB = ('[material]\nname = "mohr-coulomb"\n[material.parameters]\nyoung = 19e6\n'
                'poisson = 0.25\nfriction_angle = 35.0\ndilation_angle = 15.0\n'
                'critical_friction_angle = 25.0\nsoftening_strain = 0.05\n'
                '[newton]\nformulation = "small-strain"\n')
DEM = ('[material]\nname = "dem"\n[material.parameters]\nparticles = 16\nseed = 1\n'
       'tangent = "kruyt-rothenburg"\n[output]\ndevice = "cpu"\n')
#: columns that are times, not results
TIMES = ("wall_time",)


def _spec(material: str, steps: int, elements: str, settlement: float | None = None):
    settlement = -0.0005 * steps if settlement is None else settlement
    text = FOOTING.format(steps=steps, elements=elements, settlement=settlement,
                          material=material)
    return bvp_from_dict(tomllib.loads(text))


def _stop_at(monkeypatch, step: int) -> None:
    """Ctrl-C as load step ``step`` begins."""
    original = NewtonSolver.step

    def step_or_stop(self, target, k):
        if k == step:
            raise KeyboardInterrupt
        return original(self, target, k)

    monkeypatch.setattr(NewtonSolver, "step", step_or_stop)


def _tables(folder):
    steps = pd.read_csv(folder / "steps.csv").drop(columns=list(TIMES))
    return steps, read_points(folder)


@pytest.mark.parametrize(("material", "elements"), [(MOHR_COULOMB, "[6, 4]"),
                                                    (DEM, "[3, 2]")])
def test_a_stopped_run_resumes_to_the_run_that_never_stopped(tmp_path, monkeypatch,
                                                             material, elements):
    steps = 4
    whole = run_boundary_value(_spec(material, steps, elements), out=tmp_path / "whole")
    assert whole.error is None
    assert not (tmp_path / "whole" / "checkpoint").exists()  # finished: nothing to resume
    with monkeypatch.context() as m:
        _stop_at(m, 3)
        stopped = run_boundary_value(_spec(material, steps, elements), out=tmp_path / "run")
    assert "interrupted after load step 2" in stopped.error
    with pytest.raises(SpecError, match="`resume`"):  # a fresh run would throw it away
        run_boundary_value(_spec(material, steps, elements), out=tmp_path / "run")
    resumed = run_boundary_value(_spec(material, steps, elements), out=tmp_path / "run",
                                 resume=True)
    # the state is saved by elapsed time: after step 2, or earlier where saving it is slow
    assert resumed.error is None and 0 <= resumed.summary["resumed_from_step"] <= 2
    for a, b in zip(_tables(tmp_path / "whole"), _tables(tmp_path / "run"), strict=True):
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    np.testing.assert_array_equal(whole.u, resumed.u)
    assert (tmp_path / "run" / "fields.xdmf").read_text().count("<Grid ") == (
        (tmp_path / "whole" / "fields.xdmf").read_text().count("<Grid "))


def test_a_resume_with_another_scene_is_refused_naming_the_field(tmp_path, monkeypatch):
    with monkeypatch.context() as m:
        _stop_at(m, 2)
        run_boundary_value(_spec(MOHR_COULOMB, 3, "[4, 3]", -0.0015), out=tmp_path / "run")
    with pytest.raises(SpecError, match="steps") as refused:
        run_boundary_value(_spec(MOHR_COULOMB, 4, "[4, 3]", -0.0015), out=tmp_path / "run",
                           resume=True)
    assert refused.value.field == "steps"
    # a folder with no run to continue: the run starts there (as every command's --resume)
    fresh = run_boundary_value(_spec(MOHR_COULOMB, 3, "[4, 3]"), out=tmp_path / "other",
                               resume=True)
    assert fresh.error is None and fresh.summary["resumed_from_step"] is None


def test_a_checkpoint_written_before_a_field_was_added_still_resumes(tmp_path):
    # a checkpoint whose scene lacks fields added since (a pressure's end, the gravity
    # factor, at their default None) is the same scene; one whose steps differ is not
    spec = _spec(MOHR_COULOMB, 3, "[4, 3]", -0.0015)
    old = scene_record(spec)
    assert old.pop("gravity_factor") is None
    for condition in old["conditions"]:
        assert condition.pop("end") is None
    RunCheckpoint(tmp_path / "run" / "checkpoint").start({"scene": old})
    outcome = run_boundary_value(spec, out=tmp_path / "run", resume=True)
    assert list(outcome.steps["step"]) == [0, 1, 2, 3]
    RunCheckpoint(tmp_path / "other" / "checkpoint").start({"scene": dict(old, steps=4)})
    with pytest.raises(SpecError, match="steps"):
        run_boundary_value(spec, out=tmp_path / "other", resume=True)


def test_the_command_line_resumes_a_scene(tmp_path, monkeypatch, capsys):
    scene = tmp_path / "footing.toml"
    scene.write_text(FOOTING.format(steps=3, elements="[4, 3]", settlement=-0.0015,
                                    material=MOHR_COULOMB))
    out = tmp_path / "run"
    with monkeypatch.context() as m:
        _stop_at(m, 2)
        assert main(["run", str(scene), "--out", str(out)]) == 130  # Ctrl-C's code
    assert main(["run", str(scene), "--out", str(out)]) == 2
    assert "--resume" in capsys.readouterr().err
    assert main(["run", str(scene), "--out", str(out), "--resume"]) == 0
    assert list(pd.read_csv(out / "steps.csv")["step"]) == [0, 1, 2, 3]


def test_the_fields_carry_what_paraview_is_promised(tmp_path):
    """fields.xdmf: the displacement and, per element, the stress, strains, rotation, mean
    pressure, unconfined and failed points and the material's own fields."""
    import meshio

    run_boundary_value(_spec(MOHR_COULOMB, 2, "[4, 3]"), out=tmp_path / "run")
    with meshio.xdmf.TimeSeriesReader(str(tmp_path / "run" / "fields.xdmf")) as reader:
        reader.read_points_cells()
        _, point_data, cell_data = reader.read_data(reader.num_steps - 1)
    assert "displacement" in point_data
    assert {"sxx", "shear_strain", "rotation", "mean_pressure", "unconfined", "failed",
            "plastic_shear_strain", "friction_angle", "stress_zz"} <= set(cell_data)


def _without_surcharge(steps: int):
    """A DEM footing with nothing on the surface beside it: the soil there unloads and some
    points lose their confinement (their tangent floored by the initial one)."""
    surcharge = '[[conditions]]\ntype = "pressure"\nboundary = "surface"\nvalue = 20e3\n'
    text = FOOTING.format(steps=steps, elements="[3, 2]", settlement=-0.0005 * steps,
                          material=DEM)
    assert surcharge in text
    return bvp_from_dict(tomllib.loads(text.replace(surcharge, "")))


@pytest.mark.filterwarnings("ignore::granular_material.multiscale.UnconfinedWarning")
def test_a_footing_with_unconfined_points_resumes_to_the_run_that_never_stopped(
        tmp_path, monkeypatch):
    # the floor of an unconfined point's tangent is its initial tangent: a resume that took
    # the tangent of its own first evaluation as the floor (near zero at the points already
    # unconfined) went another way, and diverged on larger scenes (issue 61)
    steps = 3
    whole = run_boundary_value(_without_surcharge(steps), out=tmp_path / "whole")
    assert whole.error is None
    unconfined = whole.steps["unconfined_points"].to_numpy()
    assert unconfined[0] == 0 and (unconfined[1:] > 0).all()
    for stop in (1, 2):
        out = tmp_path / f"stopped-{stop}"
        with monkeypatch.context() as m:
            _stop_at(m, stop + 1)
            stopped = run_boundary_value(_without_surcharge(steps), out=out)
        assert f"interrupted after load step {stop}" in stopped.error
        resumed = run_boundary_value(_without_surcharge(steps), out=out, resume=True)
        # the state is saved by elapsed time: after the stop, or earlier where saving is slow
        assert resumed.error is None and 0 <= resumed.summary["resumed_from_step"] <= stop
        for a, b in zip(_tables(tmp_path / "whole"), _tables(out), strict=True):
            pd.testing.assert_frame_equal(a, b, check_exact=True)
        np.testing.assert_array_equal(whole.u, resumed.u)
