"""Initial stress states per Gauss point: geostatic (self-weight and a surcharge) or uniform.

Tension positive, Pa, batch-first (n, 2, 2), plane strain (the 2D stress only).

Geostatic: σ_yy = −(q + γ (y_s − y)), σ_xx = K0 σ_yy, σ_xy = 0 at a point of height y [m]
below the surface y_s [m], for a surcharge q [Pa] and a unit weight γ [N/m³] (both
compression positive). This field is in equilibrium with the body force −γ e_y and the
surcharge on a horizontal surface (div σ = (0, γ)); with rollers on vertical sides and a
fixed or rollered base it is the K0 state of a level ground. A finite-element mesh carries
it in *discrete* equilibrium (a zero residual at step 0) when its Gauss rule integrates
∇v : σ det J and the body force exactly. It does for the default rules of straight-sided
elements: triangles (tri3 with 1 point, tri6 with 3: polynomials of degree 1 and 2) and
quadrilaterals of any shape (quad4 and quad8 with 2 × 2, quad9 with 3 × 3: with a bilinear
map, ∇v det J is a polynomial, of degree at most 2 per direction for quad8, times σ of
degree 1). Measured on 12 × 8 meshes with every interior node moved at random (quad4,
quad8, quad9) and on Guo & Zhao's footing.msh: ‖R‖/‖f_ext‖ ≤ 5e-15.
"""

from __future__ import annotations

import math

import numpy as np

from granular_material.errors import ParameterError
from granular_material.memory import available_memory, memory_refusal
from granular_material.typed_fields import conform

__all__ = ["geostatic_stress", "uniform_stress"]


def _check(name: str, value: float, low: float = 0.0) -> float:
    value = conform(name, value, float)  # a finite number (a string or None named)
    if not (math.isfinite(value) and value >= low):
        raise ParameterError(name, f"must be a finite number >= {low:g}, got {value!r}")
    return float(value)


def geostatic_stress(points_xy: np.ndarray, surface_y: float, unit_weight: float,
                     surcharge: float = 0.0, k0: float = 1.0) -> np.ndarray:
    """σ [Pa] (n, 2, 2), tension positive, of the K0 state at the points ``points_xy`` [m]
    (n, 2): σ_yy = −(q + γ (y_s − y)), σ_xx = K0 σ_yy, no shear.

    Args:
        points_xy: coordinates [m], shape (n, 2).
        surface_y: height of the ground surface y_s [m]; every point must lie at or below it.
        unit_weight: γ [N/m³], >= 0.
        surcharge: q [Pa] on the surface, compression positive, >= 0.
        k0: coefficient of earth pressure at rest σ_h/σ_v [-], > 0.
    """
    given = np.asarray(points_xy)
    if given.dtype.kind not in "biuf":
        raise ParameterError("points_xy", f"must be real coordinates [m], got an array of "
                                          f"{given.dtype}")
    xy = given.astype(np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ParameterError("points_xy", f"must have shape (n, 2), got {xy.shape}")
    if not np.isfinite(xy).all():
        raise ParameterError("points_xy", f"{int((~np.isfinite(xy)).any(axis=1).sum())} "
                                          "points have coordinates that are not finite")
    gamma = _check("unit_weight", unit_weight)
    q = _check("surcharge", surcharge)
    k0 = conform("k0", k0, float)
    if not k0 > 0:
        raise ParameterError("k0", f"must be a positive number, got {k0!r}")
    surface_y = conform("surface_y", surface_y, float)
    depth = surface_y - xy[:, 1]
    above = depth < -1e-9 * max(1.0, abs(surface_y))
    if np.any(above):
        raise ParameterError("surface_y", f"{surface_y!r} m lies below {int(above.sum())} "
                                          f"points (highest y {xy[:, 1].max():.6g} m)")
    with np.errstate(over="ignore"):
        sigma_v = -(q + gamma * np.maximum(depth, 0.0))
        sigma_h = k0 * sigma_v
    if not (np.isfinite(sigma_v).all() and np.isfinite(sigma_h).all()):
        raise ParameterError("unit_weight", f"{gamma:g} N/m³ with the surcharge {q:g} Pa and "
                                            f"k0 {k0:g} over a depth of {depth.max():.6g} m "
                                            "gives a stress beyond any float")
    out = np.zeros((xy.shape[0], 2, 2))
    out[:, 1, 1] = sigma_v
    out[:, 0, 0] = sigma_h
    return out


def uniform_stress(n: int, p: float) -> np.ndarray:
    """σ = −p I [Pa] (n, 2, 2) at ``n`` points: the isotropic pressure ``p`` [Pa],
    compression positive (Guo & Zhao's start: every RVE at the surcharge)."""
    n = conform("n", n, int)
    if n < 1:
        raise ParameterError("n", f"must be an integer >= 1, got {n!r}")
    p = conform("p", p, float)  # finite
    refusal = memory_refusal(float(min(n, 10**300)) * 32, f"{n} stress tensors",
                             available_memory())
    if refusal:
        raise ParameterError("n", refusal)
    return np.broadcast_to(-float(p) * np.eye(2), (int(n), 2, 2)).copy()
