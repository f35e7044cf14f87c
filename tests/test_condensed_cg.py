"""The condensed tangent by the batched warp CG (granular_material.dem.condensed.cg), on
warp's CPU device: the scipy LU's result, its symmetries, per-RVE convergence, and a clear
error where CG does not converge."""

from __future__ import annotations

import math

import numpy as np
import pytest

from granular_material.dem import DEMBatch, RVEData, RVEMeta
from granular_material.dem.condensed.cg import (
    CGFallbackWarning,
    CGNotConvergedError,
    _raise_unless_converged,
    condensed_tangent_cg,
)
from granular_material.dem.condensed.tangent import condensed_tangent
from granular_material.procedures import drive_grad_u, prepare_packing

SPIN = np.array([[0.0, -1.0], [1.0, 0.0]])
SEEDS = (1, 2, 3)


@pytest.fixture(scope="module")
def packings() -> RVEData:
    """Three 80-disc packings at 100 kPa (seeds 1–3) and the same sheared 1 % (ε = ±0.5 %,
    contacts sliding): six RVEs of one batch."""
    parts = [prepare_packing(n_disc=80, seed=s, pressure=100e3, device="cpu") for s in SEEDS]
    prepared = RVEData.concatenate([b.to_data() for b in parts])
    batch = DEMBatch(prepared, device="cpu")
    drive_grad_u(batch, np.diag([0.005, -0.005]))
    return RVEData.concatenate([prepared, batch.to_data()])


@pytest.fixture(scope="module")
def both(packings: RVEData) -> tuple:
    """The scipy LU's and the CG's condensed tangents of ``packings``."""
    return condensed_tangent(packings), condensed_tangent_cg(packings, device="cpu")


def _relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """max|a − b| / max|b| per RVE."""
    axes = tuple(range(1, a.ndim))
    return np.abs(a - b).max(axis=axes) / np.abs(b).max(axis=axes)


def test_cg_equals_the_direct_solve(both: tuple) -> None:
    """Same C as scipy's LU to 1e-8 relative on every RVE (measured ~1e-11), the same
    network counts and, bit for bit, the same affine term."""
    direct, cg = both
    assert direct.n_sliding[3:].min() > 0  # sheared: the sliding rule is exercised
    assert (direct.n_left_out > 0).any()  # rattlers are left out somewhere
    assert _relative(cg.tangent, direct.tangent).max() < 1e-8
    np.testing.assert_array_equal(cg.affine, direct.affine)
    for name in ("n_contacts", "n_sliding", "n_left_out", "n_unknowns"):
        np.testing.assert_array_equal(getattr(cg, name), getattr(direct, name))
    assert (cg.residual <= 1e-10).all() and (cg.iterations > 0).all()


def test_cg_is_symmetric_and_objective(both: tuple) -> None:
    """Major and both minor symmetries, and a spin costs nothing: C:W = 0."""
    _, cg = both
    for c in cg.tangent:
        scale = np.abs(c).max()
        assert np.abs(c - c.transpose(2, 3, 0, 1)).max() < 1e-9 * scale
        assert np.abs(c - c.transpose(1, 0, 2, 3)).max() < 1e-9 * scale
        assert np.abs(c - c.transpose(0, 1, 3, 2)).max() < 1e-12 * scale
        assert np.abs(np.einsum("ijkl,kl->ij", c, SPIN)).max() < 1e-12 * scale


def test_each_rve_stops_at_its_own_tolerance(packings: RVEData, both: tuple) -> None:
    """RVEs needing different iteration counts: each stops at its own convergence. Solved
    alone, an RVE takes the iterations it took in the batch and gives the same C bit for
    bit (the others' further iterations do not touch it); a looser tolerance stops
    earlier, at that tolerance."""
    _, cg = both
    per_rve = cg.iterations.max(axis=1)
    assert len(set(per_rve.tolist())) > 1
    quick = int(np.argmin(per_rve))
    alone = condensed_tangent_cg(packings, rves=[quick])
    np.testing.assert_array_equal(alone.iterations[0], cg.iterations[quick])
    np.testing.assert_array_equal(alone.tangent[0], cg.tangent[quick])
    loose = condensed_tangent_cg(packings, rves=[quick, 4], tolerance=1e-4)
    assert (loose.residual <= 1e-4).all()
    assert (loose.iterations < cg.iterations[[quick, 4]]).all()


def test_not_converging_is_an_error_naming_the_rves(packings: RVEData) -> None:
    """Past the iteration cap: an error that names the RVEs, not a NaN or a wrong C."""
    with pytest.raises(CGNotConvergedError, match=r"within 5 iterations .*RVEs \[1, 2\]"):
        condensed_tangent_cg(packings, rves=[1, 2], max_iterations=5)
    told = condensed_tangent_cg(packings, rves=[1, 2], max_iterations=5,
                                raise_unconverged=False)
    assert not told.converged.any() and (told.residual.max(axis=1) > 1e-10).all()
    assert condensed_tangent_cg(packings, rves=[1, 2]).converged.all()
    with pytest.raises(ValueError, match="tolerance"):
        condensed_tangent_cg(packings, rves=[1], tolerance=0.0)


def test_the_error_quotes_the_cap_each_rve_ran_under() -> None:
    """RVEs from shards with different iteration caps: the error gives the caps of those
    that did not converge, not one cap for all."""
    index, residual = np.array([7, 8, 9]), np.full((3, 3), 1e-3)
    caps = np.array([1000, 1600, 2400])
    with pytest.raises(CGNotConvergedError, match=r"caps of \[1000, 2400\] iterations.*"
                                                  r"RVEs \[7, 9\]"):
        _raise_unless_converged(index, np.array([False, True, False]), residual, 1e-10, caps)
    with pytest.raises(CGNotConvergedError, match=r"within 1600 iterations .*RVEs \[8\]"):
        _raise_unless_converged(index, np.array([True, False, True]), residual, 1e-10, caps)


def _honeycomb_with_rattlers() -> RVEData:
    """Honeycomb of discs A (5 mm) and B (4 mm), each touching three of the other kind
    (gears: floppy counter-rotations), with a rattler in a hexagon's hole and a disc that
    touches a single lattice disc (as in test_condensed_tangent)."""
    r_a, r_b, overlap = 5e-3, 4e-3, 1e-3
    bond = (r_a + r_b) * (1.0 - overlap)
    w, h = math.sqrt(3.0) * bond, 3.0 * bond
    basis = np.array([[0.0, 0.0], [0.0, bond], [0.5 * w, 1.5 * bond], [0.5 * w, 2.5 * bond]])
    basis += np.array([0.25 * w, 0.1 * bond])
    shifts = np.array([(i * w, j * h) for i in range(2) for j in range(2)])
    position = (shifts[:, None, :] + basis[None]).reshape(-1, 2)
    radius = np.tile([r_a, r_b, r_a, r_b], 4)
    a0 = position[0]
    hole = a0 + np.array([0.5 * w, 0.5 * bond])
    dangler = a0 + (r_a + 3e-3 - 1e-5) * np.array([0.0, -1.0])
    radius = np.concatenate([radius, [1e-3, 3e-3]])
    position = np.concatenate([position, [hole, dangler]])
    n = len(radius)
    meta = RVEMeta(stiffness={"law": "constant", "kn": 3e6, "kt": 3e5}, friction_angle=0.5)
    return RVEData(radius=radius[None], position=position[None],
                   cell=np.diag([2 * w, 2 * h])[None], velocity=np.zeros((1, n, 2)),
                   angular_velocity=np.zeros((1, n)), meta=meta)


def test_lattice_mechanisms_rattlers_and_an_empty_rve() -> None:
    """The honeycomb's gear mode (regularised), its rattler and dangler (left out) give the
    direct solve's C; an RVE without contacts gives C = 0 without an error."""
    data = _honeycomb_with_rattlers()
    direct = condensed_tangent(data)
    cg = condensed_tangent_cg(data)
    assert cg.n_left_out[0] == 2
    assert _relative(cg.tangent, direct.tangent)[0] < 1e-8
    apart = RVEData(radius=np.full((1, 2), 1e-3), position=np.array([[[0.01, 0.01],
                                                                       [0.05, 0.05]]]),
                    cell=np.diag([0.1, 0.1])[None], velocity=np.zeros((1, 2, 2)),
                    angular_velocity=np.zeros((1, 2)), meta=data.meta)
    empty = condensed_tangent_cg(apart)
    assert empty.n_contacts[0] == 0 and np.all(empty.tangent == 0.0)


def test_the_dem_backend_takes_the_lu_where_the_cg_does_not_converge(
        packings: RVEData, monkeypatch) -> None:
    """``condense`` on "cuda…" (float32: the host-assembled CG): an RVE whose CG
    stops short of the tolerance takes scipy's LU's tangent, with a CGFallbackWarning that
    names it, instead of ending the run; the CG's other RVEs keep their own."""
    from dataclasses import dataclass

    from granular_material.dem.condensed import dispatch as condensation

    calls = []

    def short_cg(data: RVEData, rves: np.ndarray, device: str, sliding: str,
                 raise_unconverged: bool):
        calls.append((device, raise_unconverged))
        full = condensed_tangent_cg(data, rves=rves, sliding=sliding)
        capped = max(int(full.iterations[0].max()) + 1, 1)  # RVE 1 converges, 4 does not
        assert full.iterations[1].max() > capped
        return condensed_tangent_cg(data, rves=rves, device="cpu", sliding=sliding,
                                    max_iterations=capped, check_every=1,
                                    raise_unconverged=raise_unconverged)

    @dataclass
    class Fake:
        device: str
        dtype: str = "float32"  # a float64 CUDA batch assembles on its device

        def to_data(self) -> RVEData:
            return packings

    monkeypatch.setattr(condensation, "condensed_tangent_cg", short_cg)
    lu = condensed_tangent(packings, rves=[1, 4]).tangent
    with pytest.warns(CGFallbackWarning, match=r"1 of 2 RVEs \(\[4\]"):
        on_cuda = condensation.condense(Fake("cuda:0"), np.array([1, 4]), "free")
    assert calls == [("cuda:0", False)]
    assert _relative(on_cuda, lu).max() < 1e-8


def test_cost_benchmark_times_both_solvers(tmp_path) -> None:
    """benchmarks/condensed_tangent.py --cost-only --solver both at smoke size: both
    solvers timed, and the CG's tangent that of scipy's LU."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "condensed_tangent.py"
    spec = importlib.util.spec_from_file_location("condensed_tangent_bench_cg", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    cost = module.main(["--particles", "24", "--seeds", "1", "--cost-only", "--solver", "both",
                        "--out", str(tmp_path)]).iloc[0]
    assert cost["condensed_cg_call_s_per_rve"] > 0 and cost["condensed_direct_call_s_per_rve"] > 0
    assert cost["cg_vs_direct_max_rel"] < 1e-8 and cost["cg_iterations_max"] > 0
