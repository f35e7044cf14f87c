"""Multifractal spectrum of a non-negative measure on a square image (box counting).

The measure is split into boxes of side ε = 2⁻ᵏL (L the image side, k = 1…8 by default);
p_i(ε) is the mass of box i over the total mass. Boxes with zero mass are left out for every q
(NumPy's 0⁰ = 1 would count them at q = 0). For every moment order q the Chhabra–Jensen
direct method gives α(q) and f(α(q)); the mass exponent τ(q) and the generalised dimensions
D_q = τ/(q − 1) (D1 = α(1)) come from the partition sum. All sums are taken in the log
domain, so p^q at q = −10 never overflows.

Normalising by the total mass or by the number of pixels (Wu et al. 2025, eq. 9) changes
p_i by a constant factor c, which moves every log-moment by a term independent of ε: the
fitted slopes are the same.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["DEFAULT_K", "DEFAULT_Q", "MultifractalSpectrum", "box_masses", "multifractal_spectrum"]

DEFAULT_Q = np.linspace(-10.0, 10.0, 41)
"""Moment orders q ∈ [−10, 10] in steps of 0.5 (Wu et al. 2025, after Xia et al. 2019)."""

DEFAULT_K = tuple(range(1, 9))
"""Box levels k: boxes of side ε = 2⁻ᵏL for k = 1…8 (Wu et al. 2025, eq. 8)."""

_MAX_CHUNK = 1 << 23  # elements of one (images, q, boxes) work array, ~64 MiB of float64


@dataclass(frozen=True)
class MultifractalSpectrum:
    """Multifractal spectrum of one image, or of a batch of images (leading axes ``...``).

    Attributes:
        q: moment orders, shape (nq,), float64.
        k: box levels used in the fits (ε = 2⁻ᵏL), shape (nk,), int64.
        alpha: Hölder exponents α(q), shape (..., nq), float64.
        f: singularity spectrum f(α(q)), shape (..., nq), float64.
        tau: mass exponents τ(q), shape (..., nq), float64.
        Dq: generalised dimensions D_q = τ/(q − 1), D1 = α(1), shape (..., nq), float64.
        r2: smallest R² of the three fits (α, f, τ) at each q, shape (..., nq), float64.
        r2_alpha: R² of the α fit, shape (..., nq), float64.
        r2_f: R² of the f fit, shape (..., nq), float64.
        r2_tau: R² of the τ fit, shape (..., nq), float64.
        poor_fit: True where ``r2 < min_r2``, shape (..., nq), bool.
        D0: capacity dimension D0 = −τ(0) = f(α0), float64 scalar or shape (...).
        alpha0: α at q = 0 (the peak of f(α)), float64 scalar or shape (...).
        min_r2: the R² below which a fit is flagged as poor.
    """

    q: np.ndarray
    k: np.ndarray
    alpha: np.ndarray
    f: np.ndarray
    tau: np.ndarray
    Dq: np.ndarray
    r2: np.ndarray
    r2_alpha: np.ndarray
    r2_f: np.ndarray
    r2_tau: np.ndarray
    poor_fit: np.ndarray
    D0: np.ndarray | float
    alpha0: np.ndarray | float
    min_r2: float

    @property
    def alpha0_over_D0(self) -> np.ndarray | float:
        """α0/D0, the width measure Wu et al. (2025) use to size the RVE; same shape as D0."""
        return self.alpha0 / self.D0


def _check_levels(k: Sequence[int] | ArrayLike) -> np.ndarray:
    levels = np.asarray(k)
    if levels.ndim != 1 or levels.size < 2:
        raise ValueError(f"k must list at least two box levels, got {k!r}")
    if not np.issubdtype(levels.dtype, np.integer):
        if not np.all(np.isfinite(levels)) or np.any(levels != np.round(levels)):
            raise ValueError(f"k must hold integers, got {k!r}")
    levels = levels.astype(np.int64)
    if np.any(levels < 0) or np.unique(levels).size != levels.size:
        raise ValueError(f"k must hold distinct non-negative integers, got {levels.tolist()}")
    return np.sort(levels)


def _check_q(q: ArrayLike) -> np.ndarray:
    orders = np.asarray(q, dtype=np.float64)
    if orders.ndim != 1 or orders.size < 1:
        raise ValueError(f"q must be a non-empty 1-D sequence of moment orders, got shape "
                         f"{orders.shape}")
    if not np.all(np.isfinite(orders)):
        raise ValueError("q must hold finite numbers")
    return orders


def _check_measure(measure: ArrayLike, kmax: int) -> np.ndarray:
    array = np.asarray(measure)
    if array.dtype == np.bool_:
        array = array.astype(np.float64)
    if not (np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)):
        raise ValueError(f"measure must be real (bool, integer or float), got dtype {array.dtype}")
    array = array.astype(np.float64, copy=False)
    if array.ndim < 2:
        raise ValueError(f"measure must be an image (..., n, n), got shape {array.shape}")
    ny, nx = array.shape[-2:]
    if ny != nx:
        raise ValueError(f"measure must be a square image, got {ny} × {nx} pixels")
    n_min = 1 << kmax
    if nx < n_min or nx % n_min:
        raise ValueError(
            f"image side {nx} px must be a positive multiple of 2^{kmax} = {n_min} px so that "
            f"boxes of side 2^-{kmax}·L hold whole pixels (images are never padded)"
        )
    if not np.all(np.isfinite(array)):
        raise ValueError("measure holds a non-finite value (NaN or inf)")
    if np.any(array < 0):
        where = np.argwhere(array < 0)[0].tolist()
        raise ValueError(
            f"measure must be non-negative, got {array[tuple(where)]!r} at index {where}"
        )
    totals = array.reshape(-1, ny * nx).sum(axis=1)
    if np.any(totals <= 0):
        which = int(np.argmax(totals <= 0))
        raise ValueError(f"measure of image {which} is zero everywhere: no spectrum exists")
    return array


def box_masses(image: np.ndarray, k: int) -> np.ndarray:
    """Masses of the 4ᵏ boxes of side 2⁻ᵏL, shape (..., 2ᵏ, 2ᵏ), from an image (..., n, n)."""
    n = image.shape[-1]
    b = n >> k
    shape = (*image.shape[:-2], 1 << k, b, 1 << k, b)
    return image.reshape(shape).sum(axis=(-3, -1))


def _log_moments(mass: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Chhabra–Jensen sums at one box size.

    Args:
        mass: box masses, shape (m, nbox), float64, each row with a positive sum.
        q: moment orders, shape (nq,), float64.

    Returns:
        shape (m, nq, 3), float64: Σ μ_i ln p_i, Σ μ_i ln μ_i and ln Σ p_iᑫ over the boxes
        with p_i > 0, where μ_i(q) = p_iᑫ / Σ_j p_jᑫ is Chhabra & Jensen's (1989) normalised
        measure (Wu et al. 2025, eq. 14).
    """
    occupied = mass > 0
    log_p = np.where(occupied, np.log(np.where(occupied, mass, 1.0)), 0.0)
    log_p -= np.log(mass.sum(axis=1, keepdims=True))
    # ln p_iᑫ, with empty boxes at −inf for every q (never 0·(−inf) nor (−inf)·(−q))
    log_w = np.where(occupied[:, None, :], q[None, :, None] * log_p[:, None, :], -np.inf)
    peak = log_w.max(axis=2, keepdims=True)
    log_z = peak + np.log(np.exp(log_w - peak).sum(axis=2, keepdims=True))
    log_mu = log_w - log_z
    mu = np.exp(log_mu)  # exactly 0 for empty boxes
    safe_log_mu = np.where(occupied[:, None, :], log_mu, 0.0)
    out = np.empty((mass.shape[0], q.size, 3))
    out[..., 0] = (mu * log_p[:, None, :]).sum(axis=2)
    out[..., 1] = (mu * safe_log_mu).sum(axis=2)
    out[..., 2] = log_z[..., 0]
    return out


def _fit(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares slopes and R² of y against x along the last axis.

    Args:
        x: abscissae ln(ε/L), shape (nk,).
        y: ordinates, shape (..., nk).

    Returns:
        slope and R², each of shape (...). A perfectly flat y (no variance to explain)
        has R² = 1.
    """
    dx = x - x.mean()
    dy = y - y.mean(axis=-1, keepdims=True)
    slope = (dy * dx).sum(axis=-1) / (dx * dx).sum()
    residual = dy - slope[..., None] * dx
    ss_res = (residual * residual).sum(axis=-1)
    ss_tot = (dy * dy).sum(axis=-1)
    scale = 1.0 + (y * y).max(axis=-1)
    flat = ss_tot <= 1e-24 * scale * x.size
    r2 = np.where(flat, 1.0, 1.0 - ss_res / np.where(flat, 1.0, ss_tot))
    return slope, r2


def multifractal_spectrum(
    measure: ArrayLike,
    q: ArrayLike = DEFAULT_Q,
    k: Sequence[int] | ArrayLike = DEFAULT_K,
    *,
    min_r2: float = 0.99,
) -> MultifractalSpectrum:
    """Multifractal spectrum of a measure on a square image, or of a batch of them.

    Args:
        measure: non-negative masses per pixel, shape (..., n, n) (bool, int or float; a
            binary pore image is one case), n a multiple of 2^max(k); every image must hold
            some mass.
        q: moment orders, shape (nq,); default −10…10 in steps of 0.5.
        k: box levels, ε = 2⁻ᵏL; default 1…8 (Wu et al. 2025, eq. 8).
        min_r2: fits with R² below this are flagged in ``poor_fit``.

    Returns:
        the spectrum; scalars ``D0`` and ``alpha0`` are float64 for one image and arrays of
        the batch shape ``...`` otherwise.

    Raises:
        ValueError: for a negative, non-finite, non-square, too small or all-zero measure,
            or for malformed ``q`` or ``k``.

    Notes:
        Chhabra & Jensen (1989, Phys. Rev. Lett. 62, 1327), written as Wu et al. (2025)
        eqs. (12)–(14): with μ_i(q, ε) = p_iᑫ / Σ_j p_jᑫ,
        α(q) = lim Σ μ_i ln p_i / ln ε and f(q) = lim Σ μ_i ln μ_i / ln ε, each taken as the
        least-squares slope over the box levels k. τ(q) = lim ln Σ p_iᑫ / ln ε, so that
        f = qα − τ holds at every ε and therefore for the fitted slopes;
        D_q = τ(q)/(q − 1) (Wu et al. 2025, eq. 15), with D1 = α(1).
        α0 = α(0) and D0 = −τ(0) = f(α0), the capacity dimension.
    """
    if not (np.isfinite(min_r2) and 0.0 <= min_r2 <= 1.0):
        raise ValueError(f"min_r2 must lie in [0, 1], got {min_r2!r}")
    levels = _check_levels(k)
    orders = _check_q(q)
    kmax = int(levels[-1])
    image = _check_measure(measure, kmax)
    batch_shape = image.shape[:-2]
    n = image.shape[-1]
    images = image.reshape(-1, n, n)
    n_img = images.shape[0]

    q_all = np.append(orders, 0.0)  # α0 and D0 always come from q = 0 exactly
    moments = np.empty((n_img, q_all.size, 3, levels.size))
    finest = box_masses(images, kmax)
    for j in range(levels.size - 1, -1, -1):
        level = int(levels[j])
        while finest.shape[-1] > (1 << level):  # coarsen by 2×2 sums down to this level
            m = finest.shape[-1] // 2
            finest = finest.reshape(n_img, m, 2, m, 2).sum(axis=(2, 4))
        flat = finest.reshape(n_img, -1)
        chunk = max(1, _MAX_CHUNK // (q_all.size * flat.shape[1]))
        for start in range(0, n_img, chunk):
            stop = min(start + chunk, n_img)
            moments[start:stop, :, :, j] = _log_moments(flat[start:stop], q_all)

    log_eps = -levels * np.log(2.0)  # ln(ε/L); L drops out of the slopes
    slopes, r2s = _fit(log_eps, moments)
    alpha_all, f_all, tau_all = slopes[..., 0], slopes[..., 1], slopes[..., 2]

    def shaped(a: np.ndarray) -> np.ndarray:
        return a[:, :-1].reshape(*batch_shape, orders.size)

    def scalar(a: np.ndarray) -> np.ndarray | float:
        return a[:, -1].reshape(batch_shape)[()]

    q_one = np.abs(orders - 1.0) < 1e-9
    denom = np.where(q_one, 1.0, orders - 1.0)
    dq_all = np.where(q_one[None, :], alpha_all[:, :-1], tau_all[:, :-1] / denom[None, :])
    r2_min = r2s.min(axis=-1)
    return MultifractalSpectrum(
        q=orders,
        k=levels,
        alpha=shaped(alpha_all),
        f=shaped(f_all),
        tau=shaped(tau_all),
        Dq=dq_all.reshape(*batch_shape, orders.size),
        r2=shaped(r2_min),
        r2_alpha=shaped(r2s[..., 0]),
        r2_f=shaped(r2s[..., 1]),
        r2_tau=shaped(r2s[..., 2]),
        poor_fit=shaped(r2_min) < min_r2,
        D0=-scalar(tau_all),
        alpha0=scalar(alpha_all),
        min_r2=float(min_r2),
    )
