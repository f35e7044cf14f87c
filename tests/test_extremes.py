"""The extremes matrix (issue 12, "Reliability"): each case names what it checks and asserts
either a bounded, physically sensible result or a clear error raised before any work.

Units SI, stress tension positive (docs/design.md#conventions). The packings are small
(12–64 discs) so that the whole matrix runs in about a minute on two CPU cores; the docs'
"Numerical extremes" table gives the outcomes measured with it.
"""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest
from run_helpers import CommittedStrain, top_loaded_element

from granular_material.dem import (
    DEMBatch,
    DEMInstabilityError,
    RVEData,
    RVEFileError,
    RVEMeta,
    critical_timestep,
)
from granular_material.dem.homogenization import objective_tangent, symmetric_part
from granular_material.dem.model import FLOAT32_MAX_RESOLUTION
from granular_material.fem import (
    BiaxialSetup,
    MaterialResponse,
    NewtonError,
    NewtonSettings,
    NewtonSolver,
)
from granular_material.procedures import (
    CellTooThinError,
    biaxial_test,
    drive_grad_u,
    prepare_packing,
    strain_path,
)
from granular_material.procedures import packing as packing_module
from granular_material.procedures.packing import max_pressure
from granular_material.runs import run_biaxial

P0 = 100.0e3  #: consolidation pressure of the shared packings [Pa]
#: σ1/σ3 bound for the deviatoric cases: the stiffest frictional packing measured here
#: (tan φ = 10, 64 discs) peaked at 5.3 in a biaxial test; 6 leaves room for the small RVEs
RATIO_BOUND = 6.0


def _stiffness(kn: float) -> dict[str, float | str]:
    """The constant contact law with kn [N/m] and kt = 0.8·kn (Guo & Zhao's ratio)."""
    return {"law": "constant", "kn": kn, "kt": 0.8 * kn}


@pytest.fixture(scope="module")
def packings() -> dict[int, RVEData]:
    """Frictional (0.5 rad) packings of 12, 24 and 64 discs (seed 1) at P0."""
    return {n: prepare_packing(n_disc=n, seed=1, pressure=P0, device="cpu").to_data()
            for n in (12, 24, 64)}


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make the gas generation and any consolidation fail the test: a refusal must come
    before the work."""
    def forbidden(*_args: object, **_kwargs: object) -> int:
        raise AssertionError("the refusal came after work had started")

    monkeypatch.setattr(packing_module, "random_gas", forbidden)
    monkeypatch.setattr(packing_module, "consolidate", forbidden)


def _principal(sigma: np.ndarray) -> np.ndarray:
    """Principal stresses [Pa] of the symmetric part of ``sigma`` (2, 2), ascending."""
    return np.linalg.eigvalsh(0.5 * (sigma + sigma.T))


def _assert_compressive(sigma: np.ndarray, ratio_bound: float = RATIO_BOUND) -> None:
    """No tension (discs only push: both principal stresses negative) and σ1/σ3 bounded."""
    assert np.isfinite(sigma).all()
    most, least = _principal(sigma)
    assert least < 0, f"a principal stress is tensile: {most:.4g}, {least:.4g} Pa"
    assert most / least < ratio_bound, f"σ1/σ3 = {most / least:.3g}"


def _drift_free_change(data: RVEData, grad_u: np.ndarray,
                       **drive: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Stress change [Pa] (2, 2) that ``grad_u`` causes in RVE 0, less the change the same
    number of steps makes at a fixed cell (the packing's own settling); the initial tangent
    [Pa] (2, 2, 2, 2) and the steps."""
    batch = DEMBatch(data, device="cpu")
    start = batch.homogenize()
    snap = batch.snapshot()
    steps = drive_grad_u(batch, grad_u, **drive)
    driven = batch.homogenize().stress[0]
    batch.restore(snap)
    drive_grad_u(batch, np.zeros((2, 2)), min_steps=steps)
    return driven - batch.homogenize().stress[0], start.tangent[0], steps


# -- stiffness 1e3–1e10 N/m and p0 1 kPa–10 MPa ----------------------------------------------
@pytest.mark.parametrize(("kn", "pressure"), [
    pytest.param(1e3, 400.0, id="kn=1e3 N/m at p0=400 Pa: consolidated within 1 %"),
    pytest.param(1e10, 10e6, id="kn=1e10 N/m at p0=10 MPa: consolidated within 1 %"),
    pytest.param(3e6, 1e3, id="default kn at p0=1 kPa: consolidated within 1 %"),
])
def test_extreme_stiffness_and_pressure_consolidate(kn: float, pressure: float) -> None:
    meta = RVEMeta(stiffness=_stiffness(kn))
    batch = prepare_packing(n_disc=24, seed=1, pressure=pressure, meta=meta, device="cpu")
    h = batch.homogenize()
    # consolidate's own criterion: σxx and σyy within 1 % of −p0
    assert np.abs(np.diag(h.stress[0]) + pressure).max() <= 0.01 * pressure
    _assert_compressive(h.stress[0])
    # the time step follows the stiffness: 0.3 sqrt(m/k) of the lightest disc, k = max(kn, 2kt)
    assert batch.dt[0] == pytest.approx(0.3 * critical_timestep(batch.to_data().radius, meta))
    # a 1e-4 axial compression stiffens σyy by at most the affine (Kruyt–Rothenburg)
    # estimate, and by at least half of it (measured: 0.90–0.96 at 1e-4 for 24 discs)
    grad = np.array([[0.0, 0.0], [0.0, -1e-4]])
    change, tangent, _ = _drift_free_change(batch.to_data(), grad)
    affine = np.einsum("ijkl,kl->ij", tangent, grad)[1, 1]
    assert affine < 0 and 0.5 <= change[1, 1] / affine <= 1.02


@pytest.mark.parametrize(("kn", "pressure", "message"), [
    pytest.param(1e3, 100e3, r"at most 500 Pa", id="kn=1e3 N/m at 100 kPa: overlap 20 % refused"),
    pytest.param(1e10, 100e3, r"at least 2\.5e\+06 Pa",
                 id="kn=1e10 N/m at 100 kPa: overlap 2e-6 refused"),
    pytest.param(3e6, 10e6, r"at most 1\.5e\+06 Pa", id="p0=10 MPa: overlap 67 % refused"),
    pytest.param(3e6, 500.0, r"at least 750 Pa", id="p0=500 Pa: overlap 3.3e-5 refused"),
])
def test_pressure_outside_the_contact_law_is_refused_before_work(
        kn: float, pressure: float, message: str, no_work: None) -> None:
    named = re.escape(f"pressure = {pressure:g} Pa")
    with pytest.raises(ValueError, match=rf"{named} .*{message}"):
        prepare_packing(n_disc=24, pressure=pressure, meta=RVEMeta(stiffness=_stiffness(kn)),
                        device="cpu")


# -- radius ratio 1–10 -------------------------------------------------------------------------
@pytest.mark.parametrize("radius_range", [
    pytest.param((5e-3, 5e-3), id="radius ratio 1 (monodisperse): at p0, no tension"),
    pytest.param((1e-3, 10e-3), id="radius ratio 10: at p0, time step of the smallest disc"),
])
def test_radius_ratio(radius_range: tuple[float, float]) -> None:
    batch = prepare_packing(n_disc=24, seed=1, pressure=P0, radius_range=radius_range,
                            device="cpu")
    h = batch.homogenize()
    assert np.abs(np.diag(h.stress[0]) + P0).max() <= 0.01 * P0
    _assert_compressive(h.stress[0])
    assert h.coordination[0] >= 3.0  # a jammed frictional disc packing (isostatic: 3)
    data = batch.to_data()
    smallest = data.radius[0].min()
    mass = data.meta.density * data.meta.thickness * math.pi * smallest**2
    # 0.3 sqrt(m/k) with k = max(kn, 2 kt) = 4.8e6 N/m (the disc's rotation under kt)
    assert batch.dt[0] == pytest.approx(0.3 * math.sqrt(mass / 4.8e6))


def test_radius_ratio_10_needs_17_discs_refused_before_work(no_work: None) -> None:
    with pytest.raises(ValueError, match=r"n_disc = 16 is too few .* at least 17 discs"):
        prepare_packing(n_disc=16, radius_range=(1e-3, 10e-3), device="cpu")


# -- friction 0 and tan φ = 10 -----------------------------------------------------------------
@pytest.fixture(scope="module")
def friction_curves() -> dict[float, tuple[float, float]]:
    """Peak σ1/σ3 and final sliding fraction of a drained biaxial test to 5 % at 100 kPa,
    from the same frictionless-consolidated 64-disc packing, per friction coefficient μ."""
    out = {}
    for mu in (0.0, math.tan(0.5), 10.0):
        batch = prepare_packing(n_disc=64, seed=1, pressure=P0, device="cpu",
                                meta=RVEMeta(friction_angle=math.atan(mu)))
        curve = biaxial_test(batch, axial_strain=0.05, confining=P0, strain_per_step=2e-5,
                             record_every=250)
        assert np.isfinite(curve[["sxx", "syy", "sxy"]].to_numpy()).all()
        out[mu] = (float(curve["stress_ratio"].max()),
                   float(batch.homogenize().sliding_fraction[0]))
    return out


@pytest.mark.parametrize(("mu", "low", "high"), [
    # frictionless discs: macroscopic friction of a few degrees, σ1/σ3 well below 2
    pytest.param(0.0, 1.0, 2.0, id="friction 0: peak σ1/σ3 in (1, 2)"),
    pytest.param(math.tan(0.5), 2.0, 5.0, id="friction 0.5 rad: peak σ1/σ3 in (2, 5)"),
    # infinite friction still fails by rolling: bounded, and above μ = 0.55
    pytest.param(10.0, 3.0, 8.0, id="tan φ = 10: peak σ1/σ3 in (3, 8)"),
])
def test_friction_extremes_give_bounded_strength(friction_curves, mu: float, low: float,
                                                 high: float) -> None:
    peak, _ = friction_curves[mu]
    assert low < peak < high


def test_friction_orders_the_strength_and_tan_phi_10_does_not_slide(friction_curves) -> None:
    peaks = [friction_curves[mu][0] for mu in (0.0, math.tan(0.5), 10.0)]
    assert peaks[0] < peaks[1] < peaks[2]
    assert friction_curves[10.0][1] < 0.01  # μ = 10: (almost) no contact at the Coulomb cap


def test_friction_angle_of_90_degrees_is_refused(packings) -> None:
    batch = DEMBatch(packings[12], device="cpu")
    with pytest.raises(RVEFileError, match=r"meta\.friction_angle must lie in \[0, pi/2\)"):
        batch.set_friction(math.pi / 2)


# -- no damping ------------------------------------------------------------------------------
def _energy(batch: DEMBatch) -> float:
    """Kinetic, rotational, normal- and tangential-spring energy [J] of RVE 0 (fixed cell)."""
    data = batch.to_data()
    meta, r = data.meta, data.radius[0]
    mass = meta.density * meta.thickness * math.pi * r**2
    energy = 0.5 * np.sum(mass * np.sum(data.velocity[0] ** 2, axis=1))
    energy += 0.25 * np.sum(mass * r**2 * data.angular_velocity[0] ** 2)
    frac = data.extra["fractional_position"][0]
    ds = frac[None, :, :] - frac[:, None, :]
    ds -= np.round(ds)
    dist = np.linalg.norm(ds @ data.cell[0].T, axis=2)
    overlap = np.triu(np.clip(r[:, None] + r[None, :] - dist, 0.0, None), 1)
    energy += 0.5 * meta.stiffness["kn"] * np.sum(overlap**2)
    shear, count = data.extra["contact_shear_force"][0], data.extra["contact_count"][0]
    used = np.arange(shear.shape[1])[None, :] < count[:, None]
    return float(energy + 0.25 * np.sum(shear[used] ** 2) / meta.stiffness["kt"])  # 2 slots


@pytest.mark.parametrize("speed", [
    pytest.param(1e-3, id="no damping, kick 1e-3 m/s: energy grows < 1e-4"),
    pytest.param(1e-2, id="no damping, kick 1e-2 m/s: energy grows < 1e-4"),
    pytest.param(1e-1, id="no damping, kick 0.1 m/s (slip): energy grows < 1e-4"),
])
def test_no_damping_energy_does_not_grow(packings, speed: float) -> None:
    """Frictional contacts without damping: leap-frog keeps the energy (its error is of order
    (ω·dt)² of the kinetic part, ~1e-5 here) and Coulomb slip only takes energy away."""
    data = packings[64]
    rng = np.random.default_rng(0)
    data = replace(data, meta=replace(data.meta, damping=0.0),
                   velocity=rng.normal(0.0, speed, data.velocity.shape))
    batch = DEMBatch(data, device="cpu")
    batch.set_affine(np.zeros((1, 2, 2)))
    e0 = _energy(batch)
    energies = []
    for _ in range(6):
        batch.run(500)
        energies.append(_energy(batch))
    assert np.isfinite(energies).all()
    assert max(energies) / e0 - 1.0 < 1e-4


# -- ∇u increments 1e-7 to 5e-2 in one load step ---------------------------------------------
PURE_SHEAR = np.array([[0.5, 0.3], [0.3, -0.5]])  #: a symmetric deviatoric direction


@pytest.mark.parametrize("size", [
    pytest.param(1e-7, id="∇u 1e-7 in one step: Δσ within 2 % of the affine tangent"),
    pytest.param(1e-5, id="∇u 1e-5 in one step: Δσ within 2 % of the affine tangent"),
])
def test_tiny_increment_is_the_affine_response(packings, size: float) -> None:
    """Over its 2 steps a tiny increment deforms the contacts affinely: less the packing's own
    settling, Δσ is C:∇u (Kruyt–Rothenburg) to within 2 % (measured 0.7–0.9 %)."""
    grad = size * PURE_SHEAR
    change, tangent, steps = _drift_free_change(packings[64], grad)
    affine = np.einsum("ijkl,kl->ij", tangent, grad)
    assert steps == 2
    assert np.linalg.norm(change - affine) <= 0.02 * np.linalg.norm(affine)


@pytest.mark.parametrize("grad", [
    pytest.param(np.array([[0.0, 0.0], [0.0, -5e-2]]), id="∇u 5e-2 compression in one step"),
    pytest.param(5e-2 * PURE_SHEAR, id="∇u 5e-2 pure shear in one step"),
    pytest.param(np.array([[0.0, 0.0], [0.0, -1e-3]]), id="∇u 1e-3 compression in one step"),
])
def test_large_increment_stays_bounded(packings, grad: np.ndarray) -> None:
    """Bounded by the affine estimate (sliding and rearrangement only soften it: measured
    0.19–0.87 of it), compressive, σ1/σ3 bounded, below the law's pressure limit."""
    batch = DEMBatch(packings[64], device="cpu")
    before = batch.homogenize()
    drive_grad_u(batch, grad)
    after = batch.homogenize()
    change = after.stress[0] - before.stress[0]
    affine = np.einsum("ijkl,kl->ij", before.tangent[0], grad)
    assert np.linalg.norm(change) <= np.linalg.norm(affine)
    _assert_compressive(after.stress[0])
    assert -after.mean_stress[0] < max_pressure(RVEMeta())


def test_increment_over_the_step_cap_is_refused_before_work(packings) -> None:
    batch = DEMBatch(packings[12], device="cpu")
    cell = batch.cell()
    with pytest.raises(ValueError, match=r"needs 5000 DEM steps .* cap of 1000"):
        drive_grad_u(batch, np.array([[0.0, 0.0], [0.0, -5e-2]]), max_steps=1000)
    np.testing.assert_array_equal(batch.cell(), cell)


# -- extension until every contact is lost ---------------------------------------------------
def test_extension_until_all_contacts_are_lost(packings) -> None:
    """5 % stretch both ways (the overlaps are 0.7 % of the radius): zero stress and tangent,
    coordination 0, the void ratio of the stretched cell, and nothing NaN."""
    data = packings[64]
    batch = DEMBatch(data, device="cpu")
    e0 = batch.homogenize().void_ratio[0]
    drive_grad_u(batch, 0.05 * np.eye(2))
    h = batch.homogenize()
    assert h.n_contacts[0] == 0 and h.coordination[0] == 0
    assert np.all(h.stress == 0) and np.all(h.tangent == 0) and np.all(h.fabric == 0)
    assert h.void_ratio[0] == pytest.approx(1.05**2 * (1 + e0) - 1, rel=1e-12)
    assert not np.isnan(h.unbalanced_force[0])  # no contact force: reported as inf
    assert np.isfinite(batch.to_data().velocity).all()


# -- rotation-dominated ∇u ---------------------------------------------------------------------
def _rotation(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


@pytest.mark.parametrize("theta", [
    pytest.param(0.5, id="rotation 0.5 rad: stress rotated, error < 1e-5 p"),
    pytest.param(math.pi / 2, id="rotation pi/2: stress rotated, error < 1e-5 p"),
    pytest.param(0.9 * math.pi, id="rotation 0.9 pi: stress rotated, error < 1e-5 p"),
    pytest.param(-0.9 * math.pi, id="rotation -0.9 pi: stress rotated, error < 1e-5 p"),
])
def test_rotation_dominated_grad_u_rotates_the_stress(packings, theta: float) -> None:
    """∇u = R − I (|∇u| up to 1.95) at 1e-3 a step: Rᵀσ'R equals the stress the same steps
    give at a fixed cell (measured 1e-8–1e-6 p); the coordination is unchanged."""
    rot = _rotation(theta)
    batch = DEMBatch(packings[64], device="cpu")
    snap = batch.snapshot()
    steps = drive_grad_u(batch, rot - np.eye(2), max_strain_per_step=1e-3)
    turned = batch.homogenize()
    np.testing.assert_allclose(batch.cell()[0], rot @ packings[64].cell[0], rtol=0,
                               atol=1e-12 * np.abs(packings[64].cell[0]).max())
    batch.restore(snap)
    drive_grad_u(batch, np.zeros((2, 2)), min_steps=steps)
    still = batch.homogenize()
    p = -still.mean_stress[0]
    assert np.abs(rot.T @ turned.stress[0] @ rot - still.stress[0]).max() < 1e-5 * p
    assert turned.n_contacts[0] == still.n_contacts[0]


def test_half_turn_is_refused_before_work(packings) -> None:
    batch = DEMBatch(packings[12], device="cpu")
    cell = batch.cell()
    with pytest.raises(ValueError, match="has no real logarithm"):
        drive_grad_u(batch, _rotation(math.pi) - np.eye(2))
    np.testing.assert_array_equal(batch.cell(), cell)


def test_objective_tangent_predicts_the_response_to_a_small_spin(packings) -> None:
    """A spin W = 1e-6: the DEM rotates its stress (Wσ − σW, about 0.03 Pa); the objective
    tangent predicts that within 10 %, where Kruyt–Rothenburg as published answers with
    ±27 Pa through its kt term."""
    spin = np.array([[0.0, -1e-6], [1e-6, 0.0]])
    change, tangent, _ = _drift_free_change(packings[64], spin)
    stress = DEMBatch(packings[64], device="cpu").homogenize().stress[0]
    stress = 0.5 * (stress + stress.T)
    objective = objective_tangent(tangent[None], stress[None])[0]
    predicted = np.einsum("ijkl,kl->ij", objective, spin)
    rotated = spin @ stress - stress @ spin
    np.testing.assert_allclose(predicted, rotated, rtol=1e-12, atol=1e-12)
    assert np.linalg.norm(predicted - change) <= 0.1 * np.linalg.norm(change)
    published = np.einsum("ijkl,kl->ij", tangent, spin)
    assert np.linalg.norm(published - change) > 100 * np.linalg.norm(change)


def test_objective_tangent_is_symmetric_on_strains_and_keeps_the_strain_response(
        packings) -> None:
    """Minor symmetry in ij (a symmetric stress change) and, on strains, kl; major symmetry
    of its strain part; a strain increment gets Kruyt–Rothenburg's own answer symmetrised."""
    h = DEMBatch(packings[64], device="cpu").homogenize()
    stress = 0.5 * (h.stress + np.swapaxes(h.stress, 1, 2))
    c = objective_tangent(h.tangent, stress)
    np.testing.assert_allclose(c, np.swapaxes(c, 1, 2), atol=1e-9 * np.abs(c).max())
    strain_part = symmetric_part(h.tangent)
    np.testing.assert_allclose(strain_part, strain_part.transpose(0, 3, 4, 1, 2),
                               atol=1e-9 * np.abs(c).max())
    eps = np.array([[-1e-4, 3e-5], [3e-5, 2e-5]])
    kr = np.einsum("bijkl,kl->bij", h.tangent, eps)
    np.testing.assert_allclose(np.einsum("bijkl,kl->bij", c, eps),
                               0.5 * (kr + np.swapaxes(kr, 1, 2)),
                               atol=1e-9 * np.abs(kr).max())


# -- cells sheared past |H01/H11| = 1 -----------------------------------------------------------
def _brute_force_contacts(data: RVEData) -> int:
    """Overlapping pairs of RVE 0 over all nine periodic images (each pair in one image)."""
    cell, r = data.cell[0], data.radius[0]
    frac = np.linalg.solve(cell, data.position[0].T).T
    pairs = 0
    for i in range(r.size):
        for j in range(i + 1, r.size):
            images = [(frac[j] - frac[i] + np.array([a, b])) @ cell.T
                      for a in (-2, -1, 0, 1, 2) for b in (-2, -1, 0, 1, 2)]
            touching = sum(np.linalg.norm(d) < r[i] + r[j] for d in images)
            assert touching <= 1, f"discs {i}, {j} touch in {touching} images"
            pairs += touching
    return pairs


def test_cell_sheared_past_one_keeps_every_contact(packings) -> None:
    """Simple shear γ = 1.5 of the 64-disc cell (|H01/H11| = 1.5): the engine's contacts are
    those of a search over all images; the stress stays compressive and bounded."""
    batch = DEMBatch(packings[64], device="cpu")
    drive_grad_u(batch, np.array([[0.0, 1.5], [0.0, 0.0]]), max_strain_per_step=1e-4)
    cell = batch.cell()[0]
    assert abs(cell[0, 1] / cell[1, 1]) == pytest.approx(1.5)
    h = batch.homogenize()
    assert h.n_contacts[0] == _brute_force_contacts(batch.to_data())
    _assert_compressive(h.stress[0])


def test_shear_that_thins_the_cell_too_far_is_refused_before_work(packings, monkeypatch) -> None:
    """12 discs: the cell's height reaches twice the contact cut-off at γ* = 0.339. At 0.9 γ*
    the path runs; at 1.1 γ* it is refused before any step, naming the RVE, and the engine
    itself (pre-check switched off) stops there too."""
    data = packings[12]
    batch = DEMBatch(data, device="cpu")
    width, cutoff = data.cell[0, 0, 0], batch.cutoff[0]
    limit = math.sqrt((width / (2 * cutoff)) ** 2 - 1)  # L/sqrt(1 + γ²) = 2·cut-off
    assert limit == pytest.approx(0.339, abs=0.001)
    fine = np.array([[0.0, 0.9 * limit], [0.0, 0.0]])
    drive_grad_u(DEMBatch(data, device="cpu"), fine, max_strain_per_step=1e-4)
    far = np.array([[0.0, 1.1 * limit], [0.0, 0.0]])
    with pytest.raises(CellTooThinError, match=r"RVE 0 thins its cell .* before any step") as info:
        drive_grad_u(batch, far, max_strain_per_step=1e-4)
    assert isinstance(info.value, ValueError) and isinstance(info.value, DEMInstabilityError)
    assert info.value.rve == [0]
    np.testing.assert_array_equal(batch.cell()[0], data.cell[0])
    monkeypatch.setattr(strain_path, "_check_path_heights", lambda *args: None)
    with pytest.raises(DEMInstabilityError, match="too small or too sheared"):
        drive_grad_u(batch, far, max_strain_per_step=1e-4)


# -- one RVE and 10 000 RVEs -------------------------------------------------------------------
def test_ten_thousand_small_rves_match_one_rve_bit_for_bit(packings) -> None:
    """10 000 copies of the 12-disc RVE, each with its own ∇u (up to 1e-4: 2–10 steps): every
    sampled RVE gives exactly what it gives alone (B = 1), and nothing is NaN."""
    n = 10_000
    ramp = np.linspace(0.0, 1e-4, n)
    grad = np.zeros((n, 2, 2))
    grad[:, 0, 1], grad[:, 1, 1] = ramp, -ramp
    batch = DEMBatch(packings[12].replicate(n), device="cpu")
    assert drive_grad_u(batch, grad) == 10
    stress = batch.homogenize().stress
    assert np.isfinite(stress).all()
    for b in (0, 1234, n - 1):
        alone = DEMBatch(packings[12], device="cpu")
        drive_grad_u(alone, grad[b])
        np.testing.assert_array_equal(stress[b], alone.homogenize().stress[0])


# -- float32 on large cells ----------------------------------------------------------------------
def _triangular_lattice(n: int, kn: float, pressure: float) -> tuple[RVEData, float]:
    """n × n discs of 5 mm (n even) on a triangular lattice pressed to ``pressure`` [Pa]
    (offset off the binary grid), and its exact mean stress magnitude [Pa].

    Each disc has 6 contacts of overlap δ at spacing a = 2r − δ; Love's sum over the three
    directions gives p = √3·kn·δ/(a·t), solved here for δ."""
    r, t = 5e-3, 0.1
    delta = 0.0
    for _ in range(3):  # fixed point of δ = p·a·t/(√3 kn), a = 2r − δ
        delta = pressure * (2 * r - delta) * t / (math.sqrt(3) * kn)
    a = 2 * r - delta
    ix, iy = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    x = (ix + 0.5 * (iy % 2) + 0.2371) * a
    y = (iy + 0.3719) * a * math.sqrt(3) / 2
    position = np.stack([x.ravel(), y.ravel()], axis=1)
    cell = np.diag([n * a, n * a * math.sqrt(3) / 2])
    data = RVEData(np.full((1, n * n), r), position[None], cell[None], np.zeros((1, n * n, 2)),
                   np.zeros((1, n * n)), RVEMeta(stiffness=_stiffness(kn)))
    return data, math.sqrt(3) * kn * delta / (a * t)


def test_float32_on_a_large_cell_keeps_the_exact_stress() -> None:
    """3600 discs, 0.6 m cell, kn = 3e6 at 100 kPa: float32 spacing 3.6e-8 m is 0.19 % of the
    overlap 1.9e-5 m. After 500 steps the mean stress is the closed form within 1e-4."""
    data, exact = _triangular_lattice(60, 3e6, P0)
    batch = DEMBatch(data, device="cpu", dtype="float32")
    batch.set_affine(np.zeros((1, 2, 2)))
    batch.run(500)
    h = batch.homogenize()
    assert -h.mean_stress[0] == pytest.approx(exact, rel=1e-4)
    assert h.coordination[0] == 6.0 and h.unbalanced_force[0] < 1e-3


def test_float32_that_cannot_resolve_the_overlaps_is_refused_before_work() -> None:
    """The same lattice at kn = 1e9: the overlap is 5.8e-8 m, float32 resolves 3.6e-8 m
    (62 %, unbalanced force 0.12 and contacts lost when run). float64 holds the closed form."""
    data, exact = _triangular_lattice(60, 1e9, P0)
    with pytest.raises(ValueError, match=r"dtype float32 cannot resolve the contacts of RVE 0"):
        DEMBatch(data, device="cpu", dtype="float32")
    batch = DEMBatch(data, device="cpu")
    assert -batch.homogenize().mean_stress[0] == pytest.approx(exact, rel=1e-9)
    assert FLOAT32_MAX_RESOLUTION == 0.005


def test_float32_packing_too_soft_for_its_cell_is_refused_before_work(no_work: None) -> None:
    with pytest.raises(ValueError, match=r"dtype float32 cannot resolve contacts .*1000 Pa"):
        prepare_packing(n_disc=64, pressure=1e3, dtype="float32", device="cpu")


# -- Newton on a softening material ------------------------------------------------------------
class SofteningElastic(CommittedStrain):
    """σ = σ0·I + K·tr ε·I + 2G·exp(−γ/γ0)·e (e = dev ε, γ = |e|): the deviatoric stress
    peaks at γ = γ0 and then falls; the exact tangent (negative past the peak) is returned.

    Stateless but for the committed strain; K, G [Pa], σ0 [Pa] (tension positive)."""

    def __init__(self, bulk: float = 30e6, shear: float = 20e6, gamma0: float = 2e-3,
                 initial_stress: float = 0.0) -> None:
        self.bulk, self.shear, self.gamma0, self.initial_stress = (bulk, shear, gamma0,
                                                                   initial_stress)
        super().__init__()

    def evaluate(self, grad_u: np.ndarray) -> MaterialResponse:
        eye = np.eye(2)
        strain = self.strain + 0.5 * (grad_u + np.swapaxes(grad_u, 1, 2))
        self.trial = strain
        volume = np.trace(strain, axis1=1, axis2=2)
        dev = strain - 0.5 * volume[:, None, None] * eye
        gamma = np.sqrt(np.einsum("nij,nij->n", dev, dev))
        phi = np.exp(-gamma / self.gamma0)
        stress = ((self.initial_stress + self.bulk * volume)[:, None, None] * eye
                  + 2 * self.shear * phi[:, None, None] * dev)
        sym = 0.5 * (np.einsum("ik,jl->ijkl", eye, eye) + np.einsum("il,jk->ijkl", eye, eye))
        projector = sym - 0.5 * np.einsum("ij,kl->ijkl", eye, eye)
        unit = np.where(gamma[:, None, None] > 0, dev / np.maximum(gamma, 1e-300)[:, None, None],
                        0.0)
        tangent = (self.bulk * np.einsum("ij,kl->ijkl", eye, eye)[None]
                   + 2 * self.shear * phi[:, None, None, None, None] * (
                       projector[None] - (gamma / self.gamma0)[:, None, None, None, None]
                       * np.einsum("nij,nkl->nijkl", unit, unit)))
        return MaterialResponse(stress, tangent, np.zeros(self.n_points, dtype=np.int8))

    def platen_stress(self, axial_strain: float, confining: float) -> float:
        """Closed form [Pa, compression +] of the homogeneous drained biaxial element: with
        d = εxx − εyy, σxx = −p gives εyy = −d(K + Gφ)/(2K) (monotone in d for K > 0.14 G),
        and the platen stress is p + 2Gφ(d/√2)·d."""
        from scipy.optimize import brentq

        def phi(d: float) -> float:
            return math.exp(-d / math.sqrt(2) / self.gamma0)

        d = brentq(lambda d: d * (self.bulk + self.shear * phi(d)) / (2 * self.bulk)
                   - axial_strain, 0.0, 1.0, xtol=1e-16)
        return confining + 2 * self.shear * phi(d) * d


def test_newton_follows_a_softening_material_past_its_peak() -> None:
    """Displacement control through the peak: every step converges (exact tangent, ≤ 6
    iterations), the platen stress is the closed form within 1e-6 and falls after the peak."""
    p, strain = 100e3, 0.01
    material = SofteningElastic(initial_stress=-p)
    setup = BiaxialSetup(width=1.0, height=1.0, nx=1, ny=1, confining=p, axial_strain=strain)
    result = run_biaxial(setup, material, 20, NewtonSettings(rtol=1e-10, max_cutbacks=0))
    assert result.error is None
    steps = result.steps.iloc[1:]
    assert (steps["iterations"] <= 6).all()
    for _, row in steps.iterrows():
        assert row["platen_stress"] == pytest.approx(
            material.platen_stress(row["axial_strain"], p), rel=1e-6)
    platen = steps["platen_stress"].to_numpy()
    peak = int(np.argmax(platen))
    assert 0 < peak < len(platen) - 1 and np.all(np.diff(platen[peak:]) < 0)


# at the limit point an iterate's tangent is singular (scipy warns); Newton then diverges
@pytest.mark.filterwarnings("ignore::scipy.sparse.linalg.MatrixRankWarning")
def test_newton_under_load_past_the_limit_stops_with_a_named_step() -> None:
    """Force control of a unit Q4 (rollers below, pressure q on top) to 1.5 × the limit load
    q* = 2G·d*·e⁻¹ (d* = √2 γ0): no equilibrium exists past q*, so Newton raises NewtonError
    naming the step, and the committed state stays below q*, finite."""
    material = SofteningElastic()
    limit = 2 * material.shear * math.sqrt(2) * material.gamma0 / math.e
    basis, loading = top_loaded_element(1.5 * limit)
    solver = NewtonSolver(basis, material, loading, NewtonSettings(rtol=1e-8, max_cutbacks=4))
    with pytest.raises(NewtonError, match=r"load step \d+ .* did not converge"):
        solver.run(10)
    # the limit is at λ = 1/1.5; the cut-backs bring the committed load within 5 % of it
    assert 0.95 < solver.load_factor * 1.5 < 1.0
    assert np.isfinite(solver.u).all()
