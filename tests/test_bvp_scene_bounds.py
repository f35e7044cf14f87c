"""A boundary-value scene meets a hostile user (issue 47): what it cannot hold is refused
naming its key before any work (the run's memory, the tables' disk, grid lines to align,
shards), and nothing it is given is silently moved or ignored."""

from __future__ import annotations

import copy
import dataclasses
import time
from collections import namedtuple

import pytest

from granular_material.runs.boundary_value import checks as bvp_checks
from granular_material.runs.boundary_value.runner import run_boundary_value
from granular_material.runs.boundary_value.spec import bvp_from_dict
from granular_material.runs.spec import SpecError

SCENE = {"test": "boundary-value", "steps": 2,
         "mesh": {"size": [1.0, 1.0], "elements": [2, 2]},
         "conditions": [{"type": "fixed", "boundary": "bottom"},
                        {"type": "displacement", "boundary": "top", "component": "y",
                         "value": -0.001}],
         "initial": {"state": "uniform", "pressure": 1e5},
         "material": {"name": "linear-elastic"}, "output": {"fields": False}}


def scene(tmp_path, **sections):
    data = copy.deepcopy(SCENE)
    data.update(sections)
    return bvp_from_dict(data, tmp_path)


@pytest.mark.parametrize("component", [[0], {"x": 1}, True, 2.5])
def test_a_component_of_another_type_is_named(tmp_path, component):
    with pytest.raises(SpecError, match=r"conditions.component must be x or y"):
        scene(tmp_path, conditions=[{"type": "roller", "boundary": "left",
                                     "component": component}])


def test_an_alignment_outside_the_mesh_is_refused_not_a_moved_edge(tmp_path):
    spec = scene(tmp_path, mesh={"size": [1.0, 1.0], "elements": [2, 2], "align_x": [5.0]})
    with pytest.raises(SpecError, match=r"mesh.align_x 5 m lies outside the mesh \(0 to 1 m\)"):
        run_boundary_value(spec, None)  # it moved the right edge to x = 5 m before


def test_more_alignments_than_grid_lines_are_refused(tmp_path):
    start = time.perf_counter()
    with pytest.raises(SpecError, match=r"mesh.align_x moves 100000 grid lines; 2 elements"):
        scene(tmp_path, mesh={"size": [1.0, 1.0], "elements": [2, 2],
                              "align_x": [0.5] * 10**5})
    assert time.perf_counter() - start < 5.0  # 10**6 took 35 s of work before


def test_shards_beyond_the_cap_are_refused(tmp_path):
    with pytest.raises(SpecError, match="shards must be an integer from 1 to 1024"):
        scene(tmp_path, output={"shards": 10**9})


def test_a_mesh_beyond_the_memory_is_refused_before_its_basis(tmp_path, monkeypatch):
    monkeypatch.setattr(bvp_checks, "available_memory", lambda: 10**9)
    spec = scene(tmp_path, mesh={"size": [1.0, 1.0], "elements": [300, 300]})
    start = time.perf_counter()
    with pytest.raises(SpecError, match=r"mesh 90000 quad4 elements \(360000 Gauss points\) "
                                        r"needs about 3.6 GB of memory"):
        run_boundary_value(spec, None)
    assert time.perf_counter() - start < 5.0


def test_tables_beyond_the_free_disk_are_refused_before_any_work(tmp_path, monkeypatch):
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(bvp_checks.shutil, "disk_usage", lambda path: usage(10**6, 0, 10**4))
    spec = scene(tmp_path, steps=1000)
    with pytest.raises(SpecError, match=r"steps 1000 load steps of 16 Gauss points write at "
                                        r"least 2.18 MB of points.npy; .* has 10 kB free"):
        run_boundary_value(spec, tmp_path / "run")
    with pytest.raises(SpecError, match=r"least 3.81 MB of points.npy and points.csv"):
        run_boundary_value(dataclasses.replace(spec, points_csv=True), tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_a_file_where_the_run_folder_goes_is_named(tmp_path):
    (tmp_path / "run").write_text("mine")
    with pytest.raises(SpecError, match=r"out .*run is a file, not a folder"):
        run_boundary_value(scene(tmp_path), tmp_path / "run")
    assert (tmp_path / "run").read_text() == "mine"


@pytest.mark.parametrize("out", [None, "run"])
def test_a_generated_mesh_beyond_the_memory_is_refused_before_it_is_made(tmp_path, out):
    spec = scene(tmp_path, mesh={"size": [1.0, 1.0], "elements": [3000, 3000]})
    start = time.perf_counter()
    with pytest.raises(SpecError, match=r"mesh 9000000 quad4 elements \(36000000 Gauss "
                                        r"points\) needs about 360 GB of memory"):
        run_boundary_value(spec, None if out is None else tmp_path / out)
    assert time.perf_counter() - start < 5.0  # making the mesh took more than 60 s before


def test_a_pressure_rises_to_its_end_and_only_a_pressure_has_one(tmp_path):
    ramp = {"type": "pressure", "boundary": "top", "value": 1e5, "end": 3e5}
    rollers = [{"type": "roller", "boundary": side, "component": "x"}
               for side in ("left", "right")]
    spec = scene(tmp_path, conditions=[{"type": "fixed", "boundary": "bottom"}, *rollers,
                                       ramp])
    assert spec.conditions[-1].end == 3e5
    outcome = run_boundary_value(spec)
    load = -outcome.steps["top_force_y"].to_numpy()  # the load on the body's top [N/m]
    assert load == pytest.approx([1e5, 2e5, 3e5], rel=1e-9)
    with pytest.raises(SpecError, match="only a pressure has an end") as refused:
        scene(tmp_path, conditions=[{"type": "displacement", "boundary": "top",
                                     "component": "y", "value": -1e-3, "end": -2e-3}])
    assert refused.value.field == "conditions.end"
    with pytest.raises(SpecError, match="compression positive") as refused:
        scene(tmp_path, conditions=[{"type": "fixed", "boundary": "bottom"},
                                    dict(ramp, end=-1.0)])
    assert refused.value.field == "conditions.end"


def test_gravity_increased_from_a_geostatic_start(tmp_path):
    # a column starts in equilibrium under its weight at step 0 (f0·γ) and carries
    # (q + f·γ·H)·W at the base as f rises to f1
    gamma, q, factor = 18e3, 10e3, [1.0, 1.5]
    rollers = [{"type": "roller", "boundary": side, "component": "x"}
               for side in ("left", "right")]
    spec = scene(tmp_path, mesh={"size": [0.2, 1.0], "elements": [1, 4]},
                 conditions=[{"type": "fixed", "boundary": "bottom"}, *rollers,
                             {"type": "pressure", "boundary": "top", "value": q}],
                 gravity={"unit_weight": gamma, "factor": factor},
                 initial={"state": "geostatic", "k0": 0.5, "surcharge": q},
                 newton={"formulation": "small-strain"})
    assert spec.gravity_factor == (1.0, 1.5)
    outcome = run_boundary_value(spec)
    assert outcome.summary["initial_residual"]["relative"] < 1e-12
    base = outcome.steps["bottom_force_y"].to_numpy()
    assert base == pytest.approx([(q + f * gamma) * 0.2 for f in (1.0, 1.25, 1.5)], rel=1e-9)
    for bad in ([1.0], [1.0, -0.5], "2"):
        with pytest.raises(SpecError, match=r"gravity\.factor"):
            scene(tmp_path, gravity={"unit_weight": gamma, "factor": bad})
