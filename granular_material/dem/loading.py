"""Loading control of a DEM batch: which RVEs step, and how their cells are driven.

Held apart from the model (static) and the state (what evolves), so that changing a
parameter of the model (e.g. the friction after consolidation) keeps the loading.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from granular_material.dem.kernels.common import CONTROL_STRAIN, CONTROL_STRESS
from granular_material.dem.model import Model

__all__ = ["CONTROL_STRAIN", "CONTROL_STRESS", "LoadingControl", "ServoSettings", "expm_2x2"]


def expm_2x2(m: np.ndarray) -> np.ndarray:
    """exp of every 2×2 matrix of ``m`` (…, 2, 2), in closed form: with m = h·I + T, T
    traceless and T² = k·I, exp m = e^h (cosh √k · I + sinh √k / √k · T) (cos and sin of
    √−k for k < 0). exp 0 = I exactly. scipy's ``expm`` took 0.05–3.5 ms a matrix here (its
    BLAS threads): 10 000 RVEs spent 35 s in one ``set_affine``.
    """
    m = np.asarray(m, dtype=np.float64)
    half_trace = 0.5 * (m[..., 0, 0] + m[..., 1, 1])
    t = m - half_trace[..., None, None] * np.eye(2)
    k = t[..., 0, 0] ** 2 + t[..., 0, 1] * t[..., 1, 0]
    r = np.sqrt(np.abs(k))
    with np.errstate(all="ignore"):  # r = 0: the branch not taken divides by zero
        even = np.where(k >= 0, np.cosh(r), np.cos(r))
        odd = np.where(r > 0, np.where(k >= 0, np.sinh(r), np.sin(r)) / r, 1.0)
    return np.exp(half_trace)[..., None, None] * (even[..., None, None] * np.eye(2)
                                                   + odd[..., None, None] * t)


@dataclass(frozen=True)
class ServoSettings:
    """How the stress servo corrects the diagonal strains.

    Attributes:
        gain: fraction of the stress error corrected per step, through the contact
            stiffness estimate Σ kn (n_k d_k)² / V [Pa], in (0, 1].
        max_strain: cap on the servo's strain increment per step [-], > 0.
    """

    gain: float
    max_strain: float

    def __post_init__(self) -> None:
        if not 0 < self.gain <= 1:
            raise ValueError(f"servo gain must lie in (0, 1], got {self.gain!r}")
        if not self.max_strain > 0:
            raise ValueError(f"max_strain must be positive, got {self.max_strain!r}")


class LoadingControl:
    """The loading of B RVEs on the model's device.

    Attributes:
        active: 1 where the RVE steps, 0 where it stays frozen, (B,), int32.
        any_active: whether any RVE steps (host-side).
        velocity_gradient: L [1/s] per RVE, (B,), mat22.
        step_map: the cell's map of one step, H ← E·H, (B,), mat22.
        control: CONTROL_STRAIN or CONTROL_STRESS per diagonal component, (2·B,), int32.
        target: strain per step [-] or stress [Pa] per diagonal component, (B,), vec2.
        servo: the servo's settings while it drives the cells, else None.
    """

    def __init__(self, model: Model) -> None:
        ft = model.float_type
        dev = model.device
        b = model.n_rve
        self._timestep = model.timestep
        mat22 = wp.types.matrix((2, 2), ft)
        self.active = wp.ones(b, dtype=wp.int32, device=dev)
        #: whether any RVE steps (a host copy: a shard with none is not launched at all)
        self.any_active = True
        self.velocity_gradient = wp.zeros(b, dtype=mat22, device=dev)
        self.step_map = wp.array(np.repeat(np.eye(2)[None], b, 0), dtype=mat22, device=dev)
        self.control = wp.zeros(2 * b, dtype=wp.int32, device=dev)
        self.target = wp.zeros(b, dtype=wp.types.vector(2, ft), device=dev)
        self.servo: ServoSettings | None = None

    def set_active(self, active: np.ndarray) -> None:
        """Which RVEs step (nonzero) and which stay frozen (0), shape (B,)."""
        active = np.asarray(active, dtype=np.int32)
        self.active.assign(active)
        self.any_active = bool(active.any())

    def set_affine(self, velocity_gradient: np.ndarray) -> None:
        """Prescribe the velocity gradient L [1/s] of every RVE, shape (B, 2, 2); the cell
        advances exactly as ``H ← exp(L·dt)·H`` each step. The servo is switched off."""
        lg = np.asarray(velocity_gradient, dtype=np.float64)
        maps = expm_2x2(lg * self._timestep[:, None, None])
        self.velocity_gradient.assign(lg)
        self.step_map.assign(maps)
        self.servo = None

    def set_servo(self, control: np.ndarray, target: np.ndarray,
                  settings: ServoSettings) -> None:
        """Mixed control of the diagonal components xx, yy of every RVE.

        Args:
            control: CONTROL_STRAIN or CONTROL_STRESS per component, shape (B, 2), int.
            target: strain increment per step [-] (strain control) or stress [Pa, tension
                positive] (stress control), shape (B, 2).
            settings: the servo's gain and strain cap.
        """
        control = np.asarray(control, dtype=np.int32)
        if not np.isin(control, (CONTROL_STRAIN, CONTROL_STRESS)).all():
            raise ValueError("control must hold CONTROL_STRAIN or CONTROL_STRESS only")
        self.control.assign(control.reshape(-1))
        self.target.assign(np.asarray(target, dtype=np.float64))
        self.servo = settings
