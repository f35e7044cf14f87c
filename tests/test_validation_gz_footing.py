"""Guo & Zhao's footing beside ours (validation/gz_footing.py): the mesh writer, their
footing force (projected traction) and the patches of their script; a smoke-size run of
both codes where Debian's yade and python3-escript are installed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import tomllib
from granular_material_validation import guo_zhao_runner, gz_footing
from granular_material_validation.gz_footing import (
    FootingMesh,
    footing_mesh,
    footing_nodal_reaction,
    footing_traction_force,
    lumped_nodal_stress,
    match_elements,
    read_gmsh22,
    write_gmsh22,
)

FOOTING_PY = Path("/usr/share/doc/yade/examples/FEMxDEM/footing.py")


def _areas(mesh: FootingMesh) -> np.ndarray:
    p = mesh.points[mesh.corners]
    a, b = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])


def test_mesh_covers_their_half_domain_with_a_node_at_the_footing_edge() -> None:
    mesh = footing_mesh()
    assert mesh.triangles.shape == (80, 6) and len(mesh.points) == 187
    areas = _areas(mesh)
    assert areas.min() > 0 and areas.sum() == pytest.approx(0.6 * 0.4)  # counter-clockwise
    p = mesh.points
    mids = p[mesh.triangles[:, 3:]]
    ends = 0.5 * (p[mesh.corners] + p[np.roll(mesh.corners, -1, axis=1)])
    assert np.abs(mids - ends).max() < 1e-15
    # the boundary's line3 edges run round the whole perimeter, midside in the middle
    e = p[mesh.lines]
    assert np.linalg.norm(e[:, 1] - e[:, 0], axis=1).sum() == pytest.approx(2 * (0.6 + 0.4))
    assert np.abs(e[:, 2] - 0.5 * (e[:, 0] + e[:, 1])).max() < 1e-15
    top = p[:, 1] == 0.0
    assert np.any(top & (np.abs(p[:, 0] - gz_footing.HALF_WIDTH) < 1e-15))
    assert p[:, 0].min() == 0.0 and p[:, 0].max() == 0.6 and p[:, 1].min() == -0.4
    with pytest.raises(ValueError, match="increasing"):
        footing_mesh((0.0, 0.2, 0.1), (0.0, 1.0))


def test_gmsh22_file_round_trips_and_loads_in_ours(tmp_path: Path) -> None:
    from granular_material.fem.boundary_value.meshes import read_mesh

    mesh = footing_mesh((0.0, 0.05, 0.2, 0.6), (-0.4, -0.1, 0.0))
    path = write_gmsh22(mesh, tmp_path / "m.msh")
    assert path.read_text().startswith("$MeshFormat\n2.2 0 8")
    back = read_gmsh22(path)
    assert np.array_equal(back.triangles, mesh.triangles)
    assert np.array_equal(back.lines, mesh.lines) and np.allclose(back.points, mesh.points)
    ours = read_mesh(path)
    assert ours.element == "tri6" and ours.mesh.t.shape == (3, 12)


def _interior_points(mesh: FootingMesh) -> np.ndarray:
    """scikit-fem's 3-point rule: barycentric (2/3, 1/6, 1/6) and its permutations."""
    lam = np.array([[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
    return np.einsum("qa,ead->eqd", lam, mesh.points[mesh.corners]).reshape(-1, 2)


def _midside_points(mesh: FootingMesh) -> np.ndarray:
    """escript's tri6 rule at integration order 2: the edge midpoints."""
    return mesh.points[mesh.triangles[:, 3:]].reshape(-1, 2)


def test_uniform_stress_gives_the_surcharge_force_on_the_base_for_either_rule() -> None:
    mesh = footing_mesh()
    sigma = np.broadcast_to(np.diag([-20e3, -20e3]), (3 * 80, 2, 2))
    for xy in (_interior_points(mesh), _midside_points(mesh)):
        nodal = lumped_nodal_stress(mesh.points, mesh.corners, xy, sigma)
        corner = np.unique(mesh.corners)
        assert np.allclose(nodal[corner], np.diag([-20e3, -20e3]))
        assert np.isnan(nodal[np.setdiff1d(np.arange(len(mesh.points)), corner)]).all()
        force, length = footing_traction_force(mesh, xy, sigma)
        assert length == pytest.approx(0.05)
        assert force == pytest.approx([0.0, -20e3 * 0.05])
        # the internal force on the base's nodes holds the surcharge's share on the edge
        # node (1/6 of the next top edge, 0.025 m): less that load, the surcharge × B
        inner = footing_nodal_reaction(mesh, xy, sigma)
        assert inner[1] == pytest.approx(-20e3 * (0.05 + 0.025 / 6))
        assert footing_nodal_reaction(mesh, xy, sigma, 20e3)[1] == pytest.approx(-1000.0)


def test_projection_lumps_by_area_and_integrates_the_base_by_hand() -> None:
    """One unit cell cut into A = (0,0),(1,0),(1,1) and B = (0,0),(1,1),(0,1); σyy = s in A
    only. Lumped: node (1,0) gets s, (0,0) and (1,1) s/2, (0,1) 0; the base x ≤ 1 on top runs
    from (0,1) to (1,1): F_y = 1 · (0 + s/2)/2 = s/4 with either rule, and the elements may
    come in any order."""
    mesh = footing_mesh((0.0, 1.0), (0.0, 1.0))
    s = -8.0
    sigma = np.zeros((6, 2, 2))
    sigma[:3, 1, 1] = s
    for xy in (_interior_points(mesh), _midside_points(mesh)):
        nodal = lumped_nodal_stress(mesh.points, mesh.corners, xy, sigma)
        syy = {tuple(mesh.points[a]): nodal[a, 1, 1] for a in np.unique(mesh.corners)}
        assert syy == pytest.approx({(0.0, 0.0): s / 2, (1.0, 0.0): s, (1.0, 1.0): s / 2,
                                     (0.0, 1.0): 0.0})
        force, _ = footing_traction_force(mesh, xy, sigma, half_width=1.0)
        assert force[1] == pytest.approx(s / 4)
        swapped = np.concatenate([xy[3:], xy[:3]])
        assert np.array_equal(match_elements(mesh, swapped), [1, 0])
        again, _ = footing_traction_force(mesh, swapped, np.concatenate([sigma[3:],
                                                                          sigma[:3]]), 1.0)
        assert again[1] == pytest.approx(s / 4)
    with pytest.raises(ValueError, match="outside triangle"):
        lumped_nodal_stress(mesh.points, mesh.corners, np.concatenate([xy[3:], xy[:3]]),
                            sigma)


def test_patches_refuse_a_changed_script() -> None:
    with pytest.raises(ValueError, match="occurs 0 times"):
        gz_footing.patch_footing("print('nothing')\n", mesh="m.msh", elements=1,
                                 processes=2, steps=1)


@pytest.mark.skipif(not FOOTING_PY.is_file(), reason="Debian yade's FEMxDEM example absent")
def test_shipped_footing_script_takes_every_patch() -> None:
    text = gz_footing.patch_footing(FOOTING_PY.read_text(), mesh="m.msh", elements=80,
                                    processes=2, steps=12)
    assert "ReadGmsh('m.msh'," in text and "numg = 3 * 80" in text
    assert "while t < 12:" in text and "verbose=True" in text and "fout.flush()" in text
    assert "from msFEM import" not in text and "file(" not in text
    compile(text, "footing.py", "exec")


def test_our_scene_holds_their_conditions(tmp_path: Path) -> None:
    from granular_material.runs.boundary_value.spec import bvp_from_dict

    write_gmsh22(footing_mesh(), tmp_path / "m.msh")
    text = gz_footing.scene_text(tmp_path / "m.msh", tmp_path / "rve.npz", steps=12)
    raw = tomllib.loads(text)
    spec = bvp_from_dict(raw, tmp_path)
    assert spec.steps == 12
    kinds = {c.boundary: c for c in spec.conditions}
    assert kinds["footing"].type == "rigid" and kinds["footing"].rough
    assert tuple(kinds["footing"].displacement) == pytest.approx((0.0, -12 * 0.25e-3))
    assert kinds["surface"].type == "pressure" and kinds["surface"].value == 20e3
    assert kinds["bottom"].type == "fixed" and kinds["left"].type == "roller"
    assert spec.initial.pressure == 20e3


@pytest.mark.yade
def test_both_codes_run_a_smoke_footing(tmp_path: Path) -> None:
    """3 × 2 cells (12 tri6, 36 Gauss points), one 64-disc RVE at 20 kPa from their
    procedure, two load steps of 0.25 mm in both codes; both bearing pressures rise above
    the 20 kPa at rest, their own force agrees with ours computed from their stresses."""
    if not guo_zhao_runner.guo_zhao_available():
        pytest.skip("needs Debian's yade and python3-escript (YADE's FEMxDEM)")
    from granular_material_validation.gz_footing_report import compare
    from granular_material_validation.yade_runner import yade_prepare_guo_zhao

    rve = tmp_path / "rve.npz"
    yade_prepare_guo_zhao(rve, particles=64, pressure=20e3, workdir=tmp_path / "prep")
    mesh = footing_mesh((0.0, 0.05, 0.2, 0.6), (-0.4, -0.1, 0.0))
    gz_footing.guo_zhao_footing(rve, tmp_path / "guo_zhao", mesh, steps=2, timeout=300)
    gz_footing.ours_footing(rve, tmp_path / "ours", mesh, steps=2, timeout=300)
    result = compare(tmp_path)
    table = result["table"]
    assert table["step"] == [0, 1, 2]
    for key in ("q_theirs_kpa", "q_ours_nodal_kpa", "q_ours_projected_kpa"):
        assert table[key][0] == pytest.approx(20.0, rel=0.01)
        assert table[key][2] > table[key][1] > 25.0
    # their bearing.dat (updated mesh) against our projection of their stresses (reference)
    assert table["q_theirs_reference_kpa"] == pytest.approx(table["q_theirs_kpa"], rel=0.02)
    assert result["cost"]["theirs"]["iterations_mean"] >= 1
    assert (tmp_path / "footing_mechanism.png").stat().st_size > 10_000
    assert json.loads((tmp_path / "comparison.json").read_text())["gauss_points"] == 36
