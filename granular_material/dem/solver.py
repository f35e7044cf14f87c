"""Time stepping of a DEM batch: one launch per stage for all RVEs, guarded against blow-up."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import warp as wp

from granular_material.dem.kernels.block import BLOCK_DISCS, BLOCK_THREADS
from granular_material.dem.kernels.common import (
    CONTROL_STRAIN,
    CONTROL_STRESS,
    STATUS_BLOWUP,
    STATUS_CELL_TOO_SMALL,
    STATUS_COINCIDENT,
    STATUS_OVERFLOW,
)
from granular_material.dem.kernels.sets import (
    StepFeatures,
    StepKernels,
    kernels_for,
    launch,
    step_kernels_for,
)
from granular_material.dem.loading import LoadingControl
from granular_material.dem.model import Model
from granular_material.dem.solver_block import (
    advance_block,
    block_launches,
    block_path_expected_to_pay,
)
from granular_material.dem.state import State

__all__ = ["BIN_CAPACITY", "CONTROL_STRAIN", "CONTROL_STRESS", "DEMInstabilityError", "Solver"]

BIN_CAPACITY = 32  #: discs a contact-detection bin can hold (an overflow is an error)
GRAPH_STEPS = 50  #: steps captured in one graph and replayed

_MESSAGES = {
    STATUS_BLOWUP: "a velocity became non-finite or a disc moved more than r/4 in one step "
    "(time step too large, or the loading too violent)",
    STATUS_OVERFLOW: "a neighbour list overflowed its capacity (discs far too compressed)",
    STATUS_CELL_TOO_SMALL: "the cell became too small or too sheared for its discs "
    "(contact cut-off above half a cell height)",
    STATUS_COINCIDENT: "two disc centres coincide",
}


class DEMInstabilityError(RuntimeError):
    """The state of one or more RVEs blew up; ``rve`` lists their indices."""

    def __init__(self, rve: list[int], reasons: list[str]) -> None:
        self.rve = rve
        self.reasons = reasons
        shown = ", ".join(map(str, rve[:20])) + (" ..." if len(rve) > 20 else "")
        super().__init__(f"DEM state of RVE(s) {shown} is invalid: " + "; ".join(reasons))


def _record(kernel: wp.Kernel, dim: int, device: str, **arguments: Any) -> wp.Launch:
    return launch(kernel, dim, device, record=True, **arguments)


class Solver:
    """Advances a :class:`State` of a :class:`Model` under a :class:`LoadingControl`.

    Each step: contact forces of the pairs each disc owns, their gather with local damping
    and leap-frog integration (on CUDA two kernels, a thread per disc; on the CPU one serial
    pass per RVE that adds each pair to both discs, ``step_serial``), optionally the
    stress servo, the cell update ``H ← E·H`` and the test of the Verlet skin; where the
    skin may have closed, the next step first rebuilds that RVE's lists (candidates from the
    3 × 3 bins of a per-RVE grid in fractional coordinates, or all discs in a cell under 3
    bins across). Blocks of steps are captured
    and replayed as one graph (CUDA graphs; on the CPU warp's launch capture, with the
    rebuild under the condition that some RVE needs it).

    The block path (``block``; :mod:`~.kernels_block`, :mod:`~.solver_block`) does the
    same steps with one thread block an RVE, many steps a launch, each RVE stopping where
    its lists need a rebuild; the engine takes it only where
    :func:`block_path_expected_to_pay` says so (at present never: see
    :data:`~.solver_block.BLOCK_MIN_RVES`).

    The step kernels are the variant (see :func:`step_kernels_for`) that leaves out what the
    scene makes irrelevant: the tangential force and its history where every RVE of the
    model is frictionless, local damping where the damping is 0, and then also the stress
    sums' code where no servo runs; see :meth:`step_features`. It is picked again whenever
    the model or the servo changes (a new model from :meth:`Model.with_friction`,
    ``set_servo``, ``set_affine``), and the recorded launches and the graph follow.

    Notes:
        The lists stay valid while ``2·max|Δx_fluct| + |H H_build⁻¹ − I|·cutoff ≤ skin``.

    Args:
        model: gives the sizes and float type of the work arrays; any model of the same
            sizes (e.g. :meth:`Model.with_friction`) may be stepped.
        replica: the kernel module to launch (one per CPU thread, see ``kernels_for``).
        features: the step kernels to use whatever the scene (``kernels.GENERIC_STEP`` forces
            the generic ones; a variant must fit the scene); None: picked from the scene.
        serial: step with ``step_serial``, a thread per RVE (True) or with
            ``contact_forces`` and ``integrate``, a thread per disc (False); None: serial on
            the CPU, where a kernel's threads run one after the other anyway.
        block: step with the block path (True; for tests and benchmarks) or not (False);
            None: the engine's rule, :func:`block_path_expected_to_pay`.
    """

    def __init__(self, model: Model, replica: int = 0,
                 features: StepFeatures | None = None, serial: bool | None = None,
                 block: bool | None = None) -> None:
        self.kernels = kernels_for(model.dtype, replica)
        self.replica = replica
        #: the step kernels used whatever the scene, or None to pick them from the scene
        self.features = features
        ft = model.float_type
        dev = model.device
        b, n, k = model.n_rve, model.n_disc, model.capacity
        vec2 = wp.types.vector(2, ft)
        self.device = dev
        self._sizes = (b, n, k, ft)
        self._block = False
        self._graphs: dict[tuple, wp.Graph] = {}
        # keyed by the ids of (model, state, loading); each entry holds those objects, so
        # that an id is never reused by another object while its launches are cached
        self._recorded: dict[tuple, tuple[tuple, tuple[list, list, list]]] = {}
        self.rebuild = wp.zeros(b, dtype=wp.int32, device=dev)
        self.partner_new = wp.zeros(b * n * k, dtype=wp.int32, device=dev)
        self.count_new = wp.zeros(b * n, dtype=wp.int32, device=dev)
        self.shear_new = wp.zeros(b * n * k, dtype=ft, device=dev)
        self.bin_count = wp.zeros(b * model.max_bins**2, dtype=wp.int32, device=dev)
        self.bin_items = wp.zeros(b * model.max_bins**2 * BIN_CAPACITY, dtype=wp.int32,
                                  device=dev)
        self.serial = not wp.get_device(dev).is_cuda if serial is None else serial
        #: threads a block of the block path asks for (on the CPU one, unless
        #: ``warp.config.enable_cpu_blocks``)
        self.block_threads = BLOCK_THREADS
        #: rounds of the block path so far (a ``step_block`` launch each, after the
        #: rebuild of the lists of the RVEs that stopped for it)
        self.block_rounds = 0
        self.block = (block_path_expected_to_pay(wp.get_device(dev).is_cuda, b, n)
                      if block is None else block)
        self.part_stress = wp.zeros(b * n, dtype=wp.types.matrix((2, 2), ft), device=dev)
        self.part_stiffness = wp.zeros(b * n, dtype=vec2, device=dev)
        self.rebuild_any = wp.zeros(1, dtype=wp.int32, device=dev)
        self._host_rebuild = None if wp.get_device(dev).is_cuda else self.rebuild_any.numpy()

    @property
    def serial(self) -> bool:
        """Whether a step is ``step_serial`` (a thread per RVE) rather than two kernels."""
        return self._serial

    @serial.setter
    def serial(self, value: bool) -> None:
        self._serial = bool(value)
        self._allocate_step_buffers()

    @property
    def block(self) -> bool:
        """Whether a step is the block path's (``step_block``: one thread block an RVE,
        many steps a launch); it takes precedence over ``serial``."""
        return self._block

    @block.setter
    def block(self, value: bool) -> None:
        n_disc = self._sizes[1]
        if value and n_disc > BLOCK_DISCS:
            raise ValueError(f"the block path holds at most {BLOCK_DISCS} discs an RVE in "
                             f"shared memory, got {n_disc}")
        self._block = bool(value)
        self._allocate_step_buffers()

    def _allocate_step_buffers(self) -> None:
        """The work arrays of this step path only, the others empty: the pairs' force
        records ``pair`` and ``pair_branch`` (per slot) for ``contact_forces`` →
        ``integrate`` and the block path, ``disc_load`` (per disc) for ``step_serial``, the
        steps each RVE has left for the block path. Fresh records are zero, as a step
        expects of a pair that has not touched yet; the launches recorded with the old
        arrays are dropped."""
        self._recorded.clear()
        self._graphs.clear()
        n_rve, n_disc, k, ft = self._sizes
        discs = n_rve * n_disc
        vec3 = wp.types.vector(3, ft)
        serial = self.serial and not self.block
        slots = 0 if serial else discs * k
        self.pair = wp.zeros(slots, dtype=vec3, device=self.device)
        self.pair_branch = wp.zeros(slots, dtype=wp.types.vector(2, ft), device=self.device)
        self.disc_load = wp.zeros(discs if serial else 0, dtype=vec3, device=self.device)
        self.steps_left = wp.zeros(n_rve if self.block else 0, dtype=wp.int32,
                                   device=self.device)

    # -- recorded launches ----------------------------------------------------------------
    def _check_launch(self, model: Model, state: State, loading: LoadingControl) -> wp.Launch:
        return _record(
            self.kernels.check_lists, model.n_rve, self.device, n_disc=model.n_disc,
            skin=model.scalar(model.skin), cutoff=model.scalar(model.cutoff),
            active=loading.active, cell=state.cell,
            cell_at_list_build=state.cell_at_list_build,
            verlet_displacement=state.verlet_displacement, force_rebuild=state.force_rebuild,
            rebuild=self.rebuild, status=state.status,
        )

    def _any_launch(self, model: Model) -> wp.Launch:
        return _record(self.kernels.any_rebuild, 1, self.device, n_rve=model.n_rve,
                       rebuild=self.rebuild, any_flag=self.rebuild_any)

    def _build_launches(self, model: Model, state: State) -> list[wp.Launch]:
        ks, dev = self.kernels, self.device
        b, n, k = model.n_rve, model.n_disc, model.capacity
        cutoff = model.scalar(model.cutoff)
        return [
            _record(ks.begin_build, b, dev, max_bins=model.max_bins, rebuild=self.rebuild,
                    cell=state.cell, cell_at_list_build=state.cell_at_list_build,
                    force_rebuild=state.force_rebuild, bin_count=self.bin_count),
            _record(ks.fill_bins, b * n, dev, n_disc=n, max_bins=model.max_bins,
                    bin_capacity=BIN_CAPACITY, cutoff=cutoff, rebuild=self.rebuild,
                    cell=state.cell, fractional_position=state.fractional_position,
                    bin_count=self.bin_count, bin_items=self.bin_items, status=state.status),
            _record(ks.build_lists, b * n, dev, n_disc=n, capacity=k,
                    max_bins=model.max_bins, bin_capacity=BIN_CAPACITY,
                    skin=model.scalar(model.skin), cutoff=cutoff, rebuild=self.rebuild,
                    cell=state.cell, fractional_position=state.fractional_position,
                    radius=model.constants.radius, bin_count=self.bin_count,
                    bin_items=self.bin_items, contact_partner=state.contact_partner,
                    contact_count=state.contact_count,
                    contact_shear_force=state.contact_shear_force,
                    partner_new=self.partner_new, count_new=self.count_new,
                    shear_new=self.shear_new, status=state.status),
            _record(ks.commit_lists, b * n, dev, n_disc=n, capacity=k, rebuild=self.rebuild,
                    partner_new=self.partner_new, count_new=self.count_new,
                    shear_new=self.shear_new, contact_partner=state.contact_partner,
                    contact_count=state.contact_count,
                    contact_shear_force=state.contact_shear_force,
                    contact_mirror_slot=state.contact_mirror_slot,
                    verlet_displacement=state.verlet_displacement, pair=self.pair),
        ]

    def step_features(self, model: Model, loading: LoadingControl) -> StepFeatures:
        """The terms the step computes for ``model`` under ``loading``: ``self.features``
        if set, else only those the scene needs (reads the friction back from the device).

        The stress sums' code is left out (no servo) only where a variant is built anyway:
        behind the generic kernels' run-time test of ``with_stress`` it costs nothing
        measurable, and so a frictional, damped scene needs no module but the generic one."""
        if self.features is not None:
            return self.features
        tangential = bool(np.any(model.constants.friction.numpy() != 0))
        damping = model.meta.damping != 0
        stress = loading.servo is not None or (tangential and damping)
        return StepFeatures(tangential=tangential, damping=damping, stress=stress)

    def _step_launches(self, model: Model, state: State,
                       loading: LoadingControl) -> list[wp.Launch]:
        ks, dev = self.kernels, self.device
        sk = step_kernels_for(model.dtype, self.replica, self.step_features(model, loading))
        b, n, k = model.n_rve, model.n_disc, model.capacity
        c = model.constants
        servo = loading.servo
        if self.block:  # the servo and the cell's update are the block's own
            return block_launches(self, model, state, loading)
        if self.serial:
            launches = [_record(
                sk.step_serial, b, dev, n_disc=n, capacity=k, law=model.law,
                damping=model.scalar(model.meta.damping), with_stress=int(servo is not None),
                timestep=c.timestep, active=loading.active, friction=c.friction,
                cell=state.cell, velocity_gradient=loading.velocity_gradient,
                radius=c.radius, inv_mass=c.inv_mass, inv_inertia=c.inv_inertia,
                contact_partner=state.contact_partner, contact_count=state.contact_count,
                contact_shear_force=state.contact_shear_force,
                fractional_position=state.fractional_position, velocity=state.velocity,
                angular_velocity=state.angular_velocity,
                verlet_displacement=state.verlet_displacement, disc_load=self.disc_load,
                part_stress=self.part_stress, part_stiffness=self.part_stiffness,
                status=state.status,
            )]
        else:
            launches = self._parallel_launches(model, state, loading, sk)
        if servo is not None:
            launches.append(_record(
                ks.servo, b, dev, n_disc=n, thickness=model.scalar(model.meta.thickness),
                gain=model.scalar(servo.gain), max_strain=model.scalar(servo.max_strain),
                timestep=c.timestep, active=loading.active, cell=state.cell,
                part_stress=self.part_stress, part_stiffness=self.part_stiffness,
                control=loading.control, target=loading.target,
                velocity_gradient=loading.velocity_gradient, step_map=loading.step_map,
            ))
        launches.append(_record(
            ks.advance_cell_and_check, b, dev, n_disc=n, skin=model.scalar(model.skin),
            cutoff=model.scalar(model.cutoff), active=loading.active,
            step_map=loading.step_map, cell=state.cell,
            cell_at_list_build=state.cell_at_list_build,
            verlet_displacement=state.verlet_displacement, force_rebuild=state.force_rebuild,
            rebuild=self.rebuild, status=state.status,
        ))
        if self._host_rebuild is not None:
            launches.append(self._any_launch(model))
        return launches

    def _parallel_launches(self, model: Model, state: State, loading: LoadingControl,
                           sk: StepKernels) -> list[wp.Launch]:
        """``contact_forces`` and ``integrate``, a thread per disc (CUDA)."""
        dev = self.device
        b, n, k = model.n_rve, model.n_disc, model.capacity
        c = model.constants
        servo = loading.servo
        return [
            _record(sk.contact_forces, b * n, dev, n_disc=n, capacity=k, law=model.law,
                    timestep=c.timestep, active=loading.active, friction=c.friction,
                    cell=state.cell, velocity_gradient=loading.velocity_gradient,
                    fractional_position=state.fractional_position, velocity=state.velocity,
                    angular_velocity=state.angular_velocity, radius=c.radius,
                    contact_partner=state.contact_partner, contact_count=state.contact_count,
                    contact_mirror_slot=state.contact_mirror_slot,
                    contact_shear_force=state.contact_shear_force,
                    with_stress=int(servo is not None), pair=self.pair,
                    pair_branch=self.pair_branch, status=state.status),
            _record(sk.integrate, b * n, dev, n_disc=n, capacity=k, law=model.law,
                    damping=model.scalar(model.meta.damping),
                    with_stress=int(servo is not None), timestep=c.timestep,
                    active=loading.active, cell=state.cell, radius=c.radius,
                    inv_mass=c.inv_mass, inv_inertia=c.inv_inertia,
                    contact_partner=state.contact_partner, contact_count=state.contact_count,
                    pair=self.pair, pair_branch=self.pair_branch,
                    fractional_position=state.fractional_position, velocity=state.velocity,
                    angular_velocity=state.angular_velocity,
                    verlet_displacement=state.verlet_displacement, part_stress=self.part_stress,
                    part_stiffness=self.part_stiffness, status=state.status),
        ]

    def _key(self, model: Model, state: State, loading: LoadingControl) -> tuple:
        return (id(model), id(state), id(loading), loading.servo, self.features, self.serial,
                self.block, self.block_threads)

    def prepare(self, model: Model, state: State, loading: LoadingControl) -> tuple:
        """The recorded launches (check, build, step) for this model, state and loading,
        recorded (and the kernel module loaded) on first use. Call it from the main thread
        before stepping shards in threads: warp's module loading is not for concurrent use."""
        key = self._key(model, state, loading)
        if key not in self._recorded:
            if len(self._recorded) > 16:  # states and models come and go: keep a few
                self._recorded.clear()
                self._graphs.clear()
            self._recorded[key] = ((model, state, loading), (
                [self._check_launch(model, state, loading), self._any_launch(model)],
                self._build_launches(model, state),
                self._step_launches(model, state, loading),
            ))
            _, build, step = self._recorded[key][1]
            if not self.block:  # the block path runs many steps a launch, uncaptured
                self._graphs[key] = self._capture(build, step)
        return self._recorded[key][1]

    # -- stepping -------------------------------------------------------------------------
    def run(
        self,
        model: Model,
        state: State,
        loading: LoadingControl,
        steps: int,
        check_every: int = 200,
        callback: Callable[[int], bool | None] | None = None,
    ) -> int:
        """Advance ``state`` by up to ``steps`` steps; returns the number run.

        Every ``check_every`` steps (and at the end) the RVE status is read back: an invalid
        state raises :class:`DEMInstabilityError`; then ``callback(steps_done)`` may return
        True to stop early.
        """
        if steps < 0:
            raise ValueError(f"steps must be >= 0, got {steps}")
        check, build, step = self.prepare(model, state, loading)
        for recorded in check:
            recorded.launch()
        done = 0
        while done < steps:
            chunk = min(check_every, steps - done)
            if self.block:
                advance_block(self, check, build, step, chunk)
            else:
                self._advance(self._key(model, state, loading), build, step, chunk)
            done += chunk
            self.check(state)
            if callback is not None and callback(done):
                break
        return done

    def _advance(self, key: tuple, build: list, step: list, steps: int) -> None:
        """Launch ``steps`` steps; whole blocks of GRAPH_STEPS replay one captured graph (on
        the CPU with the rebuild captured under its condition, on CUDA unconditionally: the
        build kernels do nothing for RVEs that keep their lists)."""
        eager = steps
        if steps >= GRAPH_STEPS:
            graph = self._graphs[key]  # captured by prepare(), in the main thread
            for _ in range(steps // GRAPH_STEPS):
                wp.capture_launch(graph)
            eager = steps % GRAPH_STEPS
        flags = self._host_rebuild
        for _ in range(eager):
            if flags is None or flags[0]:  # on the CPU, launches are synchronous
                for recorded in build:
                    recorded.launch()
            for recorded in step:
                recorded.launch()

    def _capture(self, build: list, step: list) -> wp.Graph:
        def rebuild() -> None:
            for recorded in build:
                recorded.launch()

        cpu = self._host_rebuild is not None
        with wp.ScopedCapture(device=self.device, apic=cpu) as capture:
            for _ in range(GRAPH_STEPS):
                if cpu:
                    wp.capture_if(self.rebuild_any, on_true=rebuild)
                else:
                    rebuild()
                for recorded in step:
                    recorded.launch()
        return capture.graph

    def refresh_lists(self, model: Model, state: State, loading: LoadingControl) -> None:
        """Rebuild the neighbour lists of every active RVE now (tangential history kept)."""
        state.force_rebuild.fill_(1)
        check, build, _ = self.prepare(model, state, loading)
        for recorded in check:
            recorded.launch()
        for recorded in build:
            recorded.launch()
        self.check(state)

    def forget_pairs(self) -> None:
        """Zero the pairs' force records: call it when the state's lists were replaced
        other than by a build (a restored snapshot), as each step writes a separated pair's
        records only where its own is not zero yet."""
        self.pair.zero_()

    def check(self, state: State) -> None:
        """Raise :class:`DEMInstabilityError` if any RVE's status has an error bit."""
        status = state.status.numpy()
        bad = np.flatnonzero(status)
        if bad.size == 0:
            return
        bits = int(np.bitwise_or.reduce(status[bad]))
        reasons = [msg for bit, msg in _MESSAGES.items() if bits & bit]
        raise DEMInstabilityError(bad.tolist(), reasons)
