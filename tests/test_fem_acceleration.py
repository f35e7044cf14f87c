"""Aitken relaxation and secant tangents for Newton when the tangent is stiffer than the
material."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from granular_material.fem import (
    BiaxialSetup,
    MaterialResponse,
    NewtonError,
    NewtonSettings,
    NewtonSolver,
    build_biaxial,
)
from granular_material.fem.forms import stiffness
from granular_material.fem.materials.linear_elastic import isotropic_tangent
from granular_material.fem.solver import newton
from granular_material.fem.solver.acceleration import AitkenRelaxation, SecantTangent


def test_aitken_learns_the_factor_of_a_uniformly_too_stiff_tangent():
    # A x = b with the "tangent" 10 A: plain corrections are a tenth of what is needed
    a, b = np.diag([1.0, 2.0, 3.0]), np.array([1.0, -1.0, 2.0])
    x, relax = np.zeros(3), AitkenRelaxation()
    for _ in range(4):
        x = relax.update(x, np.linalg.solve(10 * a, b - a @ x))
    np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-12)
    assert relax.omega == pytest.approx(10.0)
    with pytest.raises(ValueError, match="lower"):
        AitkenRelaxation(lower=2.0)


class _Caricature:
    """A small-strain material whose tangent always reports one isotropic C [Pa] while its
    stress is :meth:`stress_of` the strain: the bookkeeping the caricatures below share."""

    def __init__(self, n_points: int):
        self.c = isotropic_tangent(20e6, 15e6)
        self.strain = np.zeros((n_points, 2, 2))
        self.trial = None

    n_points = property(lambda self: self.strain.shape[0])

    def allocate(self, n_points: int) -> None:
        assert n_points == self.n_points

    def stress_of(self, strain: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def evaluate(self, grad_u):
        self.trial = self.strain + 0.5 * (grad_u + np.swapaxes(grad_u, 1, 2))
        tangent = np.broadcast_to(self.c, (self.n_points, 2, 2, 2, 2))
        return MaterialResponse(self.stress_of(self.trial), tangent,
                                np.zeros(self.n_points, dtype=np.int8))

    def commit(self):
        self.strain = self.trial

    def revert(self):
        self.trial = None

    def checkpoint(self, path):
        np.save(path, self.strain)

    def restore(self, path):
        self.strain = np.load(path)


class BandSoftened(_Caricature):
    """Linear elastic whose true stiffness is ``soft`` · C inside a band and ``hard`` · C
    outside, while its tangent always reports C: the Kruyt–Rothenburg tangent of a sheared
    specimen in caricature (too stiff everywhere, most of all inside the band).
    """

    def __init__(self, in_band: np.ndarray, soft: float = 0.05, hard: float = 0.5):
        super().__init__(in_band.size)
        self.factor = np.where(in_band, soft, hard)

    def stress_of(self, strain: np.ndarray) -> np.ndarray:
        return self.factor[:, None, None] * np.einsum("ijkl,nkl->nij", self.c, strain)


def _band_problem(relaxation: str, tangent_update: str = "none") -> NewtonSolver:
    problem = build_biaxial(BiaxialSetup(width=1.0, height=2.0, nx=4, ny=8, confining=0.0,
                                         axial_strain=0.01))
    xy = problem.basis.global_coordinates()  # (2, nelems, nqp)
    x, y = (np.asarray(xy[i]).reshape(-1) for i in range(2))  # element-major, as the layout
    in_band = np.abs(y - 0.5 - x) < 0.3
    settings = NewtonSettings(rtol=1e-6, max_iterations=40, max_cutbacks=0,
                              relaxation=relaxation, tangent_update=tangent_update)
    return NewtonSolver(problem.basis, BandSoftened(in_band), problem.loading, settings)


def test_aitken_converges_where_a_too_stiff_tangent_stalls_plain_newton():
    # plain corrections shrink the error by 5 % per iteration inside the band
    with pytest.raises(NewtonError, match="not converged in 40 iterations"):
        _band_problem("none").step(1.0, step=1)
    relaxed = _band_problem("aitken")
    record = relaxed.step(1.0, step=1)
    assert record.cutbacks == 0 and record.iterations <= 25
    # the converged state is the solution of the softened linear problem: two half steps
    # reach the same displacements
    reference = _band_problem("aitken")
    reference.step(0.5, step=1)
    reference.step(1.0, step=2)
    np.testing.assert_allclose(relaxed.u, reference.u, atol=1e-5 * np.abs(reference.u).max())


class Saturating(_Caricature):
    """Stress C:ε scaled so that its norm saturates at ``cap`` [Pa] (‖σ‖ = cap·tanh(‖C:ε‖ /
    cap)), while its tangent reports C: past the cap it stops answering, as a DEM RVE that
    loses its confinement; ``largest`` is the largest |∇u| it was asked to evaluate."""

    def __init__(self, n_points: int, cap: float):
        super().__init__(n_points)
        self.cap = cap
        self.evaluations, self.largest = 0, 0.0

    def evaluate(self, grad_u):
        self.evaluations += 1
        self.largest = max(self.largest, float(np.abs(grad_u).max()))
        return super().evaluate(grad_u)

    def stress_of(self, strain: np.ndarray) -> np.ndarray:
        linear = np.einsum("ijkl,nkl->nij", self.c, strain)
        norm = np.maximum(np.linalg.norm(linear, axis=(1, 2)), 1e-30)[:, None, None]
        return linear * self.cap * np.tanh(norm / self.cap) / norm


def _saturating_problem(confining: float, max_growth: float) -> NewtonSolver:
    """A 2 × 4 biaxial specimen of :class:`Saturating` (cap 100 kPa) under ``confining``,
    Aitken and the extrapolating predictor, no cut-backs."""
    problem = build_biaxial(BiaxialSetup(width=1.0, height=2.0, nx=2, ny=4,
                                         confining=confining, axial_strain=0.01))
    n_points = problem.basis.nelems * len(problem.basis.quadrature[1])
    settings = NewtonSettings(max_cutbacks=0, relaxation="aitken", predictor="extrapolate",
                              max_growth=max_growth)
    return NewtonSolver(problem.basis, Saturating(n_points, 1e5), problem.loading, settings)


def test_corrections_that_keep_growing_the_increment_are_stopped_before_evaluated():
    """Confined beyond what the material can carry (200 kPa against a cap of 100 kPa), the
    corrections never shrink and Aitken's factor grows: without the limit the iterates
    reach |∇u| > 1 in a step of 0.1 % axial strain and use all 25 evaluations; with it the
    increment is abandoned at its third, named, before the material sees the iterate."""
    unlimited = _saturating_problem(2e5, max_growth=1e12)
    with pytest.raises(NewtonError, match="not converged in 25"):
        unlimited.step(0.1, step=1)
    assert unlimited.material.evaluations == 26 and unlimited.material.largest > 1.0
    limited = _saturating_problem(2e5, max_growth=10.0)
    with pytest.raises(NewtonError, match=r"grew the increment to [\d.]+ times the first"):
        limited.step(0.1, step=1)
    assert limited.material.evaluations <= 4 and limited.material.largest < 0.01
    # where the material can carry the load the limit changes nothing
    runs = [_saturating_problem(5e4, max_growth=g) for g in (10.0, 1e12)]
    for run in runs:
        run.step(0.1, step=1)
    np.testing.assert_array_equal(runs[0].u, runs[1].u)
    with pytest.raises(ValueError, match="max_growth"):
        NewtonSettings(max_growth=1.0)


def test_secant_tangent_recovers_a_linear_response_along_orthogonal_changes():
    rng = np.random.default_rng(3)
    true = rng.normal(size=(2, 4, 4)) * 1e7
    start = rng.normal(size=(2, 4, 4)) * 1e7

    def stress(g):
        return np.einsum("pij,pj->pi", true, g.reshape(2, 4)).reshape(2, 2, 2)

    zero = np.zeros((2, 2, 2))
    secant = SecantTangent(zero, stress(zero), start.reshape(2, 2, 2, 2, 2))
    g = zero
    for k in range(4):  # each update fixes one direction and leaves the orthogonal ones
        g = g + 1e-3 * np.eye(4)[k].reshape(2, 2)
        tangent = secant.update(g, stress(g))
    np.testing.assert_allclose(tangent.reshape(2, 4, 4), true, rtol=1e-9)
    assert secant.updated.all()


def test_secant_tangent_ignores_changes_below_the_noise_floor():
    c = np.broadcast_to(isotropic_tangent(20e6, 15e6), (3, 2, 2, 2, 2))
    zero = np.zeros((3, 2, 2))
    secant = SecantTangent(zero, zero, c, min_change=1e-6)
    g = np.zeros((3, 2, 2))
    g[0, 0, 0], g[1, 0, 0] = 1e-7, 1e-3
    noisy = np.full((3, 2, 2), 50.0)  # Pa of noise, nothing of the stiffness
    tangent = secant.update(g, noisy)
    np.testing.assert_array_equal(tangent[[0, 2]], c[[0, 2]])
    assert not np.allclose(tangent[1], c[1])
    assert secant.updated.tolist() == [False, True, False]
    with pytest.raises(ValueError, match="min_change"):
        SecantTangent(zero, zero, c, min_change=0.0)


def test_secant_tangent_learns_the_softened_band():
    """The rank-one updates replace the reported (too stiff) tangent by the band's own
    stiffness: at Wu et al.'s tolerance the secant tangent needs a third of plain Newton's
    iterations, and driven on to a tight tolerance it reaches the softened solution."""
    def iterations(relaxation, tangent_update):
        solver = _band_problem(relaxation, tangent_update)
        solver.settings = replace(solver.settings, rtol=0.005)
        return solver.step(1.0, step=1).iterations

    plain, aitken, secant = (iterations("none", "none"), iterations("aitken", "none"),
                             iterations("none", "secant"))
    assert 3 * secant <= plain and secant <= aitken
    tight = _band_problem("none", tangent_update="secant")  # no noise: every change counts
    tight.settings = replace(tight.settings, secant_min_change=1e-12)
    assert tight.step(1.0, step=1).cutbacks == 0
    reference = _band_problem("aitken")
    reference.step(0.5, step=1)
    reference.step(1.0, step=2)
    np.testing.assert_allclose(tight.u, reference.u, atol=1e-4 * np.abs(reference.u).max())


class DriftingTangent(BandSoftened):
    """Linear elastic (C) whose reported tangent drifts with every evaluation since the last
    commit or revert, (2 + k)·C at the k-th: a tangent that changes with the iterate, as the
    condensed one does when contacts switch between sticking and sliding."""

    def __init__(self, n_points: int):
        super().__init__(np.zeros(n_points, dtype=bool), soft=1.0, hard=1.0)
        self.evaluations = 0

    def evaluate(self, grad_u):
        response = super().evaluate(grad_u)
        factor = 2.0 + self.evaluations
        self.evaluations += 1
        return MaterialResponse(response.stress, factor * np.asarray(response.tangent),
                                response.status)

    def commit(self):
        super().commit()
        self.evaluations = 0

    def revert(self):
        super().revert()
        self.evaluations = 0


def test_a_held_tangent_is_the_first_evaluations_for_every_correction(monkeypatch):
    """``tangent_update="hold"``: every correction of an increment is solved with the
    tangent of its first evaluation (modified Newton), so a tangent that drifts with the
    iterate does not hold it back: 2C throughout halves the error every iteration, while
    2C, 3C, 4C, ... shrinks it only as 1/k."""
    # a confining pressure: the load a scaled tangent gets wrong (a prescribed displacement
    # alone it would get right, whatever the scale)
    problem = build_biaxial(BiaxialSetup(width=1.0, height=2.0, nx=1, ny=2, confining=1e5,
                                         axial_strain=0.01))
    n_points = problem.basis.nelems * problem.basis.X.shape[-1]
    assembled = []  # the tangents the stiffness matrices are assembled from
    monkeypatch.setattr(newton, "stiffness",
                        lambda basis, tangent: assembled.append(tangent)
                        or stiffness(basis, tangent))

    def solver(material, tangent_update):
        settings = NewtonSettings(rtol=1e-6, max_iterations=60, max_cutbacks=0,
                                  tangent_update=tangent_update)
        return NewtonSolver(problem.basis, material, problem.loading, settings)

    held = solver(DriftingTangent(n_points), "hold")
    record = held.step(1.0, step=1)
    base = np.broadcast_to(2 * isotropic_tangent(20e6, 15e6), (n_points, 2, 2, 2, 2))
    # the committed state's tangent (the predictor), then the corrections' (all the first's)
    assert len(assembled) == record.iterations
    for tangent in assembled:
        np.testing.assert_allclose(tangent, base)
    assert record.iterations <= 22  # 2**-20 ≈ 1e-6
    exact = solver(BandSoftened(np.zeros(n_points, dtype=bool), soft=1.0, hard=1.0), "none")
    exact.step(1.0, step=1)
    np.testing.assert_allclose(held.u, exact.u, atol=1e-5 * np.abs(exact.u).max())
    assembled.clear()
    with pytest.raises(NewtonError, match="not converged in 60"):
        solver(DriftingTangent(n_points), "none").step(1.0, step=1)
    assert not np.allclose(assembled[-1], assembled[1])
