"""DEMBatch: a model, its state and a solver together — the object users and the FEM hold."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from granular_material.dem.model import Model, State, build_model, state_from_data
from granular_material.dem.rve_file import RVEData
from granular_material.dem.solver import Solver
from granular_material.homogenization import Homogenized, homogenize

__all__ = ["DEMBatch"]


class DEMBatch:
    """B periodic RVEs of N discs on one device, advanced together.

    Args:
        data: the RVE batch (e.g. from :func:`load_rve`).
        device: "cpu", "cuda" or None (CUDA when present, else CPU).
        dtype: "float64" (default) or "float32".
        timestep: time step [s]; default: ``data.meta.timestep`` if set, else a safety
            fraction of the critical step.
    """

    def __init__(
        self,
        data: RVEData,
        device: str | None = None,
        dtype: str = "float64",
        timestep: float | None = None,
    ) -> None:
        self.model: Model = build_model(data, device=device, dtype=dtype, timestep=timestep)
        self.state: State = state_from_data(self.model, data)
        self.solver = Solver(self.model)
        if self.state.force_rebuild.numpy().any():
            self.solver.refresh_neighbors(self.state)

    # -- shape and parameters -------------------------------------------------------------
    @property
    def n_rve(self) -> int:
        """Number of RVEs B."""
        return self.model.n_rve

    @property
    def n_disc(self) -> int:
        """Discs per RVE N."""
        return self.model.n_disc

    @property
    def device(self) -> str:
        """The warp device the batch lives on."""
        return self.model.device

    @property
    def dt(self) -> float:
        """Time step [s]."""
        return self.model.dt

    def set_friction(self, friction_angle: float) -> None:
        """Set the interparticle friction angle [rad] of every RVE (tangential history kept)."""
        self.model = self.model.with_friction(friction_angle)
        self.solver = Solver(self.model)

    # -- state ----------------------------------------------------------------------------
    def snapshot(self) -> State:
        """A device copy of the whole dynamic state (commit)."""
        return self.state.clone()

    def restore(self, snapshot: State) -> None:
        """Make ``snapshot`` the current state again (revert), exactly."""
        self.state.assign(snapshot)

    def cell(self) -> np.ndarray:
        """Cell matrices H [m], shape (B, 2, 2), float64."""
        return self.state.cell.numpy().astype(np.float64)

    def homogenize(self) -> Homogenized:
        """Stress, tangent, void ratio, coordination, fabric of every RVE."""
        return homogenize(self.model, self.state)

    def to_data(self) -> RVEData:
        """The batch as an :class:`RVEData` (host copy), contact history included."""
        m = self.model
        b, n, k = m.n_rve, m.n_disc, m.capacity
        cell = self.cell()
        frac = self.state.frac.numpy().astype(np.float64).reshape(b, n, 2)
        extra = {
            "contact_partner": self.state.nbr.numpy().reshape(b, n, k),
            "contact_count": self.state.nbr_count.numpy().reshape(b, n),
            "contact_shear_force": self.state.shear.numpy().astype(np.float64).reshape(b, n, k),
            "fractional_position": frac,
            "verlet_displacement": self.state.disp.numpy().astype(np.float64).reshape(b, n, 2),
            "cell_at_list_build": self.state.cell_ref.numpy().astype(np.float64),
        }
        meta = replace(m.meta, timestep=m.dt)
        return RVEData(
            radius=m.radius_host.copy(),
            position=np.einsum("bij,bnj->bni", cell, frac),
            cell=cell,
            velocity=self.state.vel.numpy().astype(np.float64).reshape(b, n, 2),
            angular_velocity=self.state.ang_vel.numpy().astype(np.float64).reshape(b, n),
            meta=meta,
            extra=extra,
        )
