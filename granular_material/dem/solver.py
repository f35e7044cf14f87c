"""Time stepping of a DEM batch: one launch per stage for all RVEs, guarded against blow-up."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import warp as wp

from granular_material.dem.kernels import (
    STATUS_BLOWUP,
    STATUS_CELL_TOO_SMALL,
    STATUS_COINCIDENT,
    STATUS_OVERFLOW,
)
from granular_material.dem.model import Model, State

__all__ = ["BIN_CAPACITY", "CONTROL_STRAIN", "CONTROL_STRESS", "DEMInstabilityError", "Solver"]

BIN_CAPACITY = 32  #: discs a contact-detection bin can hold (an overflow is an error)
GRAPH_STEPS = 50  #: steps captured in one CUDA graph and replayed

CONTROL_STRAIN = 0  #: a diagonal component driven at a prescribed strain per step
CONTROL_STRESS = 1  #: a diagonal component servo-controlled to a target stress

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


class Solver:
    """Advances a :class:`State` of a :class:`Model`; holds the per-step work arrays.

    Each step: rebuild stale neighbour lists (Verlet skin; candidates from the 3 × 3 bins of
    a per-RVE grid in fractional coordinates, or all discs in a cell under 3 bins across),
    contact forces, optionally the stress servo, leap-frog integration with local damping,
    cell update ``H ← E·H``.
    The loading is set per RVE through :meth:`set_affine` (prescribed velocity gradient) or
    :meth:`set_servo` (mixed stress/strain control of the diagonal components).
    """

    def __init__(self, model: Model) -> None:
        self.model = model
        ks = model.kernels
        dev = model.device
        b, n, k = model.n_rve, model.n_disc, model.capacity
        self.active = wp.ones(b, dtype=wp.int32, device=dev)
        self.rebuild = wp.zeros(b, dtype=wp.int32, device=dev)
        self.nbr_new = wp.zeros(b * n * k, dtype=wp.int32, device=dev)
        self.nbr_count_new = wp.zeros(b * n, dtype=wp.int32, device=dev)
        self.shear_new = wp.zeros(b * n * k, dtype=ks.float_type, device=dev)
        self.bin_count = wp.zeros(b * model.max_bins**2, dtype=wp.int32, device=dev)
        self.bin_items = wp.zeros(b * model.max_bins**2 * BIN_CAPACITY, dtype=wp.int32,
                                  device=dev)
        self.force = wp.zeros(b * n, dtype=ks.vec2, device=dev)
        self.torque = wp.zeros(b * n, dtype=ks.float_type, device=dev)
        self.part_stress = wp.zeros(b * n, dtype=ks.mat22, device=dev)
        self.part_stiff = wp.zeros(b * n, dtype=ks.vec2, device=dev)
        self.vel_grad = wp.zeros(b, dtype=ks.mat22, device=dev)
        self.step_map = wp.array(np.repeat(np.eye(2)[None], b, 0), dtype=ks.mat22, device=dev)
        self.control = wp.zeros(2 * b, dtype=wp.int32, device=dev)
        self.target = wp.zeros(b, dtype=ks.vec2, device=dev)
        self._servo_on = False
        self._servo_gain = 0.0
        self._servo_max = 0.0
        self._graphs: dict[tuple, wp.Graph] = {}
        self._cmds: list = []
        self._cmds_key: tuple | None = None

    # -- loading --------------------------------------------------------------------------
    def set_active(self, active: np.ndarray) -> None:
        """Which RVEs step (1) and which stay frozen (0), shape (B,)."""
        self.active.assign(np.asarray(active, dtype=np.int32))

    def set_affine(self, vel_grad: np.ndarray) -> None:
        """Prescribe the velocity gradient L [1/s] of every RVE, shape (B, 2, 2).

        The cell advances exactly as ``H ← expm(L·dt)·H`` each step.
        """
        from scipy.linalg import expm

        lg = np.asarray(vel_grad, dtype=np.float64)
        maps = np.stack([expm(m * dt) for m, dt in zip(lg, self.model.dt, strict=True)])
        self.vel_grad.assign(lg)
        self.step_map.assign(maps)
        self._servo_on = False

    def set_servo(
        self, control: np.ndarray, target: np.ndarray, gain: float, max_strain: float
    ) -> None:
        """Mixed control of the diagonal components xx, yy of every RVE.

        Args:
            control: CONTROL_STRAIN or CONTROL_STRESS per component, shape (B, 2), int.
            target: strain increment per step [-] (strain control) or stress [Pa, tension
                positive] (stress control), shape (B, 2).
            gain: fraction of the stress error corrected per step, through the contact
                stiffness estimate Σ kn (n_k d_k)² / V [Pa].
            max_strain: cap on the servo's strain increment per step [-].
        """
        if not 0 < gain <= 1:
            raise ValueError(f"servo gain must lie in (0, 1], got {gain!r}")
        if not max_strain > 0:
            raise ValueError(f"max_strain must be positive, got {max_strain!r}")
        self.control.assign(np.asarray(control, dtype=np.int32).reshape(-1))
        self.target.assign(np.asarray(target, dtype=np.float64))
        self._servo_on = True
        self._servo_gain = float(gain)
        self._servo_max = float(max_strain)

    # -- stepping -------------------------------------------------------------------------
    def _record(self, state: State) -> list:
        m = self.model
        ks = m.kernels
        dev = m.device
        b, n, k = m.n_rve, m.n_disc, m.capacity
        dt = m.timestep

        def rec(kernel: wp.Kernel, dim: int, inputs: list) -> wp.Launch:
            return wp.launch(kernel, dim=dim, inputs=inputs, device=dev, record_cmd=True)

        cmds = [
            rec(ks.check_rebuild, b, [n, m.skin, m.cutoff, self.active, state.cell,
                                      state.cell_ref, state.disp, state.force_rebuild,
                                      self.rebuild, state.status]),
            rec(ks.clear_bins, b * m.max_bins**2, [m.max_bins, self.rebuild, self.bin_count]),
            rec(ks.fill_bins, b * n, [n, m.max_bins, BIN_CAPACITY, m.cutoff, self.rebuild,
                                      state.cell, state.frac, self.bin_count, self.bin_items,
                                      state.status]),
            rec(ks.build_neighbors, b * n, [n, k, m.max_bins, BIN_CAPACITY, m.skin, m.cutoff,
                                            self.rebuild, state.cell, state.frac, m.radius,
                                            self.bin_count, self.bin_items, state.nbr,
                                            state.nbr_count, state.shear, self.nbr_new,
                                            self.nbr_count_new, self.shear_new,
                                            state.status]),
            rec(ks.commit_neighbors, b * n, [n, k, self.rebuild, self.nbr_new,
                                             self.nbr_count_new, self.shear_new, state.nbr,
                                             state.nbr_count, state.shear, state.disp]),
            rec(ks.compute_forces, b * n, [n, k, dt, *m.law_args, self.active, m.friction,
                                           state.cell, self.vel_grad, state.frac, state.vel,
                                           state.ang_vel, m.radius, state.nbr,
                                           state.nbr_count, state.shear, self.force,
                                           self.torque, self.part_stress, self.part_stiff,
                                           state.status]),
        ]
        if self._servo_on:
            cmds.append(rec(ks.servo, b, [n, dt, m.meta.thickness, self._servo_gain,
                                          self._servo_max, self.active, state.cell,
                                          self.part_stress, self.part_stiff, self.control,
                                          self.target, self.vel_grad,
                                          self.step_map]))
        cmds += [
            rec(ks.integrate, b * n, [n, dt, m.meta.damping, self.active, state.cell, m.radius,
                                      m.inv_mass, m.inv_inertia, self.force, self.torque,
                                      state.frac, state.vel, state.ang_vel, state.disp,
                                      state.status]),
            rec(ks.advance_cell, b, [self.active, self.step_map, state.cell]),
        ]
        return cmds

    def run(
        self,
        state: State,
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
        cmds = self.prepare(state)
        done = 0
        while done < steps:
            chunk = min(check_every, steps - done)
            self._advance(state, cmds, chunk)
            done += chunk
            self.check(state)
            if callback is not None and callback(done):
                break
        return done

    def prepare(self, state: State) -> list:
        """The recorded launches of one step for ``state`` (recorded, and the kernel module
        loaded, on first use after a loading change). Call it from the main thread before
        stepping shards in threads: warp's module loading is not for concurrent use."""
        key = (id(state), self._servo_on, self._servo_gain, self._servo_max)
        if self._cmds_key != key:
            self._cmds = self._record(state)
            self._cmds_key = key
        return self._cmds

    def _advance(self, state: State, cmds: list, steps: int) -> None:
        """Launch ``steps`` steps; on CUDA whole blocks replay one captured graph."""
        eager = steps
        if wp.get_device(self.model.device).is_cuda and steps >= GRAPH_STEPS:
            key = (id(state), self._servo_on, self._servo_gain, self._servo_max)
            graph = self._graphs.get(key)
            if graph is None:
                with wp.ScopedCapture(device=self.model.device) as capture:
                    for _ in range(GRAPH_STEPS):
                        for cmd in cmds:
                            cmd.launch()
                graph = self._graphs[key] = capture.graph
            for _ in range(steps // GRAPH_STEPS):
                wp.capture_launch(graph)
            eager = steps % GRAPH_STEPS
        for _ in range(eager):
            for cmd in cmds:
                cmd.launch()

    def refresh_neighbors(self, state: State) -> None:
        """Rebuild the neighbour lists of every RVE now (tangential history is kept)."""
        state.force_rebuild.fill_(1)
        for cmd in self._record(state)[:5]:
            cmd.launch()
        self.check(state)

    def check(self, state: State) -> None:
        """Raise :class:`DEMInstabilityError` if any RVE's status has an error bit."""
        status = state.status.numpy()
        bad = np.flatnonzero(status)
        if bad.size == 0:
            return
        bits = int(np.bitwise_or.reduce(status[bad]))
        reasons = [msg for bit, msg in _MESSAGES.items() if bits & bit]
        raise DEMInstabilityError(bad.tolist(), reasons)
