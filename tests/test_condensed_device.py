"""The condensed tangent assembled on the batch's own device
(granular_material.dem.condensed.device), run on warp's CPU device: scipy's LU result from
the engine's arrays, RVE by RVE and shard by shard, lattices with mechanisms and rattlers,
and which path the DEM material takes on CUDA."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest
from test_condensed_cg import _honeycomb_with_rattlers

from granular_material.dem import DEMBatch, RVEData
from granular_material.dem.condensed.cg import CGNotConvergedError, condensed_tangent_cg
from granular_material.dem.condensed.device import (
    condensed_tangent_of_batch,
    condensed_tangent_on_device,
)
from granular_material.dem.condensed.tangent import condensed_tangent
from granular_material.procedures import drive_grad_u, prepare_packing

COUNTERS = ("n_contacts", "n_sliding", "n_left_out", "n_unknowns")


def _relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """max|a − b| / max|b| per RVE."""
    axes = tuple(range(1, a.ndim))
    return np.abs(a - b).max(axis=axes) / np.abs(b).max(axis=axes)


@pytest.fixture(scope="module")
def sheared() -> DEMBatch:
    """Two 80-disc packings at 100 kPa (seeds 1, 2), twice each, the second copies sheared
    1 % (ε = ±0.5 %, contacts sliding), in two shards of two RVEs."""
    parts = [prepare_packing(n_disc=80, seed=s, pressure=100e3, device="cpu") for s in (1, 2)]
    prepared = RVEData.concatenate([b.to_data() for b in parts])
    batch = DEMBatch(prepared, device="cpu")
    drive_grad_u(batch, np.diag([0.005, -0.005]))
    return DEMBatch(RVEData.concatenate([prepared, batch.to_data()]), device="cpu", shards=2)


def test_device_assembly_gives_the_direct_solve(sheared: DEMBatch) -> None:
    """Same C as scipy's LU from the batch's file copy to 1e-8 relative (measured ~1e-11),
    the same affine term to rounding and the same network counts; every shard's RVEs."""
    assert len(sheared.shards) == 2
    direct = condensed_tangent(sheared.to_data())
    assert direct.n_sliding[2:].min() > 0 and (direct.n_left_out > 0).any()
    on_device = condensed_tangent_of_batch(sheared)
    assert _relative(on_device.tangent, direct.tangent).max() < 1e-8
    assert _relative(on_device.affine, direct.affine).max() < 1e-13
    for name in COUNTERS:
        np.testing.assert_array_equal(getattr(on_device, name), getattr(direct, name))
    assert (on_device.residual <= 1e-10).all()
    assert on_device.assembly_seconds > 0 and on_device.solve_seconds > 0


def test_the_frictmat_law_gives_the_direct_solve(sheared: DEMBatch) -> None:
    """YADE's FrictMat stiffness (kn from the radii, kt a share of it) on a sheared RVE."""
    data = sheared.to_data().select(3)
    law = {"law": "frictmat", "young": 3e8, "kt_over_kn": 0.8}
    batch = DEMBatch(replace(data, meta=replace(data.meta, stiffness=law)), device="cpu",
                     shards=1)
    direct = condensed_tangent(batch.to_data())
    on_device = condensed_tangent_of_batch(batch)
    assert _relative(on_device.tangent, direct.tangent)[0] < 1e-8
    assert _relative(on_device.tangent, condensed_tangent(data).tangent)[0] > 1e-3  # moved
    np.testing.assert_array_equal(on_device.n_sliding, direct.n_sliding)


def test_chosen_rves_come_back_in_their_order_bit_for_bit(sheared: DEMBatch) -> None:
    """RVEs 3 and 0 (two shards, asked for in that order): what the whole batch gave them,
    bit for bit (each RVE's systems are its own), and the host-assembled CG's C; none asked
    for, none given."""
    whole = condensed_tangent_of_batch(sheared)
    chosen = condensed_tangent_of_batch(sheared, rves=np.array([3, 0]))
    np.testing.assert_array_equal(chosen.tangent, whole.tangent[[3, 0]])
    np.testing.assert_array_equal(chosen.iterations, whole.iterations[[3, 0]])
    host = condensed_tangent_cg(sheared.to_data(), rves=[3, 0])
    assert _relative(chosen.tangent, host.tangent).max() < 1e-9
    nothing = condensed_tangent_of_batch(sheared, rves=np.zeros(0, dtype=int))
    assert nothing.tangent.shape == (0, 2, 2, 2, 2) and nothing.iterations.shape == (0, 3)


def test_an_unconverged_rve_is_named_or_flagged(sheared: DEMBatch) -> None:
    """Past the iteration cap: the error names the RVEs across shards, or, asked not to
    raise, ``converged`` says which (the backend then takes the LU for those)."""
    with pytest.raises(CGNotConvergedError, match=r"within 3 iterations .*RVEs \[1, 3\]"):
        condensed_tangent_of_batch(sheared, rves=np.array([1, 3]), max_iterations=3)
    told = condensed_tangent_of_batch(sheared, rves=np.array([3, 1]), max_iterations=3,
                                      raise_unconverged=False)
    assert told.converged.shape == (2,) and not told.converged.any()
    assert condensed_tangent_of_batch(sheared, rves=np.array([3, 1])).converged.all()


def test_lattice_mechanisms_rattlers_and_an_empty_rve(two_discs) -> None:
    """The honeycomb's gear mode (regularised), its rattler and dangler (left out) and an
    RVE whose two discs do not touch (C = 0, no error), from lists the engine built."""
    lattice = _honeycomb_with_rattlers()
    batch = DEMBatch(lattice, device="cpu", shards=1)
    direct = condensed_tangent(batch.to_data())
    on_device = condensed_tangent_of_batch(batch)
    assert on_device.n_left_out[0] == direct.n_left_out[0] == 2
    assert _relative(on_device.tangent, direct.tangent)[0] < 1e-8
    apart = two_discs((0.01, 0.01), (0.05, 0.05), radius=1e-3)
    empty = condensed_tangent_of_batch(DEMBatch(apart, device="cpu", shards=1))
    assert empty.n_contacts[0] == 0 and np.all(empty.tangent == 0.0)


def test_sticking_contacts_give_the_direct_solve(sheared: DEMBatch) -> None:
    """``sliding="stick"`` on the device and in the host-assembled CG: scipy's LU result
    with every touching contact keeping kt, the same counts (sliding still counted); the
    Coulomb variant, not symmetric, is refused by name."""
    direct = condensed_tangent(sheared.to_data(), sliding="stick")
    on_device = condensed_tangent_of_batch(sheared, sliding="stick")
    host = condensed_tangent_cg(sheared.to_data(), sliding="stick")
    assert _relative(on_device.tangent, direct.tangent).max() < 1e-8
    assert _relative(host.tangent, direct.tangent).max() < 1e-8
    for name in COUNTERS:
        np.testing.assert_array_equal(getattr(on_device, name), getattr(direct, name))
    free = condensed_tangent(sheared.to_data(), sliding="free")
    assert _relative(direct.tangent, free.tangent)[2:].min() > 1e-3  # the sheared ones moved
    for solve in (condensed_tangent_of_batch, condensed_tangent_cg):
        with pytest.raises(ValueError, match="sliding must be one of free, stick"):
            solve(sheared if solve is condensed_tangent_of_batch else sheared.to_data(),
                  sliding="coulomb")


def test_a_float32_state_is_refused_by_name(sheared: DEMBatch) -> None:
    single = DEMBatch(sheared.to_data().select(0), device="cpu", dtype="float32")
    with pytest.raises(ValueError, match="float64"):
        condensed_tangent_on_device(single.shards[0].model, single.shards[0].state)


def test_the_dem_backend_assembles_on_a_float64_cuda_batch(sheared: DEMBatch,
                                                             monkeypatch) -> None:
    """``condense``: a float64 batch on "cuda…" takes the device assembly, a float32
    one the host-assembled CG, a CPU batch scipy's LU."""
    from granular_material.dem.condensed import dispatch as condensation

    calls = []

    @dataclass
    class OnCuda:
        dtype: str
        device: str = "cuda:0"

        def __getattr__(self, name: str):
            return getattr(sheared, name)

    def device_path(batch, rves, sliding, raise_unconverged):
        calls.append(("device", sliding))
        return condensed_tangent_of_batch(sheared, rves=rves, sliding=sliding,
                                          raise_unconverged=raise_unconverged)

    def host_cg(data, rves, device, sliding, raise_unconverged):
        calls.append(("host-cg", sliding))
        return condensed_tangent_cg(data, rves=rves, sliding=sliding,
                                    raise_unconverged=raise_unconverged)

    monkeypatch.setattr(condensation, "condensed_tangent_of_batch", device_path)
    monkeypatch.setattr(condensation, "condensed_tangent_cg", host_cg)
    rves = np.array([1, 3])
    for sliding in ("free", "stick"):  # each path is told how contacts at the cap respond
        calls.clear()
        assembled = condensation.condense(OnCuda("float64"), rves, sliding)
        host = condensation.condense(OnCuda("float32"), rves, sliding)
        direct = condensation.condense(sheared, rves, sliding)
        assert calls == [("device", sliding), ("host-cg", sliding)]
        assert _relative(assembled, direct).max() < 1e-8
        assert _relative(host, direct).max() < 1e-8
    reference = condensed_tangent(sheared.to_data(), rves=rves, sliding="stick").tangent
    assert _relative(direct, reference).max() < 1e-14
