"""Multifractal spectrum of a non-negative measure on a square image (box counting).

The measure is split into boxes of side ε = 2⁻ᵏL (L the image side, k = 1…8 by default),
or into boxes of given sides in pixels (``box_px``, the boxes of a physical box rule: the
image is then covered by ⌊n/b⌋² whole boxes from its lower-left corner, the last n mod b
rows and columns left out, never padded, and the moments are scaled up to the whole image
as if the covered part were a sample of it); p_i(ε) is the mass of box i over the total
mass of the boxes. Boxes with zero mass are left out for every q
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

__all__ = [
    "DEFAULT_K",
    "DEFAULT_Q",
    "MultifractalSpectrum",
    "box_masses",
    "box_masses_px",
    "multifractal_spectrum",
]

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
        k: box levels used in the fits (ε = 2⁻ᵏL), shape (nk,), int64; empty when the
            boxes were given in pixels (``box_px``).
        box_px: side of each box of the fits in pixels, shape (nk,), int64 (n/2ᵏ for k).
        alpha: Hölder exponents α(q), shape (..., nq), float64.
        f: singularity spectrum f(α(q)), shape (..., nq), float64.
        tau: mass exponents τ(q), shape (..., nq), float64.
        Dq: generalised dimensions D_q = τ/(q − 1), D1 = α(1), shape (..., nq), float64.
        r2: smallest R² of the three fits (α, f, τ) at each q, shape (..., nq), float64.
        r2_alpha: R² of the α fit, shape (..., nq), float64.
        r2_f: R² of the f fit, shape (..., nq), float64.
        r2_tau: R² of the τ fit, shape (..., nq), float64.
        poor_fit: True where ``r2 < min_r2``, shape (..., nq), bool.
        se_alpha, se_f, Dq_se: standard errors of the least-squares slopes α(q), f(q) and
            of D_q (SE of τ over ``|q − 1|``; of α at q = 1), shape (..., nq), float64; NaN
            with two box sizes only. The log-moments of nested boxes are not independent,
            so read them as the scatter about the line, not as a confidence interval.
        D0: capacity dimension D0 = −τ(0) = f(α0), float64 scalar or shape (...).
        alpha0: α at q = 0 (the peak of f(α)), float64 scalar or shape (...).
        D0_se, alpha0_se: standard errors of D0 and α0, float64 scalar or shape (...).
        r2_q0: smallest R² of the fits at q = 0 (which give D0 and α0), scalar or (...).
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
    box_px: np.ndarray
    se_alpha: np.ndarray
    se_f: np.ndarray
    Dq_se: np.ndarray
    D0_se: np.ndarray | float
    alpha0_se: np.ndarray | float
    r2_q0: np.ndarray | float

    @property
    def alpha0_over_D0(self) -> np.ndarray | float:
        """α0/D0, the width measure Wu et al. (2025) use to size the RVE; same shape as D0."""
        return self.alpha0 / self.D0

    @property
    def alpha0_over_D0_se(self) -> np.ndarray | float:
        """Standard error of α0/D0 from those of α0 and D0, taken as independent."""
        ratio = self.alpha0 / self.D0
        return np.abs(ratio) * np.hypot(self.alpha0_se / self.alpha0, self.D0_se / self.D0)


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


def _check_boxes(box_px: Sequence[int] | ArrayLike) -> np.ndarray:
    sides = np.asarray(box_px)
    if sides.ndim != 1 or sides.size < 2:
        raise ValueError(f"box_px must list at least two box sides, got {box_px!r}")
    if not np.issubdtype(sides.dtype, np.integer):
        if not np.all(np.isfinite(sides)) or np.any(sides != np.round(sides)):
            raise ValueError(f"box_px must hold whole pixels, got {box_px!r}")
    sides = sides.astype(np.int64)
    if np.any(sides < 1) or np.unique(sides).size != sides.size:
        raise ValueError(f"box_px must hold distinct positive sides, got {sides.tolist()}")
    return np.sort(sides)[::-1].copy()  # coarse to fine, as the levels k = 1, 2, …


def _check_measure(
    measure: ArrayLike, kmax: int | None, sides: np.ndarray | None = None
) -> np.ndarray:
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
    if kmax is not None:
        n_min = 1 << kmax
        if nx < n_min or nx % n_min:
            raise ValueError(
                f"image side {nx} px must be a positive multiple of 2^{kmax} = {n_min} px so "
                f"that boxes of side 2^-{kmax}·L hold whole pixels (images are never padded)"
            )
    elif sides is not None and nx < int(sides.max()):
        raise ValueError(f"image side {nx} px is smaller than the largest box, "
                         f"{int(sides.max())} px")
    if not np.all(np.isfinite(array)):
        raise ValueError("measure holds a non-finite value (NaN or inf)")
    if np.any(array < 0):
        where = np.argwhere(array < 0)[0].tolist()
        raise ValueError(
            f"measure must be non-negative, got {array[tuple(where)]!r} at index {where}"
        )
    totals = array.reshape(-1, ny * nx).sum(axis=1)
    where = "everywhere"
    if sides is not None and np.all(totals > 0):  # only whole boxes count: the part that
        crop = int(((nx // sides) * sides).min())  # every box size covers needs mass
        totals = array[..., :crop, :crop].reshape(-1, crop * crop).sum(axis=1)
        where = f"in its first {crop} × {crop} px, which every box size covers"
    if np.any(totals <= 0):
        which = int(np.argmax(totals <= 0))
        raise ValueError(f"measure of image {which} is zero {where}: no spectrum exists")
    return array


def box_masses(image: np.ndarray, k: int) -> np.ndarray:
    """Masses of the 4ᵏ boxes of side 2⁻ᵏL, shape (..., 2ᵏ, 2ᵏ), from an image (..., n, n)."""
    n = image.shape[-1]
    b = n >> k
    shape = (*image.shape[:-2], 1 << k, b, 1 << k, b)
    return image.reshape(shape).sum(axis=(-3, -1))


def box_masses_px(image: np.ndarray, b: int) -> np.ndarray:
    """Masses of the ⌊n/b⌋² whole boxes of b pixels from the lower-left corner, shape
    (..., ⌊n/b⌋, ⌊n/b⌋), from an image (..., n, n); the last n mod b rows and columns are
    left out."""
    m = image.shape[-1] // b
    crop = image[..., : m * b, : m * b]
    return crop.reshape(*image.shape[:-2], m, b, m, b).sum(axis=(-3, -1))


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


def _fit(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares slopes, R² and standard errors of the slopes of y against x along the
    last axis.

    Args:
        x: abscissae ln ε (any unit of ε), shape (nk,).
        y: ordinates, shape (..., nk).

    Returns:
        slope, R² and the slope's standard error √(SS_res/(nk − 2)/Σ(x − x̄)²) (NaN for
        nk = 2), each of shape (...). A perfectly flat y (no variance to explain) has R² = 1.
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
    if x.size > 2:
        se = np.sqrt(np.maximum(ss_res, 0.0) / (x.size - 2) / (dx * dx).sum())
    else:
        se = np.full(slope.shape, np.nan)
    return slope, r2, se


def multifractal_spectrum(
    measure: ArrayLike,
    q: ArrayLike = DEFAULT_Q,
    k: Sequence[int] | ArrayLike = DEFAULT_K,
    *,
    min_r2: float = 0.99,
    box_px: Sequence[int] | ArrayLike | None = None,
    min_fill: float = 0.0,
) -> MultifractalSpectrum:
    """Multifractal spectrum of a measure on a square image, or of a batch of them.

    Args:
        measure: non-negative masses per pixel, shape (..., n, n) (bool, int or float; a
            binary pore image is one case), n a multiple of 2^max(k) (with ``k``); every
            image must hold some mass.
        q: moment orders, shape (nq,); default −10…10 in steps of 0.5.
        k: box levels, ε = 2⁻ᵏL; default 1…8 (Wu et al. 2025, eq. 8). Ignored when
            ``box_px`` is given.
        min_r2: fits with R² below this are flagged in ``poor_fit``.
        box_px: box sides in pixels instead of the levels k (at least two, each ≤ n); each
            size covers the image with ⌊n/b⌋² whole boxes from the lower-left corner (the
            sides that divide n use every pixel), whose moments stand for the whole image's:
            the covered fraction a enters as ln Σ p_iᑫ + (q − 1) ln a and α, f sums + ln a,
            so a uniform image has D_q = 2 for any sides. See :func:`.boxes.physical_boxes`.
        min_fill: a box whose mass is below ``min_fill`` × (its pixels) counts as empty
            (for a binary image: whose pore fraction is below it); 0 keeps every box with
            mass. Drops the boxes that hold only a sliver of pore a pixel wide, whose count
            depends on the resolution more than on the pores.

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
    orders = _check_q(q)
    if not (np.isfinite(min_fill) and 0.0 <= min_fill < 1.0):
        raise ValueError(f"min_fill must lie in [0, 1), got {min_fill!r}")
    if box_px is None:
        levels = _check_levels(k)
        kmax = int(levels[-1])
        image = _check_measure(measure, kmax)
        sides = image.shape[-1] >> levels
    else:
        sides = _check_boxes(box_px)
        levels = np.zeros(0, dtype=np.int64)
        image = _check_measure(measure, None, sides)
    batch_shape = image.shape[:-2]
    n = image.shape[-1]
    images = image.reshape(-1, n, n)
    n_img = images.shape[0]

    q_all = np.append(orders, 0.0)  # α0 and D0 always come from q = 0 exactly
    moments = np.empty((n_img, q_all.size, 3, sides.size))

    def add_moments(j: int, boxes: np.ndarray) -> None:
        flat = boxes.reshape(n_img, -1)
        if min_fill > 0:
            side = int(sides[j])
            flat = np.where(flat >= min_fill * side * side, flat, 0.0)
            if np.any(flat.sum(axis=1) <= 0):
                raise ValueError(f"no box of {side} px holds min_fill = {min_fill:g} of its "
                                 "pixels' mass in some image: lower min_fill")
        chunk = max(1, _MAX_CHUNK // (q_all.size * flat.shape[1]))
        for start in range(0, n_img, chunk):
            stop = min(start + chunk, n_img)
            moments[start:stop, :, :, j] = _log_moments(flat[start:stop], q_all)

    if box_px is None:
        finest = box_masses(images, kmax)
        for j in range(levels.size - 1, -1, -1):
            level = int(levels[j])
            while finest.shape[-1] > (1 << level):  # coarsen by 2×2 sums down to this level
                m = finest.shape[-1] // 2
                finest = finest.reshape(n_img, m, 2, m, 2).sum(axis=(2, 4))
            add_moments(j, finest)
        log_eps = -levels * np.log(2.0)  # ln(ε/L); L drops out of the slopes
    else:
        for j, side in enumerate(sides):
            add_moments(j, box_masses_px(images, int(side)))
            # the whole boxes cover a = (⌊n/b⌋·b/n)² of the image; taken as a sample of
            # it, the image holds 1/a times as many boxes with masses a·p_i: ln Σ p_iᑫ
            # gains (q − 1) ln a, Σ μ_i ln p_i and Σ μ_i ln μ_i gain ln a (0 when b | n)
            log_a = 2.0 * np.log((n // int(side)) * int(side) / n)
            moments[:, :, 0:2, j] += log_a
            moments[:, :, 2, j] += (q_all - 1.0) * log_a
        log_eps = np.log(sides.astype(np.float64))  # ln(ε / 1 px)
    slopes, r2s, ses = _fit(log_eps, moments)
    alpha_all, f_all, tau_all = slopes[..., 0], slopes[..., 1], slopes[..., 2]

    def shaped(a: np.ndarray) -> np.ndarray:
        return a[:, :-1].reshape(*batch_shape, orders.size)

    def scalar(a: np.ndarray) -> np.ndarray | float:
        return a[:, -1].reshape(batch_shape)[()]

    q_one = np.abs(orders - 1.0) < 1e-9
    denom = np.where(q_one, 1.0, orders - 1.0)
    dq_all = np.where(q_one[None, :], alpha_all[:, :-1], tau_all[:, :-1] / denom[None, :])
    r2_min = r2s.min(axis=-1)
    se_alpha, se_f, se_tau = ses[..., 0], ses[..., 1], ses[..., 2]
    se_dq = np.where(q_one[None, :], se_alpha[:, :-1],
                     se_tau[:, :-1] / np.abs(denom)[None, :])
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
        box_px=np.asarray(sides, dtype=np.int64),
        se_alpha=shaped(se_alpha),
        se_f=shaped(se_f),
        Dq_se=se_dq.reshape(*batch_shape, orders.size),
        D0_se=scalar(se_tau),
        alpha0_se=scalar(se_alpha),
        r2_q0=scalar(r2_min),
    )
