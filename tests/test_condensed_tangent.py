"""The condensed (non-affine) tangent: closed forms of lattices, the DEM's own relaxed
response, symmetry and objectivity (granular_material.dem.condensed.tangent)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from granular_material.dem import DEMBatch, RVEData, RVEMeta
from granular_material.dem.condensed.tangent import condensed_tangent, contact_network
from granular_material.dem.homogenization import spin_tangent
from granular_material.procedures import drive_grad_u, prepare_packing

KN, KT = 3.0e6, 2.4e6  # N/m (docs/design.md#wu-2025)
THICKNESS = 0.1  # m
SPIN = np.array([[0.0, -1.0], [1.0, 0.0]])


def _isotropic(bulk: float, shear: float) -> np.ndarray:
    """2D isotropic C [Pa] (2, 2, 2, 2) of bulk modulus κ and shear modulus μ (plane)."""
    eye = np.eye(2)
    lam = bulk - shear
    return (lam * np.einsum("ij,kl->ijkl", eye, eye)
            + shear * (np.einsum("ik,jl->ijkl", eye, eye) + np.einsum("il,jk->ijkl", eye, eye)))


def _sym(c: np.ndarray) -> np.ndarray:
    """C symmetrised over (ij) and over (kl)."""
    c = 0.5 * (c + np.swapaxes(c, -4, -3))
    return 0.5 * (c + np.swapaxes(c, -2, -1))


def _lattice(radius: np.ndarray, position: np.ndarray, cell: np.ndarray,
             friction_angle: float = 0.5, kt: float = KT) -> RVEData:
    meta = RVEMeta(stiffness={"law": "constant", "kn": KN, "kt": kt},
                   friction_angle=friction_angle)
    n = len(radius)
    return RVEData(radius=radius[None], position=position[None], cell=cell[None],
                   velocity=np.zeros((1, n, 2)), angular_velocity=np.zeros((1, n)), meta=meta)


def _tile(basis: np.ndarray, width: float, height: float, nx: int, ny: int) -> tuple:
    """Positions of ``basis`` (K, 2) repeated over nx × ny rectangles, and the cell."""
    shifts = np.array([(i * width, j * height) for i in range(nx) for j in range(ny)])
    position = (shifts[:, None, :] + basis[None]).reshape(-1, 2)
    return position, np.diag([nx * width, ny * height])


def triangular(radius: float = 5e-3, overlap: float = 1e-3) -> tuple[RVEData, float]:
    """A perfect triangular lattice of equal discs (6 contacts each), 4 × 2 rectangles of
    two discs; and its bond length ℓ [m] = 2r(1 − overlap)."""
    bond = 2.0 * radius * (1.0 - overlap)
    basis = np.array([[0.0, 0.0], [0.5 * bond, 0.5 * math.sqrt(3.0) * bond]])
    position, cell = _tile(basis, bond, math.sqrt(3.0) * bond, 4, 2)
    return _lattice(np.full(len(position), radius), position, cell), bond


def honeycomb(r_a: float = 5e-3, r_b: float = 4e-3, overlap: float = 1e-3,
              kt: float = 0.1 * KN) -> tuple:
    """A honeycomb of discs A (radius r_a) and B (r_b), each touching three of the other
    kind at 120°: a lattice with a two-disc basis, 2 × 2 rectangles of four discs, contact
    stiffness kn and ``kt`` [N/m]; and its bond length ℓ [m]."""
    bond = (r_a + r_b) * (1.0 - overlap)
    w, h = math.sqrt(3.0) * bond, 3.0 * bond
    basis = np.array([[0.0, 0.0], [0.0, bond], [0.5 * w, 1.5 * bond], [0.5 * w, 2.5 * bond]])
    position, cell = _tile(basis + np.array([0.25 * w, 0.1 * bond]), w, h, 2, 2)
    radius = np.tile([r_a, r_b, r_a, r_b], 4)
    return _lattice(radius, position, cell, kt=kt), bond


# -- closed forms ------------------------------------------------------------------------------
def test_triangular_lattice_condensed_equals_affine_equals_closed_form() -> None:
    """Every disc of a triangular lattice is a centre of symmetry: the affine field is in
    equilibrium, nothing relaxes. Per disc three bonds of length ℓ at 60° and area √3ℓ²/2:
    κ = √3·kn/(2t), μ = √3·(kn + kt')/(4t), with kt' = kt·s², s = 2r/ℓ (the engine's slip
    is s·t·Δd; Kruyt–Rothenburg's is t·Δd, so it has kt' = kt)."""
    data, bond = triangular()
    s = 2 * 5e-3 / bond
    closed = _isotropic(math.sqrt(3) * KN / (2 * THICKNESS),
                        math.sqrt(3) * (KN + KT * s**2) / (4 * THICKNESS))
    result = condensed_tangent(data)
    assert result.n_contacts[0] == 3 * data.n_disc and result.n_left_out[0] == 0
    scale = np.abs(closed).max()
    assert np.abs(result.tangent[0] - closed).max() < 1e-9 * scale
    assert np.abs(result.affine[0] - closed).max() < 1e-9 * scale
    # the engine's own Kruyt–Rothenburg tangent, symmetrised, is the same closed form with kt
    kr = DEMBatch(data, device="cpu").homogenize().tangent[0]
    closed_kr = _isotropic(math.sqrt(3) * KN / (2 * THICKNESS),
                           math.sqrt(3) * (KN + KT) / (4 * THICKNESS))
    assert np.abs(_sym(kr) - closed_kr).max() < 1e-9 * scale


def test_honeycomb_relaxes_to_the_hand_calculation() -> None:
    """A honeycomb (two-disc basis, bonds ℓ along n_α at 120°) relaxes under deviatoric
    strain: sublattice B shifts by v against A. Per cell (area 3√3ℓ²/2, three bonds) with
    Σ n n = Σ t t = (3/2) I and the triad Σ n_i n_j n_k, minimising
    E = ½Σ kn (n·(v + ℓεn))² + kt' (t·(v + ℓεn))² over v gives E = (3ℓ²/16)[2 kn (tr ε)² +
    4 kn kt'/(kn + kt') D²], D² = (ε_xx − ε_yy)² + 4ε_xy², against (kn + kt') D² affinely:
    κ = kn/(2√3 t), μ = kn kt'/(√3 (kn + kt') t), affine μ = (kn + kt')/(4√3 t). The discs'
    counter-rotation (gears) is a floppy mode: the regularisation must not feel it."""
    data, bond = honeycomb(kt=0.1 * KN)
    kt_s = 0.1 * KN * (9e-3 / bond) ** 2
    relaxed = _isotropic(KN / (2 * math.sqrt(3) * THICKNESS),
                         KN * kt_s / (math.sqrt(3) * (KN + kt_s) * THICKNESS))
    affine = _isotropic(KN / (2 * math.sqrt(3) * THICKNESS),
                        (KN + kt_s) / (4 * math.sqrt(3) * THICKNESS))
    result = condensed_tangent(data)
    assert result.n_contacts[0] == 3 * data.n_disc // 2
    scale = np.abs(affine).max()
    assert np.abs(result.affine[0] - affine).max() < 1e-9 * scale
    assert np.abs(result.tangent[0] - relaxed).max() < 1e-7 * scale
    # what the relaxation takes away is not small here (the test can tell them apart)
    assert affine[0, 1, 0, 1] > 2.5 * relaxed[0, 1, 0, 1]
    # frictionless honeycomb: no shear stiffness at all once relaxed (a mechanism)
    slick = condensed_tangent(_lattice(data.radius[0], data.position[0], data.cell[0],
                                       friction_angle=0.0, kt=0.0))
    assert abs(slick.tangent[0, 0, 1, 0, 1]) < 1e-7 * scale


def test_rattlers_and_single_contacts_are_left_out_without_changing_c() -> None:
    """A disc in a hexagon's hole touching nothing (rattler), and one touching a single
    lattice disc, leave the honeycomb's C as it is and are counted as left out."""
    data, bond = honeycomb()
    base = condensed_tangent(data).tangent[0]
    a0 = data.position[0, 0]
    hole = a0 + np.array([0.5 * math.sqrt(3) * bond, 0.5 * bond])  # centre of a hexagon
    r_dangle = 3e-3
    dangler = a0 + (5e-3 + r_dangle - 1e-5) * np.array([0.0, -1.0])  # below A0, its 4th
    radius = np.concatenate([data.radius[0], [1e-3, r_dangle]])
    position = np.concatenate([data.position[0], [hole, dangler]])
    grown = _lattice(radius, position, data.cell[0], kt=0.1 * KN)
    result = condensed_tangent(grown)
    assert result.n_contacts[0] == 3 * data.n_disc // 2 + 1
    assert result.n_left_out[0] == 2
    assert np.abs(result.tangent[0] - base).max() < 1e-7 * np.abs(base).max()


# -- a packing: symmetry, objectivity, the DEM's own response ----------------------------------
@pytest.fixture(scope="module")
def sheared() -> RVEData:
    """A 24-disc packing at 100 kPa sheared 1 % (ε = ±0.5 %), so that contacts slide."""
    batch = prepare_packing(n_disc=24, seed=2, pressure=100e3, device="cpu")
    drive_grad_u(batch, np.diag([0.005, -0.005]))
    return batch.to_data()


def test_symmetries_and_objectivity(sheared: RVEData) -> None:
    """Free sliding: major symmetry, a spin costs nothing (C:W = 0) and both minor
    symmetries. Coulomb sliding keeps C:W = 0 but loses major symmetry. Kruyt–Rothenburg
    resists a spin."""
    free = condensed_tangent(sheared, sliding="free")
    assert free.n_sliding[0] > 0  # there is something for the sliding rules to do
    c = free.tangent[0]
    scale = np.abs(c).max()
    assert np.abs(c - c.transpose(2, 3, 0, 1)).max() < 1e-10 * scale
    assert np.abs(c - c.transpose(1, 0, 2, 3)).max() < 1e-10 * scale
    assert np.abs(c - c.transpose(0, 1, 3, 2)).max() < 1e-10 * scale
    assert np.abs(np.einsum("ijkl,kl->ij", c, SPIN)).max() < 1e-10 * scale
    coulomb = condensed_tangent(sheared, sliding="coulomb").tangent[0]
    assert np.abs(np.einsum("ijkl,kl->ij", coulomb, SPIN)).max() < 1e-10 * scale
    assert np.abs(coulomb - coulomb.transpose(2, 3, 0, 1)).max() > 1e-3 * scale
    kr = DEMBatch(sheared, device="cpu").homogenize().tangent[0]
    assert np.abs(np.einsum("ijkl,kl->ij", kr, SPIN)).max() > 0.1 * scale
    # the condensation only ever softens (free sliding: a minimum over the fluctuations)
    sym = free.affine[0].reshape(4, 4) - c.reshape(4, 4)
    assert np.linalg.eigvalsh(0.5 * (sym + sym.T)).min() > -1e-10 * scale


def test_sticking_bounds_the_free_tangent_from_above(sheared: RVEData) -> None:
    """``sliding="stick"`` (every touching contact keeps kt) is symmetric and objective, and
    C_stick − C_free is positive semi-definite: the condensation is a minimum of the
    network's energy over the fluctuations, and kt only adds energy. Where nothing slides
    the two are the same matrix."""
    free = condensed_tangent(sheared, sliding="free")
    stick = condensed_tangent(sheared, sliding="stick")
    c, scale = stick.tangent[0], np.abs(stick.tangent[0]).max()
    assert np.abs(c - c.transpose(2, 3, 0, 1)).max() < 1e-10 * scale
    assert np.abs(np.einsum("ijkl,kl->ij", c, SPIN)).max() < 1e-10 * scale
    np.testing.assert_array_equal(stick.n_sliding, free.n_sliding)  # still counted
    gap = c.reshape(4, 4) - free.tangent[0].reshape(4, 4)
    eigen = np.linalg.eigvalsh(0.5 * (gap + gap.T))
    assert eigen.min() > -1e-10 * scale and eigen.max() > 1e-3 * scale
    # no contact at its cap (the tolerance counts none as sliding): the same C
    none = condensed_tangent(sheared, sliding="free", cap_tolerance=-1.0)
    assert none.n_sliding[0] == 0
    np.testing.assert_allclose(none.tangent, stick.tangent, rtol=0, atol=1e-12 * scale)
    with pytest.raises(ValueError, match="sliding must be one of"):
        condensed_tangent(sheared, sliding="stuck")


def test_regularisation_does_not_move_c(sheared: RVEData) -> None:
    """The floppy modes left after pruning carry no load: the regularisation shifts C only
    in proportion to itself (below 1e-5 of max|C| at 1e-7, against 1e-11)."""
    loose = condensed_tangent(sheared, regularization=1e-7).tangent[0]
    tight = condensed_tangent(sheared, regularization=1e-11).tangent[0]
    assert np.abs(loose - tight).max() < 1e-5 * np.abs(tight).max()


def test_network_matches_the_engine(sheared: RVEData) -> None:
    """The contacts, sliding flags and Love stress of the network are the engine's."""
    h = DEMBatch(sheared, device="cpu").homogenize()
    net = contact_network(sheared, 0)
    assert len(net.a) == h.n_contacts[0]
    assert net.sliding.mean() == pytest.approx(h.sliding_fraction[0])
    n = net.branch / np.linalg.norm(net.branch, axis=1)[:, None]
    t = np.stack([-n[:, 1], n[:, 0]], axis=1)
    force_a = -net.normal_force[:, None] * n + net.shear_force[:, None] * t
    love = np.einsum("mi,mj->ij", force_a, net.branch) / net.volume
    assert np.abs(love - h.stress[0]).max() < 1e-9 * np.abs(h.stress[0]).max()


def test_condensed_predicts_the_relaxed_dem_response() -> None:
    """Central differences of the DEM (±1e-5 of each strain component, applied slowly and
    held until the packing is at rest) of a 24-disc packing at 100 kPa: the condensed
    tangent is within 3 % of them (measured 0.5–1.6 % over seeds 1–3); Kruyt–Rothenburg,
    which leaves the rearrangement out, is not within 10 % (11–39 %)."""
    batch = prepare_packing(n_disc=24, seed=1, pressure=100e3, device="cpu")
    data = batch.to_data()
    condensed = condensed_tangent(data).tangent[0]
    kr = batch.homogenize().tangent[0]
    snap = batch.snapshot()
    size = 1e-5
    for direction in (np.diag([1.0, 0.0]), np.diag([0.0, 1.0]),
                      np.array([[0.0, 1.0], [1.0, 0.0]]), np.diag([1.0, -1.0])):
        stress = []
        for sign in (1.0, -1.0):
            batch.restore(snap)
            drive_grad_u(batch, sign * size * direction, max_strain_per_step=1e-8)
            drive_grad_u(batch, np.zeros((2, 2)), min_steps=2000)
            stress.append(batch.homogenize().stress[0])
        dem = (stress[0] - stress[1]) / (2 * size)
        predicted = np.einsum("ijkl,kl->ij", condensed, direction)
        affine = np.einsum("ijkl,kl->ij", kr, direction)
        error = np.linalg.norm(predicted - dem) / np.linalg.norm(dem)
        error_kr = np.linalg.norm(affine - dem) / np.linalg.norm(dem)
        assert error < 0.03, (direction.tolist(), error)
        if direction[0, 0] != direction[1, 1]:  # deviatoric: affine is far off
            assert error_kr > 0.1, (direction.tolist(), error_kr)


# -- the DEM material ---------------------------------------------------------------------------
def test_dem_material_returns_the_condensed_tangent(sheared: RVEData, tmp_path) -> None:
    """``tangent="condensed"``: the material's tangent is the condensed tangent of each
    RVE's trial state, at no DEM run beyond the evaluation's own."""
    from granular_material.dem import save_rve
    from granular_material.multiscale import DEMMaterial

    path = tmp_path / "sheared.npz"
    save_rve(path, sheared)
    grad = np.array([[[1e-4, 0.0], [0.0, -1e-4]], [[0.0, 1e-4], [1e-4, 0.0]]])
    kr = DEMMaterial(rve=path, device="cpu", replicate=True)
    kr.allocate(2)
    condensed = DEMMaterial(rve=path, device="cpu", replicate=True, tangent="condensed")
    condensed.allocate(2)
    response = condensed.evaluate(grad)
    reference = kr.evaluate(grad)
    np.testing.assert_array_equal(response.stress, reference.stress)
    assert response.costs["dem_steps"] == reference.costs["dem_steps"]
    # the condensed tangent of the trial states, plus the rotation of the stress by a spin
    # (the material's stress is the symmetrised Love stress)
    expected = (condensed_tangent(condensed.backend.batch.to_data()).tangent
                + spin_tangent(response.stress))
    scale = np.abs(expected).max()
    np.testing.assert_allclose(response.tangent, expected, rtol=0, atol=1e-9 * scale)
    assert np.abs(response.tangent - reference.tangent).max() > 0.1 * scale
    with pytest.raises(ValueError, match="tangent must be one of"):
        DEMMaterial(rve=path, device="cpu", tangent="condensd").allocate(1)


def test_dem_material_returns_the_sticking_tangent(sheared: RVEData, tmp_path) -> None:
    """``tangent="condensed-sticking"``: the condensed tangent with every touching contact
    sticking, plus the stress's spin; the same stress as any other tangent."""
    from granular_material.dem import save_rve
    from granular_material.multiscale import DEMMaterial

    path = tmp_path / "sheared.npz"
    save_rve(path, sheared)
    grad = np.array([[[1e-4, 0.0], [0.0, -1e-4]], [[0.0, 1e-4], [1e-4, 0.0]]])
    materials = {name: DEMMaterial(rve=path, device="cpu", replicate=True, tangent=name)
                 for name in ("condensed", "condensed-sticking")}
    responses = {}
    for name, material in materials.items():
        material.allocate(2)
        responses[name] = material.evaluate(grad)
    sticking = responses["condensed-sticking"]
    np.testing.assert_array_equal(sticking.stress, responses["condensed"].stress)
    data = materials["condensed-sticking"].backend.batch.to_data()
    expected = condensed_tangent(data, sliding="stick").tangent + spin_tangent(sticking.stress)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(sticking.tangent, expected, rtol=0, atol=1e-9 * scale)
    assert np.abs(sticking.tangent - responses["condensed"].tangent).max() > 1e-3 * scale


def test_a_held_tangent_is_condensed_once_an_increment(sheared: RVEData, tmp_path,
                                                       monkeypatch) -> None:
    """``hold_tangent(True)``: the next evaluation condenses, the later ones (same or other
    ∇u) return that tangent, plus the rotation of their own stress, without condensing
    again; a revert or commit ends the hold. Under the Newton driver's ``tangent_update=
    "hold"`` the material holds and the run is the same, with one condensation a step."""
    from granular_material.dem import save_rve
    from granular_material.fem import (
        BiaxialSetup,
        NewtonSettings,
        NewtonSolver,
        build_biaxial,
    )
    from granular_material.multiscale import DEMMaterial, backend

    path = tmp_path / "sheared.npz"
    save_rve(path, sheared)
    condensations = []
    original = backend.condense
    monkeypatch.setattr(backend, "condense",
                        lambda *a: condensations.append(1) or original(*a))
    material = DEMMaterial(rve=path, device="cpu", replicate=True, tangent="condensed")
    material.allocate(2)
    first = np.array([[[1e-4, 0.0], [0.0, -1e-4]], [[0.0, 1e-4], [1e-4, 0.0]]])
    material.hold_tangent(True)
    held = material.evaluate(first)
    later = material.evaluate(2 * first)
    assert len(condensations) == 1
    np.testing.assert_allclose(later.tangent - spin_tangent(later.stress),
                               held.tangent - spin_tangent(held.stress), rtol=0, atol=1e-6)
    assert not np.allclose(later.stress, held.stress)
    material.revert()
    fresh = material.evaluate(2 * first)
    assert len(condensations) == 2
    scale = np.abs(fresh.tangent).max()
    assert np.abs(fresh.tangent - later.tangent).max() > 1e-6 * scale

    class CondensingEveryTime(DEMMaterial):
        hold_tangent = None  # the driver finds nothing to ask

    def single_element(hold_in_material: bool):
        kind = DEMMaterial if hold_in_material else CondensingEveryTime
        mat = kind(rve=path, device="cpu", tangent="condensed")
        problem = build_biaxial(BiaxialSetup(width=1.0, height=1.0, nx=1, ny=1,
                                             confining=100e3, axial_strain=0.002))
        settings = NewtonSettings(convergence="displacement", rtol=0.01,
                                  predictor="extrapolate", tangent_update="hold")
        solver = NewtonSolver(problem.basis, mat, problem.loading, settings)
        condensations.clear()
        records = solver.run(2)
        return solver.u, records, len(condensations)

    u_held, records_held, condensed_held = single_element(True)
    u_every, records_every, condensed_every = single_element(False)
    np.testing.assert_array_equal(u_held, u_every)
    assert [r.iterations for r in records_held] == [r.iterations for r in records_every]
    evaluations = sum(r.iterations for r in records_every)
    assert condensed_every >= evaluations > condensed_held


def _benchmark(name: str):
    """The module benchmarks/``name``.py, loaded from its file."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"{name}_bench", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_prediction_benchmark_smoke(tmp_path) -> None:
    """benchmarks/condensed_tangent.py at smoke size: every state, protocol and direction
    of one seed, finite errors, and the costs."""
    module = _benchmark("condensed_tangent")
    table = module.main(["--particles", "24", "--seeds", "1", "--hold", "200",
                         "--out", str(tmp_path)])
    assert len(table) == 3 * 3 * len(module.DIRECTIONS)
    errors = table[[c for c in table.columns if c.endswith("_err")]].to_numpy()
    assert np.isfinite(errors).all()
    assert (tmp_path / "prediction.md").exists() and (tmp_path / "cost.json").exists()


def test_sticking_predicts_an_unseen_increment_within_the_issues_bounds() -> None:
    """Issue 26's measure on one 100-disc RVE (seed 2): an unseen deviatoric increment of
    1e-4 (pure shear on and back), applied slowly and held (the benchmark's quasi-static
    protocol, less the drift), is predicted by ``sliding="stick"`` within 10 % at p0 and
    within 25 % right after a 1 % pure shear, with contacts still at their cap (benchmark,
    seeds 1–3: 1–3 % and 3–18 %); Kruyt–Rothenburg misses the sheared state by more."""
    module = _benchmark("condensed_tangent")
    hold = 2000
    states = module._states(100, [2], hold)
    for state, bound in (("p0", 0.10), ("shear", 0.25)):
        batch = DEMBatch(states[state], device="cpu")
        snap = batch.snapshot()
        sticking = condensed_tangent(states[state], sliding="stick").tangent[0]
        kr = batch.homogenize().tangent[0]
        for direction in ("pure-on", "pure-back"):
            grad = 1e-4 * module.DIRECTIONS[direction]
            dem = module._change(batch, snap, grad, "quasi-static", hold)[0]
            error = np.linalg.norm(np.einsum("ijkl,kl->ij", sticking, grad) - dem)
            kr_error = np.linalg.norm(np.einsum("ijkl,kl->ij", kr, grad) - dem)
            assert error < bound * np.linalg.norm(dem), (state, direction)
            if state == "shear":
                assert kr_error > 2 * error, (state, direction)


def test_newton_view_benchmark_smoke(tmp_path) -> None:
    """benchmarks/newton_tangent.py at smoke size: one seed, one state, every tangent
    against the path's derivative; the perturbation tangent (differences of the same path)
    is the closest."""
    module = _benchmark("newton_tangent")
    table = module.main(["--particles", "64", "--seeds", "1", "--strains", "0.5",
                         "--out", str(tmp_path)])
    assert sorted(table["tangent"]) == sorted(["kruyt-rothenburg", "objective", "condensed",
                                               "condensed-coulomb", "condensed-sticking",
                                               "perturbation"])
    assert np.isfinite(table["error %"]).all() and (table["J_xxxx MPa"] > 0).all()
    error = table.set_index("tangent")["error %"]
    assert error["perturbation"] < min(error["condensed"], error["kruyt-rothenburg"])
    assert (tmp_path / "newton_tangent.md").exists()
