"""The checks of an RVE batch (docs/design.md#rve-file): shapes, dtypes and values of its
arrays, its meta, and its contact history (the engine's Verlet lists) if present; each
failure an ``RVEFileError`` naming the first array or value that is not a valid RVE."""

from __future__ import annotations

import hashlib
import math
from typing import TYPE_CHECKING

import numpy as np

from granular_material.dem.rve.format import _BATCH_ARRAYS, CONTACT_HISTORY_KEYS, RVEFileError

if TYPE_CHECKING:
    from granular_material.dem.rve.data import RVEData

__all__ = ["FRACTIONAL_TOLERANCE", "validate_rve"]

#: ``|H·s − x|`` [m] above which ``fractional_position`` contradicts ``position`` (as the engine)
FRACTIONAL_TOLERANCE = 1e-9


def validate_rve(data: RVEData, capacity: int | None = None) -> None:
    """Raise ``RVEFileError`` naming the first array or value that is not a valid RVE.

    Checked: shapes, dtypes and finite values of every array, positive radii, cells and
    the meta, and the contact history if present (:func:`_validate_history`); with
    ``capacity`` also that every contact list fits ``capacity`` slots a disc.
    """
    for name in _BATCH_ARRAYS:
        dtype = np.asarray(getattr(data, name)).dtype
        if dtype.kind not in "iuf":
            raise RVEFileError(f"{name} must hold real numbers, got dtype {dtype}")
    if data.radius.ndim != 2:
        raise RVEFileError(f"radius must have shape (B, N), got {data.radius.shape}")
    b, n = data.radius.shape
    if b < 1 or n < 1:
        raise RVEFileError(
            f"radius must have shape (B, N) with B >= 1 RVEs and N >= 1 discs, got B={b}, "
            f"N={n}"
        )
    expected = {
        "position": (b, n, 2), "cell": (b, 2, 2), "velocity": (b, n, 2),
        "angular_velocity": (b, n),
    }
    for name, shape in expected.items():
        got = getattr(data, name).shape
        if got != shape:
            raise RVEFileError(
                f"{name} must have shape {shape} (radius has (B, N) = {(b, n)}), got {got}"
            )
    for name in ("radius", *expected):
        array = getattr(data, name)
        bad = ~np.isfinite(array)
        if bad.any():
            where = np.argwhere(bad)[0].tolist()
            raise RVEFileError(f"{name} holds a non-finite value at index {where}")
    if (data.radius <= 0).any():
        where = np.argwhere(data.radius <= 0)[0].tolist()
        value = data.radius[tuple(where)]
        raise RVEFileError(f"radius must be positive, got {value!r} at index {where}")
    with np.errstate(all="ignore"):
        area = np.linalg.det(data.cell)
        solid = np.pi * (data.radius**2).sum(axis=1)
    if not np.isfinite(area).all():
        rve = int(np.argmax(~np.isfinite(area)))
        raise RVEFileError(f"cell of RVE {rve} has an area out of range ({area[rve]!r} m²)")
    if (area <= 0).any():
        rve = int(np.argmax(area <= 0))
        raise RVEFileError(
            f"cell of RVE {rve} has non-positive area {area[rve]!r} m² "
            "(columns must be right-handed cell vectors)"
        )
    if (solid >= area).any():
        rve = int(np.argmax(solid >= area))
        raise RVEFileError(
            f"cell of RVE {rve} is too small for its discs: area {area[rve]:.6g} m² "
            f"<= solid area {solid[rve]:.6g} m²"
        )
    data.meta.validate()
    _check_pairs(data, _validate_history(data, capacity))


def _validate_history(data: RVEData, capacity: int | None) -> dict[str, np.ndarray] | None:
    """Check the contact history arrays (:data:`CONTACT_HISTORY_KEYS`), all or none.

    The stored lists are the engine's Verlet lists, trusted until its skin test calls
    for a rebuild: each used slot ``k < contact_count[b, i]`` holds a partner
    ``0 <= j < N``, ``j != i``, at most once, and j lists i back (symmetry); the two
    slots of a pair hold the same tangential force (finite); every pair of discs that
    overlaps is listed (a list that misses one, e.g. emptied, would leave that contact
    without force until the next rebuild). Slots past the count are not read.
    """
    present = [k for k in CONTACT_HISTORY_KEYS if k in data.extra]
    if not present:
        return None
    if len(present) < len(CONTACT_HISTORY_KEYS):
        lacking = [k for k in CONTACT_HISTORY_KEYS if k not in data.extra]
        raise RVEFileError(
            f"contact history is incomplete: has {', '.join(present)} but lacks "
            f"{', '.join(lacking)} (give all of them, or none to rebuild the lists)"
        )
    b, n = data.radius.shape
    arrays = {k: np.asarray(data.extra[k]) for k in CONTACT_HISTORY_KEYS}
    partner = arrays["contact_partner"]
    if partner.ndim != 3 or partner.shape[:2] != (b, n):
        raise RVEFileError(
            f"contact_partner must have shape ({b}, {n}, K), got {partner.shape}"
        )
    k = partner.shape[2]
    expected = {
        "contact_count": (b, n), "contact_shear_force": (b, n, k),
        "fractional_position": (b, n, 2), "verlet_displacement": (b, n, 2),
        "cell_at_list_build": (b, 2, 2),
    }
    for name, shape in expected.items():
        if arrays[name].shape != shape:
            basis = "contact_partner's (B, N, K)" if len(shape) == 3 and name.startswith(
                "contact") else "radius' (B, N)"
            raise RVEFileError(
                f"{name} must have shape {shape} (from {basis}), got {arrays[name].shape}"
            )
    for name in ("contact_partner", "contact_count"):
        if arrays[name].dtype.kind not in "iu":
            raise RVEFileError(f"{name} must hold integers, got dtype {arrays[name].dtype}")
    for name in CONTACT_HISTORY_KEYS[2:]:
        if arrays[name].dtype.kind not in "iuf":
            raise RVEFileError(
                f"{name} must hold real numbers, got dtype {arrays[name].dtype}"
            )
        bad = ~np.isfinite(arrays[name])
        if bad.any():
            where = np.argwhere(bad)[0].tolist()
            raise RVEFileError(f"{name} holds a non-finite value at index {where}")
    count = arrays["contact_count"].astype(np.int64)
    limit = k if capacity is None else min(k, capacity)
    if (count < 0).any() or (count > limit).any():
        where = np.argwhere((count < 0) | (count > limit))[0].tolist()
        bound = f"the {k} columns of contact_partner"
        if capacity is not None and capacity < k:
            bound = f"the engine's capacity of {capacity} slots a disc"
        raise RVEFileError(
            f"contact_count must lie in [0, {limit}] ({bound}), got "
            f"{count[tuple(where)]} at index {where}"
        )
    used = np.arange(k)[None, None, :] < count[:, :, None]
    part = partner.astype(np.int64)
    disc = np.broadcast_to(np.arange(n)[None, :, None], part.shape)
    bad = used & ((part < 0) | (part >= n))
    if bad.any():
        where = np.argwhere(bad)[0].tolist()
        raise RVEFileError(
            f"contact_partner must lie in [0, {n}) in used slots, got "
            f"{part[tuple(where)]} at index {where}"
        )
    bad = used & (part == disc)
    if bad.any():
        where = np.argwhere(bad)[0].tolist()
        raise RVEFileError(f"contact_partner lists disc {where[1]} as its own partner "
                           f"at index {where}")
    _check_fractional(data, arrays["fractional_position"])
    ref = arrays["cell_at_list_build"].astype(np.float64)
    area = np.linalg.det(ref)
    if (area <= 0).any():
        rve = int(np.argmax(area <= 0))
        raise RVEFileError(
            f"cell_at_list_build of RVE {rve} has non-positive area {area[rve]!r} m²"
        )
    return arrays


def _check_fractional(data: RVEData, frac: np.ndarray) -> None:
    """``fractional_position`` in [0, 1] and ``cell`` times it = ``position`` (1 itself
    occurs: the engine's ``s − floor(s)`` rounds to 1 for s just below 0)."""
    outside = (frac < 0) | (frac > 1)
    if outside.any():
        where = np.argwhere(outside)[0].tolist()
        raise RVEFileError(
            f"fractional_position must lie in [0, 1], got {frac[tuple(where)]!r} at "
            f"index {where}"
        )
    drift = np.abs(np.einsum("bij,bnj->bni", data.cell, frac) - data.position)
    if drift.max() > FRACTIONAL_TOLERANCE:
        where = np.unravel_index(int(np.argmax(drift)), drift.shape)
        raise RVEFileError(
            f"fractional_position does not match position and cell: cell·s differs "
            f"from position by {drift.max():.3g} m at index {list(map(int, where))}"
        )


def _check_pairs(data: RVEData, history: dict[str, np.ndarray] | None) -> None:
    """Per RVE: no two discs at the same place and, with ``history``, its lists
    consistent and complete (:func:`_check_lists`). Identical RVEs are checked once."""
    seen: set[bytes] = set()
    checked: list[int] = []
    touching: list[tuple[np.ndarray, np.ndarray]] = []
    for rve in range(data.n_rve):
        if history is None:
            inv = np.linalg.inv(data.cell[rve])
            frac = data.position[rve] @ inv.T
            frac -= np.floor(frac)
            parts = (data.radius[rve], data.position[rve], data.cell[rve])
        else:
            frac = np.asarray(history["fractional_position"][rve], dtype=np.float64)
            parts = (data.radius[rve], frac, data.cell[rve],
                     *(np.asarray(history[k][rve]) for k in CONTACT_HISTORY_KEYS[:3]))
        digest = hashlib.blake2b(b"".join(np.ascontiguousarray(p).tobytes()
                                          for p in parts)).digest()
        if digest in seen:
            continue
        seen.add(digest)
        i, j, dist2, reach = _touching_pairs(frac, data.cell[rve], data.radius[rve])
        same = dist2 <= (1e-12 * reach) ** 2
        if same.any():
            m = int(np.argmax(same))
            raise RVEFileError(
                f"position of discs {i[m]} and {j[m]} of RVE {rve} coincide (centres "
                f"{np.sqrt(dist2[m]):.3g} m apart)"
            )
        checked.append(rve)
        touching.append((i, j))
    if history is not None:
        _check_lists(history, np.array(checked), touching)


def _check_lists(history: dict[str, np.ndarray], rves: np.ndarray,
                 touching: list[tuple[np.ndarray, np.ndarray]]) -> None:
    """The lists of RVEs ``rves``: no partner twice, symmetric, one force a pair, and
    the touching pairs ``touching[m] = (i, j)`` of RVE ``rves[m]`` all listed."""
    partner = np.asarray(history["contact_partner"][rves], dtype=np.int64)
    count = np.asarray(history["contact_count"][rves], dtype=np.int64)
    shear = np.asarray(history["contact_shear_force"][rves], dtype=np.float64)
    n, k = partner.shape[1:]
    used = np.arange(k)[None, None, :] < count[:, :, None]
    where = np.nonzero(used)
    lane, rows, cols = where[0], where[1], partner[used]
    forces = shear[used]
    key = (lane * n + rows) * n + cols  # one number a (RVE, disc, partner)
    back = (lane * n + cols) * n + rows

    def name(m: int) -> tuple[int, int, int]:
        return int(rves[lane[m]]), int(rows[m]), int(cols[m])

    order = np.argsort(key, kind="stable")
    twice = np.nonzero(np.diff(key[order]) == 0)[0]
    if twice.size:
        rve, i, j = name(int(order[twice[0]]))
        raise RVEFileError(
            f"contact_partner of RVE {rve} lists partner {j} of disc {i} more than once"
        )
    ordered = key[order]  # sorted: membership by binary search (np.isin hashes, slowly)
    lonely = ~_sorted_member(ordered, back)
    if lonely.any():
        rve, i, j = name(int(np.argmax(lonely)))
        raise RVEFileError(
            f"contact_partner of RVE {rve} is not symmetric: disc {i} lists {j} but {j} "
            f"does not list {i}"
        )
    # the sets agree: slot order[m] and slot order_back[m] are the two slots of a pair
    order_back = np.argsort(back, kind="stable")
    differ = forces[order] != forces[order_back]
    if differ.any():
        m, mate = int(order[np.argmax(differ)]), int(order_back[np.argmax(differ)])
        rve, i, j = name(m)
        raise RVEFileError(
            f"contact_shear_force of RVE {rve} differs between the two slots of pair "
            f"({i}, {j}): {forces[m]!r} N and {forces[mate]!r} N"
        )
    lanes = np.concatenate([np.full(len(i), m) for m, (i, _) in enumerate(touching)])
    i = np.concatenate([i for i, _ in touching])
    j = np.concatenate([j for _, j in touching])
    missing = ~_sorted_member(ordered, (lanes * n + i) * n + j)
    if missing.any():
        m = int(np.argmax(missing))
        raise RVEFileError(
            f"contact_partner of RVE {int(rves[lanes[m]])} misses the overlapping pair "
            f"({i[m]}, {j[m]}) ({int(missing.sum())} pair(s) in all): the stored contact "
            "lists are incomplete (remove the contact history arrays to have the lists "
            "rebuilt)"
        )


def _sorted_member(ordered: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Whether each of ``values`` is in the sorted array ``ordered`` (bool, shape of
    ``values``)."""
    if ordered.size == 0:
        return np.zeros(values.shape, dtype=bool)
    at = np.minimum(np.searchsorted(ordered, values), ordered.size - 1)
    return ordered[at] == values


def _touching_pairs(
    frac: np.ndarray, cell: np.ndarray, radius: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pairs i < j of discs that overlap, measured as the engine does (minimum image of
    ``ds = s_j − s_i``, d = H·ds): (i, j, |d|² [m²], r_i + r_j [m]).

    Candidates come from a periodic k-d tree in fractional coordinates: |H·ds| ≥ σ_min·|ds|
    (σ_min the smallest singular value of H), so no overlapping pair is missed.
    """
    s = np.clip(frac, 0.0, np.nextafter(1.0, 0.0))
    sigma = float(np.linalg.svd(cell, compute_uv=False)[-1])
    reach_max = 2.0 * float(radius.max())
    if not (sigma > 0 and math.isfinite(reach_max / sigma)):
        search = math.inf
    else:
        search = reach_max / sigma * (1.0 + 1e-9)
    if search >= 0.5:
        idx = np.triu_indices(len(radius), 1)  # a small or sheared cell: every pair
        pairs = np.stack(idx, axis=1)
    else:
        from scipy.spatial import cKDTree  # here: a continuum run never loads it

        pairs = cKDTree(s, boxsize=1.0).query_pairs(search, output_type="ndarray")
    i, j = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
    ds = s[j] - s[i]
    ds -= np.round(ds)
    d = ds @ cell.T
    dist2 = np.einsum("pi,pi->p", d, d)
    reach = radius[i] + radius[j]
    touching = dist2 < reach * reach * (1.0 - 1e-9)
    return i[touching], j[touching], dist2[touching], reach[touching]
