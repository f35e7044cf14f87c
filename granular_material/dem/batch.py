"""DEMBatch: the RVEs, their state and solvers together — the object users and the FEM hold.

On the CPU a warp kernel runs on one thread, so the batch is split into shards (contiguous
groups of RVEs, each with its own Model, State, LoadingControl and Solver) and each thread
steps its lane of shards, one after the other, with its own copy of the kernel module; the
launches release the GIL, so two threads use two cores, and a shard small enough to stay in
cache is stepped a whole block of steps at a time. RVEs are independent, so sharding never
changes a result. On CUDA one shard holds the batch.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from granular_material.dem.cell_basis import rebase_state
from granular_material.dem.homogenization import Homogenized, MeasureBuffers, homogenize
from granular_material.dem.loading import LoadingControl, ServoSettings
from granular_material.dem.model import Model, build_model, resolve_device
from granular_material.dem.rve.checks import validate_rve
from granular_material.dem.rve.file import RVEData
from granular_material.dem.solver import DEMInstabilityError, Solver
from granular_material.dem.state import State, state_from_data, state_to_data

__all__ = ["CPU_SHARD_DISCS", "BatchSnapshot", "DEMBatch", "Shard"]

#: a cell whose perpendicular height is below this many times the engine's limit (twice the
#: contact cut-off) takes its lattice's least skewed basis (:meth:`DEMBatch.rebase_thin_cells`):
#: close to the limit, so that only RVEs about to stop are re-described (the others stay bit
#: for bit as they were), and far enough that a load step's shear (a path that would cross
#: the limit is refused and cut back, then rebased at its commit) seldom reaches it first
REBASE_MARGIN = 1.1


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The runs ``(first, stop)`` of consecutive True entries of a 1-D boolean mask."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(),
                    strict=True))

#: most discs in one CPU shard: a thread steps its shards one after the other, each for a
#: whole block of steps, so that a shard's arrays stay in cache (measured with 400-disc
#: RVEs in benchmarks/dem_throughput.py: 16 to 32 RVEs a shard keep the rate of B = 16)
CPU_SHARD_DISCS = 8000


@dataclass(eq=False)
class Shard:
    """A contiguous group of RVEs ``first : first + model.n_rve`` of a batch."""

    first: int
    model: Model
    state: State
    loading: LoadingControl
    solver: Solver
    measures: MeasureBuffers

    @property
    def rves(self) -> slice:
        """The shard's RVEs as a slice of the batch."""
        return slice(self.first, self.first + self.model.n_rve)

    def run(self, steps: int, check_every: int = 200,
            callback: Callable[[int], bool | None] | None = None) -> int:
        """Advance the shard's state by up to ``steps`` steps (see :meth:`Solver.run`)."""
        return self.solver.run(self.model, self.state, self.loading, steps, check_every,
                               callback)


@dataclass(frozen=True, eq=False)
class BatchSnapshot:
    """Device copies of every shard's state (what ``DEMBatch.snapshot`` returns)."""

    states: tuple[State, ...]


class DEMBatch:
    """B periodic RVEs of N discs on one device, advanced together.

    Args:
        data: the RVE batch (e.g. from :func:`load_rve`).
        device: "cpu", "cuda" or None (CUDA when present, else CPU).
        dtype: "float64" (default) or "float32".
        timestep: time step [s] for every RVE; default: ``data.meta.timestep`` if set, else a
            safety fraction of each RVE's critical step.
        shards: number of CPU threads; default: as many as cores, at most B. Each thread
            steps its own shards of at most ``CPU_SHARD_DISCS`` discs, one after the
            other.
    """

    def __init__(
        self,
        data: RVEData,
        device: str | None = None,
        dtype: str = "float64",
        timestep: float | None = None,
        shards: int | None = None,
    ) -> None:
        validate_rve(data)
        device = resolve_device(device)
        if shards is None:
            shards = (os.cpu_count() or 1) if device == "cpu" else 1
        if shards < 1:
            raise ValueError(f"shards must be >= 1, got {shards}")
        threads = min(shards, data.n_rve)
        per_shard = max(1, CPU_SHARD_DISCS // data.n_disc) if device == "cpu" else data.n_rve
        count = max(threads, math.ceil(data.n_rve / per_shard))
        self.shards: list[Shard] = []
        for index, part in enumerate(np.array_split(np.arange(data.n_rve), count)):
            part_data = data.take(slice(int(part[0]), int(part[-1]) + 1))
            model = build_model(part_data, device=device, dtype=dtype, timestep=timestep)
            solver = Solver(model, replica=index % threads)  # one kernel module per thread
            shard = Shard(int(part[0]), model, state_from_data(model, part_data),
                          LoadingControl(model), solver, MeasureBuffers(model))
            if shard.state.force_rebuild.numpy().any():
                shard.solver.refresh_lists(shard.model, shard.state, shard.loading)
            self.shards.append(shard)
        #: the shards each thread steps, one after the other
        self.lanes = [self.shards[t::threads] for t in range(threads)]
        self._pool = ThreadPoolExecutor(threads) if threads > 1 else None

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
    def dtype(self) -> str:
        """The float type of the device arrays ("float64" or "float32")."""
        return self.shards[0].model.dtype

    @property
    def dt(self) -> np.ndarray:
        """Time step of every RVE [s], shape (B,), float64."""
        return np.concatenate([s.model.timestep for s in self.shards])

    @property
    def cutoff(self) -> np.ndarray:
        """Contact cut-off 2·r_max + skin [m] of every RVE, shape (B,) (its shard's): the
        engine stops an RVE whose cell's perpendicular height falls to twice it."""
        return np.concatenate([np.full(s.model.n_rve, s.model.cutoff) for s in self.shards])

    def set_friction(self, friction_angle: float) -> None:
        """Set the interparticle friction angle [rad] of every RVE; the tangential history
        and the loading are kept."""
        for shard in self.shards:
            shard.model = shard.model.with_friction(friction_angle)

    # -- loading and stepping -------------------------------------------------------------
    def set_affine(self, vel_grad: np.ndarray) -> None:
        """Prescribe each RVE's velocity gradient L [1/s], shape (B, 2, 2)."""
        for shard in self.shards:
            shard.loading.set_affine(np.asarray(vel_grad)[shard.rves])

    def set_servo(
        self, control: np.ndarray, target: np.ndarray, gain: float, max_strain: float
    ) -> None:
        """Mixed stress/strain control of xx, yy per RVE (see
        :meth:`LoadingControl.set_servo`): ``control`` and ``target`` of shape (B, 2)."""
        settings = ServoSettings(float(gain), float(max_strain))
        for shard in self.shards:
            shard.loading.set_servo(np.asarray(control)[shard.rves],
                                    np.asarray(target)[shard.rves], settings)

    def set_active(self, active: np.ndarray) -> None:
        """Which RVEs step (True) and which stay frozen, shape (B,)."""
        for shard in self.shards:
            shard.loading.set_active(np.asarray(active)[shard.rves])

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
        stepping = [s for s in self.shards if s.loading.any_active]  # a frozen shard waits
        for shard in stepping:  # record launches and load modules here, not in threads
            shard.solver.prepare(shard.model, shard.state, shard.loading)

        def lane(shards: list[Shard]) -> list[DEMInstabilityError | None]:
            return [self._guard(shard, steps) for shard in shards if shard.loading.any_active]

        if self._pool is None:
            results = lane(stepping)
        else:
            results = [r for part in self._pool.map(lane, self.lanes) for r in part]
        failures = [r for r in results if r is not None]
        if failures:
            rves = sorted(i for f in failures for i in f.rve)
            reasons = sorted({reason for f in failures for reason in f.reasons})
            raise DEMInstabilityError(rves, reasons)

    @staticmethod
    def _guard(shard: Shard, steps: int) -> DEMInstabilityError | None:
        try:
            shard.run(steps, check_every=steps)
        except DEMInstabilityError as exc:
            return DEMInstabilityError([shard.first + i for i in exc.rve], exc.reasons)
        return None

    # -- state ----------------------------------------------------------------------------
    def snapshot(self) -> BatchSnapshot:
        """A device copy of the whole dynamic state (commit)."""
        return BatchSnapshot(tuple(s.state.clone() for s in self.shards))

    def restore(self, snapshot: BatchSnapshot, rves: np.ndarray | None = None) -> None:
        """Make ``snapshot`` the current state again (revert), exactly: of every RVE, or
        only of those where the mask ``rves`` (B,) is True (the others keep their state)."""
        for shard, state in zip(self.shards, snapshot.states, strict=True):
            if rves is None:
                shard.state.assign(state)
            else:
                mine = np.asarray(rves, dtype=bool)[shard.rves]
                if not mine.any():
                    continue
                if mine.all():
                    shard.state.assign(state)
                else:
                    for first, stop in _runs(mine):
                        shard.state.assign_rves(state, first, stop, shard.model.n_rve)
            shard.solver.forget_pairs()

    def cell(self) -> np.ndarray:
        """Cell matrices H [m], shape (B, 2, 2), float64."""
        return np.concatenate([s.state.cell.numpy().astype(np.float64) for s in self.shards])

    def rebase_cells(self, rves: np.ndarray) -> np.ndarray:
        """Re-describe the cell of each RVE where the mask ``rves`` (B,) is True by its
        lattice's least skewed basis (:mod:`granular_material.dem.cell_basis`): the same
        packing, contacts and velocities, larger perpendicular heights; its neighbour lists
        are rebuilt at its next step. Returns the mask (B,) of the RVEs whose basis changed."""
        wanted = np.asarray(rves, dtype=bool)
        changed = np.zeros(self.n_rve, dtype=bool)
        for shard in self.shards:
            mine = np.flatnonzero(wanted[shard.rves])
            if not mine.size:
                continue
            state = shard.state
            cell = state.cell.numpy()
            frac = state.fractional_position.numpy().reshape(cell.shape[0], -1, 2)
            rebuild = state.force_rebuild.numpy()
            for b in mine:
                cell_b, frac_b, moved = rebase_state(cell[b], frac[b])
                if moved:
                    cell[b], frac[b], rebuild[b] = cell_b, frac_b, 1
                    frac[b][frac[b] >= 1.0] = 0.0  # 1 - ε rounded up in float32 wraps to 0
                    changed[shard.first + b] = True
            if changed[shard.rves].any():
                state.cell.assign(cell)
                state.fractional_position.assign(frac.reshape(-1, 2))
                state.force_rebuild.assign(rebuild)
        return changed

    def rebase_thin_cells(self, margin: float = REBASE_MARGIN) -> np.ndarray:
        """:meth:`rebase_cells` of every RVE whose cell's perpendicular height is below
        ``margin`` times the engine's limit (twice the contact cut-off); the mask (B,) of
        those whose basis changed."""
        from granular_material.dem.model import cell_heights

        return self.rebase_cells(cell_heights(self.cell()) < margin * 2.0 * self.cutoff)

    def set_cell(self, cell: np.ndarray, refresh: bool = True) -> None:
        """Overwrite the cell matrices H [m], shape (B, 2, 2); discs keep their fractional
        coordinates. The neighbour lists are rebuilt for the new cell unless ``refresh`` is
        False (for changes at rounding level: every step checks the lists anyway)."""
        for shard in self.shards:
            shard.state.cell.assign(np.asarray(cell, dtype=np.float64)[shard.rves])
            if refresh:
                shard.solver.refresh_lists(shard.model, shard.state, shard.loading)

    def summary(self, homogenized: Homogenized | None = None) -> dict[str, Any]:
        """The batch's state as JSON values, each a list over the RVEs (the value itself for
        one RVE): ``void_ratio``, ``mean_stress`` [Pa], ``coordination``, ``cell`` [m],
        ``particles`` and ``batch`` (counts), ``timestep`` [s]; ``homogenized``: this state's
        measures where the caller has them."""
        h = self.homogenize() if homogenized is None else homogenized

        def batch_value(values: np.ndarray) -> Any:
            listed = np.asarray(values).tolist()
            return listed[0] if self.n_rve == 1 else listed

        return {"void_ratio": batch_value(h.void_ratio),
                "mean_stress": batch_value(h.mean_stress),
                "coordination": batch_value(h.coordination), "cell": batch_value(self.cell()),
                "particles": self.n_disc, "batch": self.n_rve,
                "timestep": batch_value(self.dt)}

    def homogenize(self, rves: np.ndarray | None = None) -> Homogenized:
        """Stress, tangent, void ratio, coordination, fabric of every RVE, or with the
        boolean mask ``rves`` (B,) of the masked RVEs only, in batch order (shards without
        a masked RVE are not measured)."""
        if rves is None:
            return Homogenized.concatenate([
                homogenize(s.model, s.state, s.measures, s.solver.kernels) for s in self.shards
            ])
        mask = np.asarray(rves, dtype=bool)
        parts = [homogenize(s.model, s.state, s.measures, s.solver.kernels).take(mask[s.rves])
                 for s in self.shards if mask[s.rves].any()]
        if not parts:
            return self.homogenize().take(mask)  # empty, of the right shapes
        return Homogenized.concatenate(parts)

    def to_data(self) -> RVEData:
        """The batch as an :class:`RVEData` (host copy), contact history included."""
        return RVEData.concatenate([state_to_data(s.model, s.state) for s in self.shards])
