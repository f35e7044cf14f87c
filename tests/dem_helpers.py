"""Helpers shared by the DEM step tests: a batch loaded by shear or by the servo, and two
RVEs of which one blows up."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from granular_material.dem import DEMBatch, RVEData


def load_shear_or_servo(batch: DEMBatch, servo: bool, shear: float) -> None:
    """``batch`` under the servo (σxx held at −100 kPa, εyy compressed by ``shear`` a step)
    or, without it, sheared by ``shear`` a step (an affine velocity gradient)."""
    if servo:
        target = np.tile([[-100e3, -shear]], (batch.n_rve, 1))  # sxx held, eyy compressed
        batch.set_servo(np.tile([[1, 0]], (batch.n_rve, 1)), target, gain=0.5,
                        max_strain=1e-4)
    else:
        grad = np.zeros((batch.n_rve, 2, 2))
        grad[:, 0, 1] = shear / batch.dt
        batch.set_affine(grad)


def calm_and_violent(two_discs: Callable[..., RVEData]) -> RVEData:
    """Two RVEs of two discs (``two_discs``: the conftest factory): RVE 0 calm, RVE 1 with
    its discs almost on top of each other, so that it, and only it, blows up."""
    calm = two_discs((0.05, 0.1), (0.08, 0.1))
    violent = two_discs((0.05, 0.1), (0.0502, 0.1))
    return replace(
        calm,
        radius=np.concatenate([calm.radius, violent.radius]),
        position=np.concatenate([calm.position, violent.position]),
        cell=np.concatenate([calm.cell, violent.cell]),
        velocity=np.zeros((2, 2, 2)),
        angular_velocity=np.zeros((2, 2)),
    )
