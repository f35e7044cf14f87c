"""Newton driver: patch test, analytic plane-strain response, cut-back and recovery."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from run_helpers import CommittedStrain, top_loaded_element
from skfem import Basis, ElementQuad1, ElementVector, MeshQuad

from granular_material.fem import (
    BiaxialSetup,
    LinearElastic,
    Loading,
    MaterialResponse,
    NewtonError,
    NewtonSettings,
    NewtonSolver,
    PointStatus,
    build_biaxial,
)
from granular_material.fem.materials.linear_elastic import isotropic_tangent
from granular_material.results import COST_COLUMNS, BiaxialWriter
from granular_material.runs import run_biaxial


def _distorted_mesh() -> MeshQuad:
    mesh = MeshQuad.init_tensor(np.linspace(0, 2, 4), np.linspace(0, 1, 4))
    p = mesh.p.copy()
    interior = np.flatnonzero((p[0] > 0) & (p[0] < 2) & (p[1] > 0) & (p[1] < 1))
    p[:, interior] += np.random.default_rng(3).uniform(-0.1, 0.1, size=(2, interior.size))
    return MeshQuad(p, mesh.t)


def test_patch_test_reproduces_uniform_strain():
    """Linear boundary displacements u = G x on a distorted mesh → u = G x inside, σ uniform."""
    mesh = _distorted_mesh()
    basis = Basis(mesh, ElementVector(ElementQuad1()), intorder=2)
    grad = np.array([[1.0e-3, 4.0e-4], [-2.0e-4, -6.0e-4]])
    exact = np.zeros(basis.N)
    exact[basis.nodal_dofs[0]], exact[basis.nodal_dofs[1]] = grad @ mesh.p
    boundary = basis.get_dofs().flatten()
    loading = Loading(boundary, exact[boundary], np.zeros(basis.N), np.zeros(basis.N))
    material = LinearElastic(young=50e6, poisson=0.3)
    solver = NewtonSolver(basis, material, loading, NewtonSettings(rtol=1e-12))
    solver.run(1)
    np.testing.assert_allclose(solver.u, exact, rtol=0, atol=1e-10 * np.abs(exact).max())
    eps = 0.5 * (grad + grad.T)
    sigma = np.einsum("ijkl,kl->ij", isotropic_tangent(*material.parameters.lame), eps)
    stress = solver.response.stress
    assert np.abs(stress - sigma).max() <= 1e-10 * np.abs(sigma).max()
    np.testing.assert_allclose(solver.grad_u(), np.broadcast_to(grad, stress.shape),
                               atol=1e-10 * np.abs(grad).max())


def test_single_element_plane_strain_uniaxial_analytic():
    """σxx = −p held, εyy prescribed: Δσyy = E/(1−ν²) εyy and εxx = −ν/(1−ν) εyy.

    Closed form of plane-strain Hooke's law with Δσxx = 0 (ε_zz = 0).
    """
    e, nu, p, strain = 40e6, 0.25, 100e3, 0.01
    setup = BiaxialSetup(width=1.0, height=1.0, nx=1, ny=1, confining=p, axial_strain=strain)
    result = run_biaxial(setup, LinearElastic(young=e, poisson=nu, initial_stress=-p), 4)
    last = result.steps.iloc[-1]
    assert last["platen_stress"] == pytest.approx(p + e / (1 - nu**2) * strain, rel=1e-10)
    assert last["syy"] == pytest.approx(-last["platen_stress"], rel=1e-10)
    assert last["sxx"] == pytest.approx(-p, rel=1e-10)
    exx = result.points[result.points["step"] == 4]["exx"].to_numpy()
    np.testing.assert_allclose(exx, nu / (1 - nu) * strain, rtol=1e-10)
    assert (result.steps["iterations"].iloc[1:] == 1).all()  # a linear law: the predictor


class StiffeningElastic(CommittedStrain):
    """σ = (1 + ε:ε/ε0²) C:ε with a tangent frozen at the committed state.

    Written for the cut-back test: the frozen (too soft) tangent makes Newton's iteration a
    fixed-point iteration that converges only while the true stiffness over the increment
    stays below twice the committed one, i.e. it genuinely diverges for large increments.
    """

    def __init__(self, young: float = 10e6, poisson: float = 0.2, eps0: float = 2e-3):
        lam, mu = young * poisson / ((1 + poisson) * (1 - 2 * poisson)), young / (2 + 2 * poisson)
        self.c = isotropic_tangent(lam, mu)
        self.eps0 = eps0
        super().__init__()

    def _factor(self, strain):
        return 1.0 + np.einsum("nij,nij->n", strain, strain) / self.eps0**2

    def evaluate(self, grad_u):
        strain = self.strain + 0.5 * (grad_u + np.swapaxes(grad_u, 1, 2))
        self.trial = strain
        stress = self._factor(strain)[:, None, None] * np.einsum("ijkl,nkl->nij", self.c, strain)
        tangent = self._factor(self.strain)[:, None, None, None, None] * self.c
        return MaterialResponse(stress, tangent, np.zeros(self.n_points, dtype=np.int8))


def test_diverging_step_is_cut_back_and_recovers():
    # q = 20 kPa on E = 10 MPa: the final stiffening factor is about 1.4 (ε ≈ 1.3e-3 vs
    # ε0 = 2e-3), enough for one increment to diverge and for 32 increments not to
    settings = NewtonSettings(rtol=1e-6, max_iterations=40, max_cutbacks=8)
    basis, loading = top_loaded_element(q=20e3)
    big = NewtonSolver(basis, StiffeningElastic(), loading, settings)
    record = big.step(1.0, step=1)
    assert record.cutbacks >= 1
    assert any(len(h) == settings.max_iterations or h[-1] > 1 for h in record.residual_history)
    assert big.load_factor == 1.0
    # reference: the same load in 32 small steps, which converge without any cut-back
    small = NewtonSolver(basis, StiffeningElastic(), loading, settings)
    records = small.run(32)
    assert sum(r.cutbacks for r in records) == 0
    np.testing.assert_allclose(big.u, small.u, rtol=1e-4, atol=1e-4 * np.abs(small.u).max())
    # the solution is stiffer than the initial linear response (the law stiffens)
    linear = NewtonSolver(basis, LinearElastic(young=10e6, poisson=0.2), loading, settings)
    linear.run(1)
    assert np.abs(big.u).max() < np.abs(linear.u).max()


def test_cut_back_limit_names_the_step_and_keeps_committed_state():
    settings = NewtonSettings(rtol=1e-6, max_iterations=40, max_cutbacks=0)
    basis, loading = top_loaded_element(q=20e3)
    material = StiffeningElastic()
    solver = NewtonSolver(basis, material, loading, settings)
    solver.step(0.05, step=1)  # a small first step converges
    committed_u, committed_strain = solver.u.copy(), material.strain.copy()
    with pytest.raises(NewtonError, match="load step 2") as info:
        solver.step(1.0, step=2)
    assert solver.load_factor == 0.05
    np.testing.assert_array_equal(solver.u, committed_u)
    np.testing.assert_array_equal(material.strain, committed_strain)
    assert [r.step for r in info.value.records] == [1, 2]


class _WrappedElastic:
    """A linear-elastic material that subclasses alter in ``evaluate`` only."""

    def __init__(self, inner: LinearElastic):
        self.inner = inner

    n_points = property(lambda self: self.inner.n_points)

    def allocate(self, n):
        self.inner.allocate(n)

    def evaluate(self, grad_u):
        return self.inner.evaluate(grad_u)

    def commit(self):
        self.inner.commit()

    def revert(self):
        self.inner.revert()

    def checkpoint(self, path):
        self.inner.checkpoint(path)

    def restore(self, path):
        self.inner.restore(path)


class _FailsAbove(_WrappedElastic):
    """Linear elastic, but reports FAILED at every point when max|∇u| exceeds a limit."""

    def __init__(self, limit: float):
        super().__init__(LinearElastic())
        self.limit = limit

    def evaluate(self, grad_u):
        r = self.inner.evaluate(grad_u)
        if np.abs(grad_u).max() > self.limit:
            return MaterialResponse(r.stress, r.tangent,
                                    np.full(r.status.shape, PointStatus.FAILED, dtype=np.int8))
        return r


def test_failed_points_trigger_cut_back():
    problem = build_biaxial(BiaxialSetup(width=1, height=1, nx=1, ny=1, confining=0.0,
                                         axial_strain=0.01))
    solver = NewtonSolver(problem.basis, _FailsAbove(limit=3e-3), problem.loading)
    record = solver.step(1.0, step=1)
    # 1 % → 0.5 % → 0.25 % per increment (below the 0.3 % limit), then regrowth is refused
    assert record.cutbacks >= 2
    assert solver.load_factor == 1.0
    np.testing.assert_allclose(solver.grad_u()[:, 1, 1], -0.01, rtol=1e-10)


class _OneBlowsUp(_WrappedElastic):
    """Linear elastic, but once loaded its last point blows up and the others are aborted
    with it (as a DEM batch answers when one RVE blows up)."""

    def __init__(self):
        super().__init__(LinearElastic())

    def evaluate(self, grad_u):
        r = self.inner.evaluate(grad_u)
        if not np.any(grad_u):
            return r
        n = r.status.shape[0]
        reasons = np.array(["aborted"] * (n - 1) + ["blow_up"], dtype=object)
        return MaterialResponse(r.stress, r.tangent,
                                np.full(n, PointStatus.FAILED, dtype=np.int8), reasons=reasons)


def test_a_failed_step_names_the_point_that_failed_not_those_aborted_with_it():
    problem = build_biaxial(BiaxialSetup(width=1, height=1, nx=2, ny=2, confining=0.0,
                                         axial_strain=0.01))
    solver = NewtonSolver(problem.basis, _OneBlowsUp(), problem.loading)
    with pytest.raises(NewtonError, match=r"material failed at points \[15\] "
                                          r"\(aborted: 15, blow_up: 1\)"):
        solver.step(1.0, step=1)


class _Costly(_FailsAbove):
    """:class:`_FailsAbove` with costs of its own names: one call and 0.25 units of work an
    evaluation (a failed one too), and 3 "dem_steps" an evaluation that fails."""

    def evaluate(self, grad_u):
        response = super().evaluate(grad_u)
        costs = {"calls": np.int64(1), "work": 0.25}
        if not response.ok:
            costs["dem_steps"] = 3
        return replace(response, costs=costs)


def test_the_driver_sums_each_cost_and_the_table_carries_the_cost_columns():
    """The driver knows no cost by name: each is summed over the evaluations of a step,
    failed attempts included; the steps table carries COST_COLUMNS (0 where the material
    reports none) and no column for the other names."""
    setup = BiaxialSetup(width=1, height=1, nx=1, ny=1, confining=0.0, axial_strain=0.01)
    result = run_biaxial(setup, _Costly(limit=3e-3), 2)
    steps = result.steps.set_index("step")
    for record in result.records:
        assert record.cutbacks >= 1
        assert record.costs == {"calls": record.iterations, "work": 0.25 * record.iterations,
                                "dem_steps": 3 * record.cutbacks}
        assert type(record.costs["calls"]) is int
        row = steps.loc[record.step]
        assert row["dem_steps"] == 3 * record.cutbacks
        assert row["rve_evaluations"] == row["particle_steps"] == 0
    assert list(result.steps.columns[11:15]) == ["iterations", *COST_COLUMNS]
    assert "calls" not in result.steps and "work" not in result.steps
    elastic = run_biaxial(setup, LinearElastic(), 1)
    assert elastic.records[0].costs == {}
    assert (elastic.steps[list(COST_COLUMNS)] == 0).all(axis=None)


def test_full_scale_specimen_mesh_with_linear_elastic():
    """Wu et al.'s specimen: 50 mm × 100 mm, 10 × 15 Q4, 600 Gauss points (docs/design.md#wu-2025).

    With a linear-elastic material the smooth-platen test stays homogeneous, so the platen
    stress is the plane-strain closed form p + E/(1−ν²) ε_a.
    """
    setup = BiaxialSetup()
    problem = build_biaxial(setup)
    assert setup.n_points == 600 == problem.weights.size
    assert problem.weights.sum() == pytest.approx(0.05 * 0.10, rel=1e-12)
    result = run_biaxial(setup, LinearElastic(young=30e6, poisson=0.3, initial_stress=-100e3),
                         2)
    expected = 100e3 + 30e6 / (1 - 0.3**2) * 0.10
    assert result.steps["platen_stress"].iloc[-1] == pytest.approx(expected, rel=1e-9)
    last = result.points[result.points["step"] == 2]
    np.testing.assert_allclose(last["syy"], -expected, rtol=1e-9)


def test_rough_platens_hold_the_ends_and_stiffen_the_specimen():
    """Rough platens stop the ends spreading: the specimen barrels, the platen stress is above
    the smooth-platen closed form, and no platen node moves sideways."""
    material = LinearElastic(young=30e6, poisson=0.3, initial_stress=-100e3)
    smooth = run_biaxial(BiaxialSetup(nx=4, ny=8, axial_strain=0.01), material, 1)
    setup = BiaxialSetup(nx=4, ny=8, axial_strain=0.01, platens="rough")
    rough = run_biaxial(setup, LinearElastic(young=30e6, poisson=0.3, initial_stress=-100e3), 1)
    closed_form = 100e3 + 30e6 / (1 - 0.3**2) * 0.01
    assert smooth.steps["platen_stress"].iloc[-1] == pytest.approx(closed_form, rel=1e-9)
    assert rough.steps["platen_stress"].iloc[-1] > 1.01 * closed_form
    basis = build_biaxial(setup).basis
    ux = rough.displacements[-1][basis.nodal_dofs[0]]
    y = basis.mesh.p[1]
    ends = (y < 1e-12) | (y > 0.1 - 1e-12)
    assert np.abs(ux[ends]).max() == 0 and np.abs(ux[~ends]).max() > 1e-6
    with pytest.raises(ValueError, match="platens"):
        BiaxialSetup(platens="glued")


def test_an_interrupted_biaxial_run_keeps_and_writes_its_committed_steps(tmp_path):
    def stop_after_two(solver, record, points):
        if record.step == 2:
            raise KeyboardInterrupt

    with BiaxialWriter(tmp_path) as writer:
        result = run_biaxial(BiaxialSetup(nx=1, ny=2), LinearElastic(young=30e6, poisson=0.3),
                             5, on_step=stop_after_two, observer=writer)
    assert result.error == "interrupted after load step 2 of 5"
    assert result.steps["step"].tolist() == [0, 1, 2]
    assert len(pd.read_csv(tmp_path / "steps.csv")) == 3


class _NoisyElastic(_WrappedElastic):
    """Linear elastic plus a stress noise of ``amplitude`` [Pa] that changes with every ∇u
    (seeded by its bytes): like a DEM RVE, the same ∇u gives the same stress, any other ∇u a
    fresh draw, so Newton's residual settles on a floor set by the noise."""

    def __init__(self, amplitude: float):
        super().__init__(LinearElastic(young=50e6, poisson=0.3))
        self.amplitude = amplitude

    def evaluate(self, grad_u):
        r = self.inner.evaluate(grad_u)
        seed = int.from_bytes(np.ascontiguousarray(grad_u).tobytes()[-64:], "little") % 2**63
        noise = np.random.default_rng(seed).uniform(-1, 1, r.stress.shape)
        noise = 0.5 * (noise + np.swapaxes(noise, 1, 2))
        return MaterialResponse(r.stress + self.amplitude * noise, r.tangent, r.status)


def _noisy_solver(stall_rtol: float) -> NewtonSolver:
    problem = build_biaxial(BiaxialSetup(width=1, height=2, nx=2, ny=4, confining=0.0,
                                         axial_strain=0.01))
    # the 0.5 MPa step load against a 1 kPa noise: a floor near 2e-3 of ‖R₀‖
    settings = NewtonSettings(rtol=1e-4, stall_rtol=stall_rtol, max_iterations=30,
                              max_cutbacks=1)
    return NewtonSolver(problem.basis, _NoisyElastic(1e3), problem.loading, settings)


def test_stalled_residual_is_accepted_only_when_asked_and_counted():
    with pytest.raises(NewtonError, match="not converged"):
        _noisy_solver(0.0).step(1.0, step=1)
    solver = _noisy_solver(0.02)
    record = solver.step(1.0, step=1)
    assert record.stalled == 1 and record.cutbacks == 0
    history = record.residual_history[-1]
    assert 1e-4 < history[-1] <= 0.02 and len(history) > solver.settings.stall_window
    # the accepted state is the elastic solution up to the noise
    exact = NewtonSolver(solver.basis, LinearElastic(young=50e6, poisson=0.3), solver.loading)
    exact.step(1.0, step=1)
    assert np.abs(solver.u - exact.u).max() < 0.01 * np.abs(exact.u).max()


def test_stall_tolerance_is_checked():
    with pytest.raises(ValueError, match="stall_rtol"):
        NewtonSettings(rtol=0.005, stall_rtol=0.001)
    with pytest.raises(ValueError, match="stall_window"):
        NewtonSettings(stall_window=1)
