"""The geostatic start of real ground: a sloping or stepped surface, layers of their own unit
weight and K0, brought into discrete equilibrium; and the floor of its least compression.

Tension positive, Pa, batch-first (n, 2, 2), plane strain. Three stages, each a function:

1. **The overburden column** (:func:`overburden`). At every Gauss point (x, y), σv is the
   surcharge q on the surface plus the weight of the body straight above it:
   σv = q + ∫ γ dy from y up to the ground surface along the vertical x, each element's own
   unit weight γ_e [N/m³] over the length of the vertical inside it (the corners' straight
   sides: every mesh here is straight-sided). The surface is the mesh's own upper boundary
   above the point's x; no height is given. A vertical that leaves the body and enters it
   again above the point (an overhang, a cavity) has no overburden column: refused, naming
   the point. A point outside the body (above its surface, beside it) is refused too.
2. **The column state** (:func:`column_stress`): σyy = −σv, σxx = K0·σyy, no shear, K0 the
   point's own (its region's). Under a level surface with one unit weight this is the exact
   K0 state of level ground (in discrete equilibrium, see
   :mod:`~granular_material.fem.boundary_value.initial_stress`). Under a slope, a step or a
   jagged layer boundary it is not: the shear that carries the weight towards the free face
   is missing, and the residual is of the order of the load (3.8 times it on a 1:1.5
   embankment).
3. **The equilibrium correction** (:func:`equilibrium_correction`). One linear solve, the
   problem's own supports held at zero displacement: an isotropic linear-elastic body, one
   Young's modulus E for the whole mesh and Poisson's ratio ν = K0/(1 + K0) at each point
   (the ν whose one-dimensional compression in plane strain gives σh/σv = K0; at most
   :data:`MAX_POISSON`), loaded by the residual R = f_ext − f_int of the column state. Its
   stress Δσ = D(ν):ε(Δu) is added: K Δu = R makes the sum's residual zero to round-off on
   every free degree of freedom, whatever the loads (a surcharge, pressures on the sides,
   each region's own weight). Δu is proportional to 1/E and Δσ to E/E: the correction does
   not depend on E. With layers it does depend on the ratio of their stiffnesses, taken
   here as 1 (one E): the correction is the one a body of uniform stiffness would carry.
   The real layers' stiffnesses (and the ground's history) would share it otherwise; the
   corrected state is *a* state in equilibrium near the column state, not the in-situ one.
   It may lie outside a material's strength near a steep face (Mohr–Coulomb then refuses
   it, naming the points).

:func:`ground_stress` does all three for a
:class:`~granular_material.fem.boundary_value.conditions.Problem`. Under a level surface
(every column reaching the same height) with one unit weight and one K0 it returns the
field of :func:`~granular_material.fem.boundary_value.initial_stress.geostatic_stress`, bit
for bit, and solves nothing (that field is already in discrete equilibrium).

**The floor** (:func:`lift_to_floor`). At the free surface σ → 0, and after the correction
a point near a steep face may even be in tension. A DEM RVE cannot be prepared there (a
packing of discs carries stress only while confined). A point whose least principal
compression is below its floor p_min is lifted by an isotropic pressure to p_min:
σ ← σ − (p_min − σ3)·I, σ3 its least principal compression; the deviator (the shear) is
kept. The lift adds a residual of the order of p_min times the lifted points' area.

Measured (the tests' layered slope: 90 m wide, a 15 m crest, 1:1.5 down to a 5 m toe, a
3 m foundation layer of its own γ and K0; quad8, 360 elements): the column state's residual
0.126 times the load, the corrected one 9e-15 times it (0.02 s); σv of the corrected state
within 0.6 % of the column's 30 m and more from the slope's face (1.7 % at 10 m from the
toe); σh/σv under the crest 0.46 for K0 = 0.5 (the slope's horizontal thrust, shared by the
side supports), 0.52 under the toe. A stepped surface (a vertical face): the column 0.32
times the load, corrected 5e-16.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse.linalg import spsolve
from skfem import Basis
from skfem.mesh import Mesh

from granular_material.errors import ParameterError
from granular_material.fem.boundary_value.initial_stress import geostatic_stress
from granular_material.fem.forms import gauss_points_grad, internal_force, stiffness
from granular_material.typed_fields import conform

__all__ = ["MAX_POISSON", "GroundState", "Overburden", "column_stress", "elastic_tangent",
           "equilibrium_correction", "ground_stress", "lift_to_floor", "overburden",
           "poisson_of_k0"]

#: the largest Poisson's ratio of the correction's body: ν = K0/(1 + K0) reaches 0.5 (an
#: incompressible body, no stiffness matrix) at K0 = 1; K0 >= 0.96 takes 0.49
MAX_POISSON = 0.49
#: pairs (point, element) of the column integration handled at once
_CHUNK = 1 << 20


@dataclass(frozen=True)
class Overburden:
    """The overburden column of every point.

    Attributes:
        sigma_v: σv [Pa] (n,), compression positive: the surcharge plus the weight above.
        surface: the height of the ground surface above each point [m] (n,).
    """

    sigma_v: np.ndarray
    surface: np.ndarray


def _xy(points_xy: np.ndarray) -> np.ndarray:
    given = np.asarray(points_xy)
    if given.dtype.kind not in "biuf" or given.ndim != 2 or given.shape[1] != 2:
        raise ParameterError("points_xy", f"must be real coordinates [m] of shape (n, 2), got "
                                          f"{given.dtype} of shape {given.shape}")
    xy = given.astype(np.float64)
    if not np.isfinite(xy).all():
        raise ParameterError("points_xy", "holds coordinates that are not finite")
    return xy


def _per(name: str, value: object, n: int, what: str, low: float = 0.0,
         strict: bool = False) -> np.ndarray:
    """``value`` (a number or an array of ``n``) as (n,) float64, finite and >= ``low``
    (> with ``strict``)."""
    if np.ndim(value) == 0:
        value = conform(name, value, float)
    array = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)) if np.ndim(value) == 0 \
        else np.asarray(value, dtype=np.float64)
    if array.shape != (n,):
        raise ParameterError(name, f"must be a number or one value per {what} ({n}), got "
                                   f"shape {array.shape}")
    bad = ~np.isfinite(array) | ((array <= low) if strict else (array < low))
    if bad.any():
        raise ParameterError(name, f"must be finite and {'>' if strict else '>='} {low:g} "
                                   f"at every {what}, got {array[bad][0]!r}")
    return array


def overburden(mesh: Mesh, points_xy: np.ndarray, unit_weight: float | np.ndarray,
               surcharge: float = 0.0) -> Overburden:
    """σv [Pa] at ``points_xy`` [m] (n, 2) from the column of ``mesh`` above each: the
    surcharge q [Pa] plus Σ γ_e × (the length of the vertical inside element e above the
    point), ``unit_weight`` γ [N/m³] one number or one per element (see the module
    docstring). ParameterError for a point outside the body or whose vertical leaves the
    body and enters it again above it (no surface to measure from)."""
    xy = _xy(points_xy)
    corners = np.asarray(mesh.t)
    p = np.asarray(mesh.p, dtype=np.float64)
    n_elem = corners.shape[1]
    gamma = _per("unit_weight", unit_weight, n_elem, "element")
    q = _per("surcharge", surcharge, 1, "surface")[0]
    x_c, y_c = p[0][corners], p[1][corners]  # (k, e)
    x_lo, x_hi = x_c.min(axis=0), x_c.max(axis=0)
    order = np.argsort(xy[:, 0], kind="stable")
    xs = xy[order, 0]
    start = np.searchsorted(xs, x_lo, side="left")
    counts = np.searchsorted(xs, x_hi, side="left") - start  # points with x_lo <= x < x_hi
    n = xy.shape[0]
    weight = np.zeros(n)
    inside = np.zeros(n)  # the length of the vertical inside the body above the point
    surface = np.full(n, -np.inf)
    held = np.zeros(n, dtype=bool)  # the point lies in some element's vertical span
    ends = np.cumsum(counts)
    total = int(ends[-1]) if n_elem else 0
    k = corners.shape[0]
    for first in range(0, total, _CHUNK):
        pair = np.arange(first, min(first + _CHUNK, total))
        elem = np.searchsorted(ends, pair, side="right")
        point = order[start[elem] + pair - (ends[elem] - counts[elem])]
        x, y = xy[point, 0], xy[point, 1]
        low = np.full(pair.size, np.inf)
        high = np.full(pair.size, -np.inf)
        for a in range(k):  # each straight side; half-open in x: a vertex counts once
            b = (a + 1) % k
            xa, xb = x_c[a, elem], x_c[b, elem]
            ya, yb = y_c[a, elem], y_c[b, elem]
            crosses = (np.minimum(xa, xb) <= x) & (x < np.maximum(xa, xb))
            with np.errstate(divide="ignore", invalid="ignore"):
                at = ya + (x - xa) * (yb - ya) / (xb - xa)
            low = np.where(crosses, np.minimum(low, at), low)
            high = np.where(crosses, np.maximum(high, at), high)
        length = np.maximum(high - np.maximum(low, y), 0.0)
        weight += np.bincount(point, weights=gamma[elem] * length, minlength=n)
        inside += np.bincount(point, weights=length, minlength=n)
        np.maximum.at(surface, point, high)
        scale = 1e-9 * np.maximum(high - low, 1.0)
        held[point[(low - scale <= y) & (y <= high + scale)]] = True
    _check_columns(xy, held, surface, inside, p)
    return Overburden(q + weight, surface)


def _check_columns(xy: np.ndarray, held: np.ndarray, surface: np.ndarray,
                   inside: np.ndarray, p: np.ndarray) -> None:
    """ParameterError for a point outside the body or whose column has a gap."""
    outside = np.flatnonzero(~held)
    if outside.size:
        i = int(outside[0])
        raise ParameterError("points_xy", f"{outside.size} points lie outside the body (above "
                                          f"its surface or beside it), the first at "
                                          f"({xy[i, 0]:.6g}, {xy[i, 1]:.6g}) m: the overburden "
                                          "is measured from points of the mesh")
    size = float(np.ptp(p[1]) + np.ptp(p[0]))
    gap = (surface - xy[:, 1]) - inside
    gapped = np.flatnonzero(gap > 1e-9 * size)
    if gapped.size:
        i = int(gapped[0])
        raise ParameterError("mesh", f"the vertical above {gapped.size} points leaves the body "
                                     f"and enters it again (an overhang or a cavity: "
                                     f"{gap[i]:.4g} m of it outside the body between the "
                                     f"point ({xy[i, 0]:.6g}, {xy[i, 1]:.6g}) m and the top "
                                     f"at y = {surface[i]:.6g} m), so the ground surface above it "
                                     "cannot be found and its overburden is not a column; "
                                     "start uniform, or mesh the ground without it")


def column_stress(sigma_v: np.ndarray, k0: float | np.ndarray) -> np.ndarray:
    """σ [Pa] (n, 2, 2), tension positive: σyy = −σv, σxx = K0·σyy, no shear; ``sigma_v``
    [Pa] (n,) compression positive, ``k0`` [-] > 0 one number or one per point."""
    sv = np.asarray(sigma_v, dtype=np.float64)
    k0 = _per("k0", k0, sv.shape[0], "point", strict=True)
    out = np.zeros((sv.shape[0], 2, 2))
    out[:, 1, 1] = -sv
    out[:, 0, 0] = k0 * -sv
    return out


def poisson_of_k0(k0: float | np.ndarray) -> np.ndarray:
    """ν = K0/(1 + K0), at most :data:`MAX_POISSON`: the Poisson's ratio whose plane-strain
    one-dimensional compression gives σh/σv = K0."""
    k0 = np.asarray(k0, dtype=np.float64)
    return np.minimum(k0 / (1.0 + k0), MAX_POISSON)


def elastic_tangent(poisson: np.ndarray, young: float = 1.0) -> np.ndarray:
    """D [Pa] (n, 2, 2, 2, 2) of isotropic plane-strain elasticity acting on ∇u:
    D_ijkl = λ δij δkl + μ (δik δjl + δil δjk), ν per point, one E [Pa]."""
    nu = np.asarray(poisson, dtype=np.float64)
    lam = young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = young / (2.0 * (1.0 + nu))
    eye = np.eye(2)
    iso = np.einsum("ij,kl->ijkl", eye, eye)
    sym = np.einsum("ik,jl->ijkl", eye, eye) + np.einsum("il,jk->ijkl", eye, eye)
    return lam[:, None, None, None, None] * iso + mu[:, None, None, None, None] * sym


def equilibrium_correction(basis: Basis, stress: np.ndarray, force: np.ndarray,
                           fixed: np.ndarray, poisson: np.ndarray,
                           ) -> tuple[np.ndarray, float, float]:
    """Δσ [Pa] (n, 2, 2) that brings ``stress`` [Pa] (n, 2, 2) into equilibrium with the
    nodal forces ``force`` [N/m] (ndofs,) on every dof but ``fixed`` (held at zero): the
    stress of the linear-elastic body (one E, ``poisson`` ν per point) under the residual
    (see the module docstring); and ‖R‖ [N/m] over the free dofs before and after."""
    n = basis.N
    fixed = np.asarray(fixed, dtype=np.int64)
    free = np.ones(n, dtype=bool)
    free[fixed] = False
    residual = np.asarray(force, dtype=np.float64) - internal_force(basis, stress)
    before = float(np.linalg.norm(residual[free]))
    tangent = elastic_tangent(poisson)
    k = stiffness(basis, tangent).tocsr()
    du = np.zeros(n)
    index = np.flatnonzero(free)
    du[index] = spsolve(k[index][:, index].tocsc(), residual[index])
    delta = np.einsum("nijkl,nkl->nij", tangent, gauss_points_grad(basis, du))
    delta = 0.5 * (delta + np.swapaxes(delta, 1, 2))
    after = np.asarray(force) - internal_force(basis, stress + delta)
    return delta, before, float(np.linalg.norm(after[free]))


def lift_to_floor(stress: np.ndarray, floor: float | np.ndarray,
                  ) -> tuple[np.ndarray, np.ndarray]:
    """``stress`` [Pa] (n, 2, 2) with every point whose least principal compression is below
    its ``floor`` p_min [Pa] (>= 0, one or one per point; −inf: none at that point) lifted
    by an isotropic pressure to it (to within 1e-9 above: a preparation's own floor then
    leaves it alone), its deviator kept; and the indices of the lifted points."""
    sigma = np.asarray(stress, dtype=np.float64)
    floor = np.asarray(floor, dtype=np.float64)
    none = np.isneginf(floor)
    floor = np.where(none, 0.0, floor)
    floor = _per("minimum_pressure", floor if floor.ndim else float(floor), sigma.shape[0],
                 "point")
    floor = np.where(np.broadcast_to(none, floor.shape), -np.inf, floor)
    least = -np.linalg.eigvalsh(sigma)[:, 1]  # the least principal compression
    lifted = np.flatnonzero(least < floor)
    out = sigma.copy()
    shift = floor[lifted] * (1.0 + 1e-9) - least[lifted]
    out[lifted] -= shift[:, None, None] * np.eye(2)
    return out, lifted


@dataclass(frozen=True)
class GroundState:
    """The geostatic start of :func:`ground_stress`.

    Attributes:
        stress: the initial stress [Pa] (n, 2, 2), tension positive.
        sigma_v: the overburden column's σv [Pa] (n,), compression positive.
        level: every column reached the same height with one unit weight and one K0: the
            level-ground field, not corrected.
        residual_column: ‖R‖/‖f_ext‖ of the column state over the free dofs (0 when level).
        residual: ‖R‖/‖f_ext‖ of ``stress`` (that of the column state when level).
        correction: the largest component of Δσ, in magnitude, over the largest σv [-] (0
            when level).
    """

    stress: np.ndarray
    sigma_v: np.ndarray
    level: bool
    residual_column: float
    residual: float
    correction: float


def ground_stress(problem: object, unit_weight: float | np.ndarray,
                  k0: float | np.ndarray, surcharge: float = 0.0) -> GroundState:
    """The geostatic start of ``problem`` (a
    :class:`~granular_material.fem.boundary_value.conditions.Problem`): the overburden column
    of its mesh with ``unit_weight`` γ [N/m³] (one, or one per element), ``k0`` [-] (one, or
    one per Gauss point) and ``surcharge`` q [Pa], corrected into equilibrium with the
    problem's loads at λ = 0 (see the module docstring)."""
    mesh = problem.mesh_data.mesh
    xy = problem.points
    column = overburden(mesh, xy, unit_weight, surcharge)
    n = xy.shape[0]
    k0 = _per("k0", k0, n, "point", strict=True)
    gamma = np.asarray(unit_weight, dtype=np.float64)
    top = float(np.max(column.surface))
    size = float(np.ptp(mesh.p[1]) + np.ptp(mesh.p[0]))
    level = (bool(np.all(np.abs(column.surface - top) <= 1e-9 * size))
             and bool(np.all(gamma == gamma.flat[0])) and bool(np.all(k0 == k0[0])))
    if level:  # level ground: the K0 field itself, already in discrete equilibrium (from
        # the mesh's highest node, as before the column was measured)
        top = float(mesh.p[1].max())
        return GroundState(geostatic_stress(xy, top, float(gamma.flat[0]), surcharge,
                                            float(k0[0])),
                           column.sigma_v, True, 0.0, 0.0, 0.0)
    sigma = column_stress(column.sigma_v, k0)
    _, force = problem.loading.at(0.0)
    free = np.ones(force.size, dtype=bool)
    free[problem.loading.dirichlet_dofs] = False
    load = float(np.linalg.norm(force[free])) or float(
        np.linalg.norm(internal_force(problem.basis, sigma))) or 1.0
    delta, before, after = equilibrium_correction(
        problem.basis, sigma, force, problem.loading.dirichlet_dofs, poisson_of_k0(k0))
    largest = float(column.sigma_v.max())
    change = float(np.abs(delta).max()) / largest if largest > 0 else math.inf
    return GroundState(sigma + delta, column.sigma_v, False, before / load, after / load,
                       change)
