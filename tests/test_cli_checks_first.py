"""Checks before work (issue 24, parts 4-6): figure formats, an output named twice, meshes
too small for their measures, Newton settings, radii too wide for the discs, and requests
whose memory or step count no machine (or not this one) can hold are refused with exit 2
before anything is computed or written, the estimate in the message."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

import granular_material.checks as checks
import granular_material.cli.options as options
from granular_material.cli import main
from granular_material.dem import save_rve
from granular_material.procedures import prepare_packing


@pytest.fixture(scope="module")
def rve16(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rve") / "rve16.npz"
    save_rve(path, prepare_packing(n_disc=16, seed=1, pressure=100e3, device="cpu").to_data())
    return path


@pytest.fixture(autouse=True)
def no_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """Packing, driving, the biaxial test and the fractal analysis fail the test: every
    refusal here must come before the work."""
    import granular_material_pore_fractal.cli as fractal

    import granular_material.procedures as procedures
    import granular_material.procedures.driven_path as driven_path
    import granular_material.procedures.packing as packing

    def forbidden(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("the refusal came after work had started")

    for module, name in ((packing, "random_gas"), (packing, "consolidate"),
                         (procedures, "drive_grad_u"), (driven_path, "drive_grad_u"),
                         (procedures, "biaxial_test"),
                         (fractal, "analyse_rve")):
        monkeypatch.setattr(module, name, forbidden)


def _refused(capsys, *argv: str, within: float = 20.0) -> str:
    """Run ``argv``; it must exit 2 within ``within`` seconds (imports on a busy machine
    included) without a traceback; stderr."""
    started = time.monotonic()
    code = main([*argv, *([] if argv[0] == "fractal" else ["--device", "cpu",
                                                           "--no-progress"])])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    assert time.monotonic() - started < within, err
    return err


def test_a_figure_format_matplotlib_cannot_write_is_refused_first(rve16, tmp_path, capsys):
    csv = tmp_path / "c.csv"
    err = _refused(capsys, "biaxial-dem", str(rve16), "--axial-strain", "0.002", "--out",
                   str(csv), "--plot", str(tmp_path / "p.xyz"))
    assert "not .xyz" in err and ".png" in err
    err = _refused(capsys, "fractal", str(rve16), "--plot", str(tmp_path / "f.xyz"))
    assert "not .xyz" in err
    assert list(tmp_path.iterdir()) == []


def test_out_and_plot_naming_one_file_are_refused(rve16, tmp_path, capsys):
    err = _refused(capsys, "biaxial-dem", str(rve16), "--axial-strain", "0.002", "--out",
                   str(tmp_path / "same.png"), "--plot", str(tmp_path / "." / "same.png"))
    assert "name the same file" in err and list(tmp_path.iterdir()) == []


def test_a_biaxial_mesh_without_four_points_is_refused_first(rve16, tmp_path, capsys):
    out = tmp_path / "run"
    err = _refused(capsys, "biaxial", "--element", "tri3", "--elements", "1", "1",
                   "--platens", "rough", "--rve", str(rve16), "--steps", "2", "--out", str(out))
    assert "2 Gauss points" in err and "at least 4" in err and not out.exists()


def test_newton_settings_are_refused_before_the_rves_are_made(tmp_path, capsys):
    out = tmp_path / "run"
    err = _refused(capsys, "biaxial", "--secant-min-change", "0", "--elements", "2", "2",
                   "--particles", "64", "--out", str(out))
    assert "--secant-min-change must be a finite number > 0" in err
    assert not out.exists()


def test_radii_too_wide_for_the_discs_drawn_are_refused_first(tmp_path, capsys):
    # 18 discs of 0.1-7 mm pass the mean-radius limit (18), but seed 2 draws large ones
    wide = ["--radius-min", "0.0001", "--radius-max", "0.007", "--particles", "18",
            "--seed", "2"]
    err = _refused(capsys, "prepare", *wide, "--out", str(tmp_path / "r.npz"))
    assert "too few for seed 2" in err
    out = tmp_path / "run"
    err = _refused(capsys, "single-element", *wide, "--out", str(out))
    assert "too few for seed 2" in err and not out.exists()


@pytest.mark.parametrize(("argv", "says"), [
    (["prepare", "--batch", "100000000", "--out", "{out}.npz"], "81.9 TB of memory"),
    (["biaxial", "--elements", "100000", "100000", "--out", "{out}"], "7.02 PB of memory"),
    (["single-element", "--particles", "100000000000", "--out", "{out}"], "of memory"),
    (["fractal", "{rve}", "--pixel", "1e-9"], "39973376 x 39973376 pixels"),
    (["fractal", "{rve}", "--q-step", "1e-12"], "2e+13 moment orders"),
    (["dem-drive", "{rve}", "--grad-u", "0,0.001,0,0", "--increments", "10000000", "--out",
      "{out}.csv"], "at least 20000000 DEM steps"),
    (["dem-drive", "{rve}", "--grad-u", "0,0.001,0,0", "--increments", "600000", "--out",
      "{out}.csv"], "more than --max-dem-steps 1000000"),
])
def test_requests_no_machine_can_do_are_refused_at_once(argv, says, rve16, tmp_path,
                                                        capsys):
    err = _refused(capsys, *[a.format(rve=rve16, out=tmp_path / "out") for a in argv])
    assert says in err
    assert list(tmp_path.iterdir()) == []


def test_memory_beyond_what_is_available_now_is_refused(tmp_path, capsys, monkeypatch):
    options.check_memory(1e6, "a small request")  # this machine has a megabyte free
    monkeypatch.setattr(checks, "available_memory", lambda: 10**6)
    err = _refused(capsys, "prepare", "--batch", "10", "--particles", "400", "--out",
                   str(tmp_path / "r.npz"))
    assert "8.19 MB of memory" in err and "1 MB available now" in err
    monkeypatch.setattr(checks, "available_memory", lambda: None)
    options.check_memory(1e12, "a request")  # unknown availability: only the hard limit
    with pytest.raises(options.UsageError, match=r"more than the 1\.1 TB"):
        options.check_memory(2e12, "a request")
