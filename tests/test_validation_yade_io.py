"""Exporter/importer between our RVE file and YADE's scene file (no yade needed)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from granular_material_validation import yade_io, yade_runner

from granular_material.dem.rve.file import RVEData, RVEMeta, load_rve, save_rve


def grid_rve(seed: int = 0, law: str = "frictmat", shear: float = 0.02) -> RVEData:
    """A 6×6 grid of discs (radius 3–7 mm) in a slightly sheared 0.1 m cell, moving."""
    rng = np.random.default_rng(seed)
    cell = np.array([[0.1, shear * 0.1], [0.0, 0.1]])
    frac = (np.stack(np.meshgrid(np.arange(6), np.arange(6)), -1).reshape(-1, 2) + 0.5) / 6
    position = frac @ cell.T
    stiffness = ({"law": "frictmat", "young": 6e8, "kt_over_kn": 0.8} if law == "frictmat"
                 else {"law": "constant", "kn": 3e6, "kt": 2.4e6})
    return RVEData(
        radius=rng.uniform(3e-3, 7e-3, (1, 36)), position=position[None], cell=cell[None],
        velocity=rng.normal(0, 1e-3, (1, 36, 2)), angular_velocity=rng.normal(0, 0.1, (1, 36)),
        meta=RVEMeta(stiffness=stiffness, seed=seed, timestep=3.16e-5 if seed else None))


def assert_same_rve(a: RVEData, b: RVEData) -> None:
    for name in ("radius", "position", "cell", "velocity", "angular_velocity"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.meta == b.meta


@pytest.mark.parametrize("law", ["frictmat", "constant"])
def test_export_import_round_trip_is_exact(tmp_path: Path, law: str) -> None:
    data = grid_rve(seed=3, law=law)
    rve = tmp_path / "in.npz"
    save_rve(rve, data)
    scene_path = yade_io.export_rve(rve, tmp_path / "scene.json")
    scene = json.loads(scene_path.read_text())
    assert scene["format"] == yade_io.SCENE_FORMAT and len(scene["radius"]) == 36
    back = yade_io.import_scene(scene_path, tmp_path / "out.npz")
    assert_same_rve(data, back)
    assert_same_rve(data, load_rve(tmp_path / "out.npz"))


def test_missing_timestep_stays_missing() -> None:
    data = grid_rve(seed=0)
    assert data.meta.timestep is None
    assert yade_io.scene_to_rve(yade_io.rve_to_scene(data)).meta.timestep is None


def test_wrap_keeps_inside_discs_bit_for_bit_and_shifts_the_others() -> None:
    data = grid_rve()
    cell, pos = data.cell[0], data.position[0]
    moved = pos.copy()
    moved[0] += cell[:, 0] * 2 - cell[:, 1]  # two cells right, one cell down
    moved[5] -= cell[:, 1]
    wrapped = yade_io.wrap_into_cell(moved, cell)
    keep = np.ones(len(pos), bool)
    keep[[0, 5]] = False
    np.testing.assert_array_equal(wrapped[keep], pos[keep])
    np.testing.assert_allclose(wrapped[[0, 5]], pos[[0, 5]], atol=1e-15)
    frac = np.linalg.solve(cell, wrapped.T).T
    assert (frac >= 0).all() and (frac < 1).all()


def test_yade_total_velocity_becomes_the_fluctuation() -> None:
    """YADE stores v = v' + L·x; the importer returns v' (docs/design.md#kinematics)."""
    data = grid_rve(seed=2)
    scene = yade_io.rve_to_scene(data)
    lg = np.array([[0.3, 0.1], [-0.05, -0.2]])
    pos = np.asarray(scene["position"])
    scene["velocity"] = (np.asarray(scene["velocity"]) + pos @ lg.T).tolist()
    scene["velocity_gradient"] = lg.tolist()
    back = yade_io.scene_to_rve(scene)
    np.testing.assert_allclose(back.velocity, data.velocity, atol=1e-15)


def test_import_names_bad_format_and_shapes() -> None:
    scene = yade_io.rve_to_scene(grid_rve())
    with pytest.raises(ValueError, match="format"):
        yade_io.scene_to_rve({**scene, "format": "other"})
    with pytest.raises(ValueError, match="position"):
        yade_io.scene_to_rve({**scene, "position": scene["position"][:-1]})
    with pytest.raises(ValueError, match="index"):
        yade_io.rve_to_scene(grid_rve(), index=3)


def test_missing_yade_is_a_clear_error(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("GM_YADE", "no-such-yade-executable")
    with pytest.raises(yade_runner.YadeNotFoundError, match="apt-get install yade"):
        yade_runner.find_yade()
    assert yade_runner.yade_throughput(tmp_path / "any.npz") is None
