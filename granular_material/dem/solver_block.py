"""The solver's block path: the recorded launches of ``step_block`` and the loop that runs
them, rebuilding the lists of the RVEs that stopped for it, until every RVE has stepped.

:class:`~.solver.Solver` uses it where its ``block`` is set, by default where
:func:`block_path_expected_to_pay`, the engine's rule, says so.
"""

from __future__ import annotations

from typing import Any, Protocol

import warp as wp

from granular_material.dem.kernels.block import BLOCK_DISCS
from granular_material.dem.kernels.sets import block_kernels_for, launch
from granular_material.dem.loading import LoadingControl
from granular_material.dem.model import Model
from granular_material.dem.state import State


class BlockSolver(Protocol):
    """What the block path reads and sets of a :class:`~.solver.Solver`: its device,
    its thread blocks' size and rounds, its replicas, its pair records, the flags of the
    RVEs whose lists need a rebuild and their steps left (stated here so that this module
    needs nothing of ``solver``, which imports it)."""

    device: Any
    block_threads: int
    block_rounds: int
    replica: Any
    pair: Any
    pair_branch: Any
    rebuild: Any
    rebuild_any: Any
    steps_left: Any

__all__ = ["BLOCK_MIN_RVES", "advance_block", "block_launches", "block_path_expected_to_pay"]

#: the fewest RVEs for which the engine steps a CUDA batch with the block path
#: (:mod:`~.kernels_block`, one thread block an RVE); None: never, the block path has not
#: been timed on a GPU yet (no GPU was lent when it was written), so the two-kernel step,
#: timed on an H200, stays the engine's choice until ``benchmarks/gpu_check.sh`` shows
#: from which batch size on the block path is faster
BLOCK_MIN_RVES: int | None = None


def block_path_expected_to_pay(cuda: bool, n_rve: int, n_disc: int) -> bool:
    """The engine's rule for the block path: only on CUDA (``cuda``), only for batches of
    at least :data:`BLOCK_MIN_RVES` RVEs (None: never) whose discs fit the block's shared
    tiles (``n_disc <= BLOCK_DISCS``)."""
    return (cuda and BLOCK_MIN_RVES is not None and n_rve >= BLOCK_MIN_RVES
            and n_disc <= BLOCK_DISCS)


def block_launches(solver: BlockSolver, model: Model, state: State,
                   loading: LoadingControl) -> list[wp.Launch]:
    """``step_block`` (one block of ``solver.block_threads`` threads an RVE) and
    ``block_pending``, recorded for this model, state and loading."""
    kernels = block_kernels_for(model.dtype, solver.replica)
    dev = solver.device
    c = model.constants
    servo = loading.servo
    gain = servo.gain if servo is not None else 0.0
    max_strain = servo.max_strain if servo is not None else 0.0
    return [
        launch(kernels.step_block, model.n_rve, dev, record=True,
               block_dim=solver.block_threads, n_disc=model.n_disc, capacity=model.capacity,
               law=model.law, damping=model.scalar(model.meta.damping),
               servo_on=int(servo is not None),
               thickness=model.scalar(model.meta.thickness), gain=model.scalar(gain),
               max_strain=model.scalar(max_strain), skin=model.scalar(model.skin),
               cutoff=model.scalar(model.cutoff), timestep=c.timestep,
               active=loading.active, friction=c.friction, radius=c.radius,
               inv_mass=c.inv_mass, inv_inertia=c.inv_inertia,
               contact_partner=state.contact_partner, contact_count=state.contact_count,
               contact_mirror_slot=state.contact_mirror_slot,
               contact_shear_force=state.contact_shear_force, control=loading.control,
               target=loading.target, velocity_gradient=loading.velocity_gradient,
               step_map=loading.step_map, cell=state.cell,
               cell_at_list_build=state.cell_at_list_build,
               force_rebuild=state.force_rebuild,
               fractional_position=state.fractional_position, velocity=state.velocity,
               angular_velocity=state.angular_velocity,
               verlet_displacement=state.verlet_displacement, pair=solver.pair,
               pair_branch=solver.pair_branch, steps_left=solver.steps_left,
               rebuild=solver.rebuild, status=state.status),
        launch(kernels.block_pending, 1, dev, record=True, n_rve=model.n_rve,
               steps_left=solver.steps_left, rebuild=solver.rebuild,
               any_flag=solver.rebuild_any),
    ]


def advance_block(solver: BlockSolver, check: list, build: list, step: list, steps: int) -> None:
    """Step every active RVE ``steps`` steps by the block path: the lists' test (as at the
    start of every run), then, until no RVE has steps left, the rebuild of the flagged
    RVEs' lists and a ``step_block`` launch (each RVE steps until it is done or its lists
    may have gone stale). One read-back a round; ``solver.block_rounds`` counts the
    rounds."""
    step_block, pending = step
    solver.steps_left.fill_(steps)
    check[0].launch()  # the flags of the lists' test, as the previous step left them
    while True:
        for recorded in build:
            recorded.launch()
        step_block.launch()
        pending.launch()
        solver.block_rounds += 1
        if not solver.rebuild_any.numpy()[0]:
            return
