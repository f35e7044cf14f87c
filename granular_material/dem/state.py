"""State: everything of a DEM batch that evolves, on the model's device; to and from files."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np
import warp as wp

from granular_material.dem.kernels.sets import kernels_for, launch
from granular_material.dem.model import Model
from granular_material.dem.rve.file import RVEData

__all__ = ["HISTORY_KEYS", "State", "state_from_data", "state_to_data"]

#: further arrays of the RVE file that make a resumed run bit-identical to an uninterrupted one
HISTORY_KEYS = (
    "contact_partner",  # (B, N, K) int32, partner index within the RVE, -1 = empty slot
    "contact_count",  # (B, N) int32, used slots
    "contact_shear_force",  # (B, N, K) float64, tangential spring force [N]
    "fractional_position",  # (B, N, 2) float64, s = H⁻¹x in [0, 1)
    "verlet_displacement",  # (B, N, 2) float64, displacement since the last list build [m]
    "cell_at_list_build",  # (B, 2, 2) float64, H at the last list build [m]
)


@dataclass(eq=False)
class State:
    """Everything that evolves, on the model's device. Flat particle index ``b·N + j``, flat
    slot index ``(b·N + j)·K + k``; names as the RVE file's keys.

    Attributes:
        fractional_position: s = H⁻¹x in [0, 1)², shape (B·N,), vec2.
        velocity: fluctuating velocities [m/s], (B·N,), vec2.
        angular_velocity: [rad/s], (B·N,).
        cell: cell matrices H [m] (columns = cell vectors), (B,), mat22.
        contact_partner: neighbour slots (partner's index within its RVE), (B·N·K,), int32.
        contact_count: used slots per disc, (B·N,), int32.
        contact_shear_force: tangential spring force [N] per slot, (B·N·K,); the pair's
            owner (its lower index) keeps it, the partner's copy is refreshed at list builds
            (and when the state is written to a file).
        contact_mirror_slot: per slot, the slot of the partner's list that holds this disc,
            counted from the RVE's first slot (b·N·K), (B·N·K,), int32.
        verlet_displacement: fluctuating displacement since the last list build [m], vec2.
        cell_at_list_build: cell at the last list build [m], (B,), mat22.
        force_rebuild: 1 where the next step must rebuild the lists, (B,), int32.
        status: error bits per RVE (kernels.STATUS_*), (B,), int32.
    """

    fractional_position: wp.array
    velocity: wp.array
    angular_velocity: wp.array
    cell: wp.array
    contact_partner: wp.array
    contact_count: wp.array
    contact_shear_force: wp.array
    contact_mirror_slot: wp.array
    verlet_displacement: wp.array
    cell_at_list_build: wp.array
    force_rebuild: wp.array
    status: wp.array

    def clone(self) -> State:
        """A device copy of every array."""
        return State(**{f.name: wp.clone(getattr(self, f.name)) for f in fields(self)})

    def assign(self, other: State) -> None:
        """Copy ``other``'s arrays into this state's arrays, in place."""
        for f in fields(self):
            wp.copy(getattr(self, f.name), getattr(other, f.name))

    def assign_rves(self, other: State, first: int, stop: int, n_rve: int) -> None:
        """Copy RVEs ``first : stop`` of ``other`` into this state (of ``n_rve`` RVEs), in
        place; the other RVEs are left as they are. Every array is batch-first, the same
        number of entries per RVE."""
        for f in fields(self):
            dest, src = getattr(self, f.name), getattr(other, f.name)
            per_rve = dest.shape[0] // n_rve
            wp.copy(dest, src, dest_offset=first * per_rve, src_offset=first * per_rve,
                    count=(stop - first) * per_rve)


def _types(model: Model) -> tuple:
    ft = model.float_type
    return ft, wp.types.vector(2, ft), wp.types.matrix((2, 2), ft)


def state_from_data(model: Model, data: RVEData) -> State:
    """Upload the dynamic arrays of ``data`` (and its contact history if present)."""
    ft, vec2, mat22 = _types(model)
    dev = model.device
    b, n, k = model.n_rve, model.n_disc, model.capacity
    inv = np.linalg.inv(data.cell)
    frac = np.einsum("bij,bnj->bni", inv, data.position)
    frac -= np.floor(frac)
    partner = np.full((b, n, k), -1, dtype=np.int32)
    count = np.zeros((b, n), dtype=np.int32)
    shear = np.zeros((b, n, k))
    disp = np.zeros((b, n, 2))
    cell_ref = np.array(data.cell)
    resume = all(key in data.extra for key in HISTORY_KEYS)
    if resume:
        stored = np.asarray(data.extra["fractional_position"], dtype=np.float64)
        drift = np.abs(np.einsum("bij,bnj->bni", data.cell, stored) - data.position).max()
        if stored.shape != frac.shape or drift > 1e-9:
            raise ValueError("fractional_position does not match position and cell")
        frac = stored
        disp = np.asarray(data.extra["verlet_displacement"], dtype=np.float64)
        cell_ref = np.asarray(data.extra["cell_at_list_build"], dtype=np.float64)
        stored_partner = np.asarray(data.extra["contact_partner"], dtype=np.int32)
        width = min(stored_partner.shape[-1], k)
        if stored_partner.shape[:2] != (b, n):
            raise ValueError(
                f"contact_partner has shape {stored_partner.shape}, expected ({b}, {n}, K)"
            )
        partner[..., :width] = stored_partner[..., :width]
        count[:] = np.minimum(np.asarray(data.extra["contact_count"], dtype=np.int32), width)
        shear[..., :width] = np.asarray(data.extra["contact_shear_force"])[..., :width]
    state = State(
        fractional_position=wp.array(frac.reshape(-1, 2), dtype=vec2, device=dev),
        velocity=wp.array(data.velocity.reshape(-1, 2), dtype=vec2, device=dev),
        angular_velocity=wp.array(data.angular_velocity.reshape(-1), dtype=ft, device=dev),
        cell=wp.array(data.cell, dtype=mat22, device=dev),
        contact_partner=wp.array(partner.reshape(-1), dtype=wp.int32, device=dev),
        contact_count=wp.array(count.reshape(-1), dtype=wp.int32, device=dev),
        contact_shear_force=wp.array(shear.reshape(-1), dtype=ft, device=dev),
        contact_mirror_slot=wp.full(b * n * k, -1, dtype=wp.int32, device=dev),
        verlet_displacement=wp.array(disp.reshape(-1, 2), dtype=vec2, device=dev),
        cell_at_list_build=wp.array(cell_ref, dtype=mat22, device=dev),
        force_rebuild=wp.array(np.full(b, 0 if resume else 1), dtype=wp.int32, device=dev),
        status=wp.zeros(b, dtype=wp.int32, device=dev),
    )
    if resume:
        launch(kernels_for(model.dtype).link_lists, b * n, dev, n_disc=n, capacity=k,
               contact_partner=state.contact_partner, contact_count=state.contact_count,
               contact_mirror_slot=state.contact_mirror_slot)
    return state


def state_to_data(model: Model, state: State) -> RVEData:
    """The state as an :class:`RVEData` (host copy, float64), contact history included;
    each slot holds its pair's tangential force as the pair's owner keeps it."""
    b, n, k = model.n_rve, model.n_disc, model.capacity
    cell = state.cell.numpy().astype(np.float64)
    frac = state.fractional_position.numpy().astype(np.float64).reshape(b, n, 2)
    shear = state.contact_shear_force.numpy().astype(np.float64)
    mirror = state.contact_mirror_slot.numpy()
    count = state.contact_count.numpy()
    partner = state.contact_partner.numpy()
    disc = np.repeat(np.arange(b * n) % n, k)
    # the partner's copy where the partner is the pair's owner (the lower index)
    taken = (mirror >= 0) & (np.arange(k)[None, :] < count[:, None]).reshape(-1)
    taken &= partner < disc
    first_slot = np.repeat(np.arange(b) * n * k, n * k)  # mirrors count from the RVE's first
    shear[taken] = shear[first_slot[taken] + mirror[taken]]
    extra = {
        "contact_partner": state.contact_partner.numpy().reshape(b, n, k),
        "contact_count": count.reshape(b, n),
        "contact_shear_force": shear.reshape(b, n, k),
        "fractional_position": frac,
        "verlet_displacement": state.verlet_displacement.numpy().astype(np.float64)
        .reshape(b, n, 2),
        "cell_at_list_build": state.cell_at_list_build.numpy().astype(np.float64),
    }
    meta = replace(model.meta,
                   timestep=float(model.timestep[0]) if model.explicit_timestep else None)
    return RVEData(
        radius=model.radius.copy(),
        position=np.einsum("bij,bnj->bni", cell, frac),
        cell=cell,
        velocity=state.velocity.numpy().astype(np.float64).reshape(b, n, 2),
        angular_velocity=state.angular_velocity.numpy().astype(np.float64).reshape(b, n),
        meta=meta,
        extra=extra,
    )
