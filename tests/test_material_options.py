"""The FEM commands' continuum materials: --material mohr-coulomb with its options or a
material file, and the refusals of another material's options."""

from __future__ import annotations

import json
import math

import pytest

from granular_material.cli import main


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, dict]:
    code = main([*argv, "--json"])
    out = capsys.readouterr().out
    return code, json.loads(out[out.index("{"):]) if "{" in out else {}


def test_single_element_mohr_coulomb_peaks_at_the_closed_form(tmp_path, capsys):
    code, summary = _run(["single-element", "--material", "mohr-coulomb", "--friction-angle", "30",
                          "--axial-strain", "0.01", "--steps", "10", "--formulation",
                          "small-strain", "--out", str(tmp_path / "se")], capsys)
    assert code == 0
    assert summary["peak_stress_ratio"] == pytest.approx(3.0, rel=1e-6)


def test_material_file_sets_the_parameters_and_options_beside_it_win(tmp_path, capsys):
    path = tmp_path / "mc.toml"
    path.write_text("young = 40e6\npoisson = 0.25\nfriction_angle = 35.0\ndilation_angle = 5.0\n"
                    "cohesion = 0.0\n")
    code, summary = _run(["single-element", "--material", "mohr-coulomb", "--material-file",
                          str(path), "--axial-strain", "0.01", "--steps", "10",
                          "--formulation", "small-strain", "--out", str(tmp_path / "a")],
                         capsys)
    assert code == 0
    s = math.sin(math.radians(35.0))
    assert summary["peak_stress_ratio"] == pytest.approx((1 + s) / (1 - s), rel=1e-6)
    code, summary = _run(["single-element", "--material", "mohr-coulomb", "--material-file",
                          str(path), "--friction-angle", "30", "--axial-strain", "0.01",
                          "--steps", "10",
                          "--formulation", "small-strain", "--out", str(tmp_path / "b")],
                         capsys)
    assert summary["peak_stress_ratio"] == pytest.approx(3.0, rel=1e-6)


def test_biaxial_takes_the_mohr_coulomb_material(tmp_path, capsys):
    code, summary = _run(["biaxial", "--material", "mohr-coulomb", "--elements", "2", "4",
                          "--axial-strain", "0.01", "--steps", "5", "--out",
                          str(tmp_path / "bx")], capsys)
    assert code == 0 and summary["error"] is None
    assert summary["peak_stress_ratio"] == pytest.approx(3.0, rel=0.03)


@pytest.mark.parametrize("argv, message", [
    (["--material", "dem", "--dilation-angle", "3"],
     "--dilation-angle is no option of --material dem"),
    (["--material", "dem", "--phi", "30"], "--phi is no option of --material dem"),
    (["--material", "linear-elastic", "--cohesion", "5e3"], "--cohesion is no option"),
])
def test_another_materials_option_is_refused(tmp_path, capsys, argv, message):
    code = main(["single-element", *argv, "--out", str(tmp_path / "x")])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_a_material_file_with_an_unknown_key_is_refused(tmp_path, capsys):
    path = tmp_path / "mc.toml"
    path.write_text("friction_angel = 30.0\n")
    code = main(["single-element", "--material", "mohr-coulomb", "--material-file", str(path),
                 "--out", str(tmp_path / "x")])
    assert code == 2
    assert "'friction_angel' is no parameter of --material mohr-coulomb" in \
        capsys.readouterr().err


def test_single_element_tresca_and_its_refusal(tmp_path, capsys):
    """--friction-angle 0 is Tresca: σ1 − σ3 peaks at 2c (a ratio 1 + 2c/p); without a
    cohesion it is refused naming the cohesion."""
    code, summary = _run(["single-element", "--material", "mohr-coulomb", "--friction-angle",
                          "0", "--cohesion", "20e3", "--confining", "100e3", "--axial-strain",
                          "0.01", "--steps", "10", "--formulation", "small-strain", "--out",
                          str(tmp_path / "se")], capsys)
    assert code == 0
    assert summary["peak_stress_ratio"] == pytest.approx(1.4, rel=1e-6)
    code = main(["single-element", "--material", "mohr-coulomb", "--friction-angle", "0",
                 "--out", str(tmp_path / "x")])
    assert code == 2
    assert "cohesion" in capsys.readouterr().err and not (tmp_path / "x").exists()
