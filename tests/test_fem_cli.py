"""The FEM commands and the scikit-fem example, run as tests."""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pandas as pd
import pytest

from granular_material.cli import main
from granular_material.results import read_points

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "skfem_material_swap.py"


def _example():
    spec = importlib.util.spec_from_file_location("skfem_material_swap", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_single_element_finite_strain_linear_elastic(capsys):
    """The default (updated-Lagrangian) formulation: σxx held at −p on the current sides;
    each step strains the element by its platen displacement over the current height, so
    σyy = −p − E/(1−ν²) Σ_k h/(H − k·h) for the hypoelastic linear law."""
    code = main(["single-element", "--material", "linear-elastic", "--young", "50e6", "--poisson",
                 "0.25", "--axial-strain", "0.01", "--steps", "4", "--confining", "100e3",
                 "--json", "--no-progress"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    h = 0.0025
    strain = sum(h / (1.0 - k * h) for k in range(4))
    # within the Newton tolerance (rtol 0.005 of the step's residual)
    assert out["syy"] == pytest.approx(-100e3 - 50e6 / (1 - 0.25**2) * strain, rel=1e-4)
    assert out["sxx"] == pytest.approx(-100e3, rel=1e-4)
    assert out["syy"] != pytest.approx(-100e3 - 50e6 / (1 - 0.25**2) * 0.01, rel=1e-4)


def test_single_element_linear_elastic_json(tmp_path, capsys):
    code = main(["single-element", "--material", "linear-elastic", "--young", "50e6", "--poisson",
                 "0.25", "--axial-strain", "0.01", "--steps", "4", "--confining", "100e3",
                 "--formulation", "small-strain",
                 "--out", str(tmp_path), "--json", "--no-progress"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    # plane strain, σxx held: σyy = −p − E/(1−ν²)·ε_a (tension positive)
    assert out["syy"] == pytest.approx(-100e3 - 50e6 / (1 - 0.25**2) * 0.01, rel=1e-10)
    assert out["sxx"] == pytest.approx(-100e3, rel=1e-10)
    # the residual displacement test (the default) accepts the exact tangent predictor
    # (Guo & Zhao's displacement test would evaluate once more after a zero correction)
    assert out["newton_iterations_mean"] == 1.0
    assert out["peak_stress_ratio"] == pytest.approx(-out["syy"] / 100e3, rel=1e-10)
    steps = pd.read_csv(tmp_path / "steps.csv")
    points = read_points(tmp_path)
    assert len(steps) == 5 and len(points) == 5 * 4
    for name in ("stress_strain.png", "maps.png", "fields.xdmf"):
        assert (tmp_path / name).stat().st_size > 0
    with meshio.xdmf.TimeSeriesReader(str(tmp_path / "fields.xdmf")) as reader:
        _, cells = reader.read_points_cells()
        assert reader.num_steps == 5 and cells[0].data.shape == (1, 4)


def test_points_csv_is_written_on_request_as_pandas_writes_the_table(tmp_path, capsys):
    """points.npy always; points.csv with --points-csv, the table's text as pandas writes it
    (as every run wrote it before points.npy); a run without it leaves no earlier one."""
    options = ["single-element", "--material", "mohr-coulomb", "--steps", "3",
               "--axial-strain", "0.01", "--no-progress", "--out", str(tmp_path)]
    assert main([*options, "--points-csv"]) == 0
    points = read_points(tmp_path)
    assert len(points) == 4 * 4 and (tmp_path / "points.npy").is_file()
    pd.testing.assert_frame_equal(pd.DataFrame(np.load(tmp_path / "points.npy")), points)
    assert (tmp_path / "points.csv").read_text() == points.to_csv(index=False)
    assert main(options) == 0
    assert not (tmp_path / "points.csv").exists()
    pd.testing.assert_frame_equal(read_points(tmp_path), points, check_exact=True)


def test_no_figures_writes_the_same_tables_without_figures(tmp_path, capsys):
    """--no-figures: the same tables and summary numbers, no figure (an earlier run's in the
    folder removed), and matplotlib never imported (a fresh process)."""
    options = ["single-element", "--material", "mohr-coulomb", "--steps", "3",
               "--axial-strain", "0.01", "--no-progress", "--map-strain", "0.005", "0.01"]
    assert main([*options, "--out", str(tmp_path / "drawn")]) == 0
    drawn = sorted(p.name for p in (tmp_path / "drawn").glob("*.png"))
    assert drawn == ["maps_0.5pct.png", "maps_1.0pct.png", "stress_strain.png"]
    folder = tmp_path / "plain"
    shutil.copytree(tmp_path / "drawn", folder)  # a run's figures there before
    code = ("import sys\nfrom granular_material.cli import main\n"
            f"code = main({[*options, '--out', str(folder), '--no-figures']!r})\n"
            "assert code == 0, code\nassert 'matplotlib' not in sys.modules\n")
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)
    assert not list(folder.glob("*.png"))
    for name in ("steps.csv", "fields.xdmf"):
        assert (folder / name).is_file()
    pd.testing.assert_frame_equal(read_points(folder), read_points(tmp_path / "drawn"))
    steps = [pd.read_csv(f / "steps.csv").drop(columns="wall_time")
             for f in (folder, tmp_path / "drawn")]
    pd.testing.assert_frame_equal(*steps)


def test_bad_input_is_a_value_error(capsys):
    assert main(["single-element", "--material", "linear-elastic", "--steps", "0",
                 "--no-progress"]) == 2
    assert "--steps" in capsys.readouterr().err
    assert main(["single-element", "--material", "linear-elastic", "--poisson", "0.7",
                 "--no-progress"]) == 2


def test_unreached_target_void_ratio_stops_the_run(tmp_path, capsys):
    """RVEs prepared with --target-void-ratio below what frictionless compaction reaches at
    --confining (24 discs: about 0.17 at 100 kPa) stop the run with code 1 naming it."""
    code = main(["single-element", "--particles", "24", "--target-void-ratio", "0.05",
                 "--steps", "1", "--device", "cpu", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 1 and "target void ratio 0.05 not reached" in err and "seed 1: 0.1" in err


def test_biaxial_command_reduced_scale(tmp_path, capsys):
    code = main(["biaxial", "--elements", "1", "2", "--particles", "40", "--axial-strain",
                 "0.004", "--steps", "2", "--device", "cpu", "--map-strain", "0.002", "0.004",
                 "--out", str(tmp_path), "--json", "--no-progress"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0, out["error"]
    assert out["gauss_points"] == 8 and out["steps_completed"] == 2 and out["dem_steps"] > 0
    points = read_points(tmp_path)
    assert points["void_ratio"].notna().all() and points["point"].max() == 7
    # the tables written step by step match the final ones; band measures of the last step
    assert len(pd.read_csv(tmp_path / "steps.csv")) == 3 and len(points) == 3 * 8
    assert [b["step"] for b in out["shear_bands"]] == [1, 2]
    band = out["shear_band_final"]
    assert band == out["shear_bands"][1] and -90 < band["inclination_deg"] <= 90
    assert band["localization"] >= 1 and 45 <= out["mohr_coulomb_inclination_deg"] < 90
    assert (tmp_path / "maps_0.2pct.png").exists() and (tmp_path / "maps_0.4pct.png").exists()


def test_biaxial_command_with_secant_tangents(tmp_path, capsys):
    code = main(["biaxial", "--elements", "1", "2", "--particles", "40", "--axial-strain",
                 "0.004", "--steps", "2", "--device", "cpu", "--tangent-update", "secant",
                 "--relaxation", "none", "--json", "--no-progress"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0, out["error"]
    assert out["steps_completed"] == 2 and out["peak_stress_ratio"] > 1
    assert main(["biaxial", "--tangent-update", "secant", "--secant-min-change", "0",
                 "--no-progress"]) == 2
    assert "--secant-min-change must be" in capsys.readouterr().err


def test_example_swaps_the_material_by_name():
    example = _example()
    elastic = example.main("linear-elastic", axial_strain=0.004, steps=2)
    # 2 × 2 elements, σxx held at −P: σyy = P + E/(1−ν²) ε_a, E = 60 MPa, ν = 0.3
    assert elastic[-1] == pytest.approx(100e3 + 60e6 / (1 - 0.09) * 0.004, rel=1e-6)
    example.PARAMETERS["dem"].update(particles=40)
    dem = example.main("dem", axial_strain=0.004, steps=2)
    assert 100e3 < dem[0] < dem[1] < elastic[-1]  # granular: softer than the elastic block
