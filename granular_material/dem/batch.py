"""DEMBatch: the RVEs, their state and solvers together — the object users and the FEM hold.

On the CPU a warp kernel runs on one thread, so the batch is split into shards (contiguous
groups of RVEs, each with its own Model, State, Solver and copy of the kernel module)
stepped by one thread each; the launches release the GIL, so two shards use two cores. RVEs
are independent, so sharding never changes a result. On CUDA one shard holds the batch.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from granular_material.dem.homogenization import Homogenized, homogenize
from granular_material.dem.model import Model, State, build_model, resolve_device, state_from_data
from granular_material.dem.rve_file import RVEData
from granular_material.dem.solver import DEMInstabilityError, Solver

__all__ = ["BatchSnapshot", "DEMBatch", "Shard"]


@dataclass(eq=False)
class Shard:
    """A contiguous group of RVEs ``first : first + model.n_rve`` of a batch."""

    first: int
    model: Model
    state: State
    solver: Solver

    @property
    def rves(self) -> slice:
        """The shard's RVEs as a slice of the batch."""
        return slice(self.first, self.first + self.model.n_rve)


@dataclass(frozen=True, eq=False)
class BatchSnapshot:
    """Device copies of every shard's state (what ``DEMBatch.snapshot`` returns)."""

    states: tuple[State, ...]


def _slice_data(data: RVEData, rves: slice) -> RVEData:
    return replace(
        data, radius=data.radius[rves], position=data.position[rves], cell=data.cell[rves],
        velocity=data.velocity[rves], angular_velocity=data.angular_velocity[rves],
        extra={k: v[rves] for k, v in data.extra.items()},
    )


class DEMBatch:
    """B periodic RVEs of N discs on one device, advanced together.

    Args:
        data: the RVE batch (e.g. from :func:`load_rve`).
        device: "cpu", "cuda" or None (CUDA when present, else CPU).
        dtype: "float64" (default) or "float32".
        timestep: time step [s] for every RVE; default: ``data.meta.timestep`` if set, else a
            safety fraction of each RVE's critical step.
        shards: number of CPU shards (threads); default: as many as cores, at most B.
    """

    def __init__(
        self,
        data: RVEData,
        device: str | None = None,
        dtype: str = "float64",
        timestep: float | None = None,
        shards: int | None = None,
    ) -> None:
        data.validate()
        device = resolve_device(device)
        if shards is None:
            shards = (os.cpu_count() or 1) if device == "cpu" else 1
        if shards < 1:
            raise ValueError(f"shards must be >= 1, got {shards}")
        shards = min(shards, data.n_rve)
        self.shards: list[Shard] = []
        for replica, part in enumerate(np.array_split(np.arange(data.n_rve), shards)):
            rves = slice(int(part[0]), int(part[-1]) + 1)
            model = build_model(_slice_data(data, rves), device=device, dtype=dtype,
                                timestep=timestep, replica=replica)
            state = state_from_data(model, _slice_data(data, rves))
            solver = Solver(model)
            if state.force_rebuild.numpy().any():
                solver.refresh_neighbors(state)
            self.shards.append(Shard(rves.start, model, state, solver))
        self._pool = ThreadPoolExecutor(len(self.shards)) if len(self.shards) > 1 else None

    # -- shape and parameters -------------------------------------------------------------
    @property
    def n_rve(self) -> int:
        """Number of RVEs B."""
        return sum(s.model.n_rve for s in self.shards)

    @property
    def n_disc(self) -> int:
        """Discs per RVE N."""
        return self.shards[0].model.n_disc

    @property
    def device(self) -> str:
        """The warp device the batch lives on."""
        return self.shards[0].model.device

    @property
    def dt(self) -> np.ndarray:
        """Time step of every RVE [s], shape (B,), float64."""
        return np.concatenate([s.model.dt for s in self.shards])

    def set_friction(self, friction_angle: float) -> None:
        """Set the interparticle friction angle [rad] of every RVE (tangential history kept)."""
        for shard in self.shards:
            shard.model = shard.model.with_friction(friction_angle)
            shard.solver = Solver(shard.model)

    # -- loading and stepping -------------------------------------------------------------
    def set_affine(self, vel_grad: np.ndarray) -> None:
        """Prescribe each RVE's velocity gradient L [1/s], shape (B, 2, 2)."""
        for shard in self.shards:
            shard.solver.set_affine(np.asarray(vel_grad)[shard.rves])

    def set_servo(
        self, control: np.ndarray, target: np.ndarray, gain: float, max_strain: float
    ) -> None:
        """Mixed stress/strain control of xx, yy per RVE (see :meth:`Solver.set_servo`)."""
        for shard in self.shards:
            shard.solver.set_servo(np.asarray(control)[shard.rves],
                                   np.asarray(target)[shard.rves], gain, max_strain)

    def set_active(self, active: np.ndarray) -> None:
        """Which RVEs step (True) and which stay frozen, shape (B,)."""
        for shard in self.shards:
            shard.solver.set_active(np.asarray(active)[shard.rves])

    def run(
        self,
        steps: int,
        check_every: int = 200,
        callback: Callable[[int], bool | None] | None = None,
    ) -> int:
        """Advance every RVE by up to ``steps`` steps (shards in parallel on the CPU).

        Every ``check_every`` steps the state is checked (DEMInstabilityError names the RVEs
        by their batch index) and ``callback(steps_done)`` may return True to stop early.
        Returns the steps run.
        """
        if steps < 0:
            raise ValueError(f"steps must be >= 0, got {steps}")
        done = 0
        while done < steps:
            chunk = min(check_every, steps - done)
            self._run_shards(chunk)
            done += chunk
            if callback is not None and callback(done):
                break
        return done

    def _run_shards(self, steps: int) -> None:
        def one(shard: Shard) -> None:
            shard.solver.run(shard.state, steps, check_every=steps)

        for shard in self.shards:  # record launches and load modules here, not in threads
            shard.solver.prepare(shard.state)
        if self._pool is None:
            results = [self._guard(one, self.shards[0])]
        else:
            results = list(self._pool.map(lambda s: self._guard(one, s), self.shards))
        failures = [r for r in results if r is not None]
        if failures:
            rves = sorted(i for f in failures for i in f.rve)
            reasons = sorted({reason for f in failures for reason in f.reasons})
            raise DEMInstabilityError(rves, reasons)

    @staticmethod
    def _guard(run: Callable[[Shard], None], shard: Shard) -> DEMInstabilityError | None:
        try:
            run(shard)
        except DEMInstabilityError as exc:
            return DEMInstabilityError([shard.first + i for i in exc.rve], exc.reasons)
        return None

    # -- state ----------------------------------------------------------------------------
    def snapshot(self) -> BatchSnapshot:
        """A device copy of the whole dynamic state (commit)."""
        return BatchSnapshot(tuple(s.state.clone() for s in self.shards))

    def restore(self, snapshot: BatchSnapshot) -> None:
        """Make ``snapshot`` the current state again (revert), exactly."""
        for shard, state in zip(self.shards, snapshot.states, strict=True):
            shard.state.assign(state)

    def cell(self) -> np.ndarray:
        """Cell matrices H [m], shape (B, 2, 2), float64."""
        return np.concatenate([s.state.cell.numpy().astype(np.float64) for s in self.shards])

    def set_cell(self, cell: np.ndarray, refresh: bool = True) -> None:
        """Overwrite the cell matrices H [m], shape (B, 2, 2); discs keep their fractional
        coordinates. The neighbour lists are rebuilt for the new cell unless ``refresh`` is
        False (for changes at rounding level: every step checks the lists anyway)."""
        for shard in self.shards:
            shard.state.cell.assign(np.asarray(cell, dtype=np.float64)[shard.rves])
            if refresh:
                shard.solver.refresh_neighbors(shard.state)

    def homogenize(self) -> Homogenized:
        """Stress, tangent, void ratio, coordination, fabric of every RVE."""
        return Homogenized.concatenate([homogenize(s.model, s.state) for s in self.shards])

    def to_data(self) -> RVEData:
        """The batch as an :class:`RVEData` (host copy), contact history included."""
        parts = [_shard_data(s) for s in self.shards]
        first = parts[0]
        return replace(
            first,
            radius=np.concatenate([p.radius for p in parts]),
            position=np.concatenate([p.position for p in parts]),
            cell=np.concatenate([p.cell for p in parts]),
            velocity=np.concatenate([p.velocity for p in parts]),
            angular_velocity=np.concatenate([p.angular_velocity for p in parts]),
            extra={k: np.concatenate([p.extra[k] for p in parts]) for k in first.extra},
        )


def _shard_data(shard: Shard) -> RVEData:
    m, state = shard.model, shard.state
    b, n, k = m.n_rve, m.n_disc, m.capacity
    cell = state.cell.numpy().astype(np.float64)
    frac = state.frac.numpy().astype(np.float64).reshape(b, n, 2)
    extra = {
        "contact_partner": state.nbr.numpy().reshape(b, n, k),
        "contact_count": state.nbr_count.numpy().reshape(b, n),
        "contact_shear_force": state.shear.numpy().astype(np.float64).reshape(b, n, k),
        "fractional_position": frac,
        "verlet_displacement": state.disp.numpy().astype(np.float64).reshape(b, n, 2),
        "cell_at_list_build": state.cell_ref.numpy().astype(np.float64),
    }
    meta = replace(m.meta, timestep=float(m.dt[0]) if m.explicit_timestep else None)
    return RVEData(
        radius=m.radius_host.copy(),
        position=np.einsum("bij,bnj->bni", cell, frac),
        cell=cell,
        velocity=state.vel.numpy().astype(np.float64).reshape(b, n, 2),
        angular_velocity=state.ang_vel.numpy().astype(np.float64).reshape(b, n),
        meta=meta,
        extra=extra,
    )
