"""Your own boundary-value problem, solved by the project's ``NewtonSolver``.

The mesh, the basis and the loading are built here with scikit-fem alone (no
``build_problem``), the way a problem of your own would be: half of a smooth rigid strip
footing (half-width b = 0.1 m) pushed into a layer 1.0 m wide and 0.5 m deep, its weight
(γ = 16 kN/m³) and a surcharge q = 20 kPa beside the footing held constant, the soil in its
K0 state from the start. The soil softens (Mohr–Coulomb, φ from 40° to 25° over a plastic
shear strain of 5 %), so the bearing pressure passes through a peak. The pieces:

- ``Loading``: the prescribed dofs and their values at λ = 1, the external forces at λ = 0
  and λ = 1 (here the same: weight and surcharge, assembled by two scikit-fem forms);
- ``NewtonSettings``: the force test with an absolute tolerance, stall acceptance,
  cut-backs; ``NewtonError`` when a step cannot be taken, the committed steps kept;
- the reaction on the footing from ``solver.reaction``, the unconfined points from
  ``granular_material.multiscale.unconfined`` (a mask per Gauss point), a progress bar;
- ParaView output: one VTU file a step through meshio and a ``.pvd`` series that lists
  them with the settlement as time.

Run it (installed with the package)::

    python -m granular_material_examples.own_problem [--material dem] [--steps N]
           [--settlement S] [--out DIR]

See docs/guide/own-problem.md.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import brentq
from skfem import Basis, ElementTriP2, ElementVector, FacetBasis, LinearForm, MeshTri
from tqdm import tqdm

from granular_material.fem import (
    Loading,
    NewtonError,
    NewtonSettings,
    NewtonSolver,
    Regularisation,
    StepRecord,
    create_material,
    geostatic_stress,
    to_points,
)
from granular_material.multiscale import unconfined

WIDTH, DEPTH, B = 1.0, 0.5, 0.1  # half domain and footing half-width [m]
Q, GAMMA, K0 = 20e3, 16e3, 0.5  # surcharge [Pa], unit weight [N/m³], σh/σv [-]


def soil(name: str, sigma0: np.ndarray) -> dict:
    """The material's keywords, every point starting at ``sigma0`` [Pa] (n, 2, 2)."""
    return {
        "mohr-coulomb": {"young": 20e6, "poisson": 0.3, "friction_angle": 40.0,
                         "dilation_angle": 10.0,
                         "critical_friction_angle": 25.0, "softening_strain": 0.05,
                         "initial_stress": sigma0},
        "dem": {"particles": 64, "seed": 1, "initial_stress": sigma0, "share_tolerance": 0.02,
                "tangent": "condensed-sticking", "device": "cpu"},
    }[name]


def mesh(nx: int = 6, ny: int = 3) -> MeshTri:
    """``nx`` × ``ny`` rectangles cut into triangles: the first column b wide, the others
    growing away from the footing, rows finer towards the surface; the boundaries named by
    where their facets' midpoints lie."""
    # column widths b, b·g, b·g², ... with g chosen so that nx columns fill the width
    g = 1.0
    if nx * B < WIDTH:
        g = brentq(lambda g: B * (g**nx - 1) / (g - 1) - WIDTH, 1 + 1e-9, 10.0)
    x = np.concatenate([[0.0], np.cumsum(B * g ** np.arange(nx))])
    x[-1] = WIDTH
    y = DEPTH * (1 - (1 - np.linspace(0, 1, ny + 1)) ** 1.5)
    m = MeshTri.init_tensor(x, y)
    return m.with_boundaries({
        "left": lambda p: np.isclose(p[0], 0.0),
        "right": lambda p: np.isclose(p[0], WIDTH),
        "bottom": lambda p: np.isclose(p[1], 0.0),
        "footing": lambda p: np.isclose(p[1], DEPTH) & (p[0] < B),
        "surface": lambda p: np.isclose(p[1], DEPTH) & (p[0] > B),
    })


@LinearForm
def weight(v, w):
    return -GAMMA * v[1]  # the body force −γ e_y [N/m³]


@LinearForm
def surcharge(v, w):
    return -Q * v[1]  # a pressure q pushing down on the top surface [Pa]


def loading(basis: Basis, settlement: float) -> tuple[Loading, np.ndarray]:
    """The footing's push, the supports, weight and surcharge as a ``Loading``; also the
    footing's dofs along y (for its reaction)."""
    m = basis.mesh
    dofs = basis.get_dofs
    footing_y = dofs("footing").all("u^2")
    fixed = [dofs("bottom").all(), dofs("left").all("u^1"), dofs("right").all("u^1"),
             footing_y]
    end = [np.zeros(d.size) for d in fixed[:-1]] + [np.full(footing_y.size, -settlement)]
    d_all, first = np.unique(np.concatenate(fixed), return_index=True)
    d_end = np.concatenate(end)[first]  # a dof on two lists takes its first value
    forces = (weight.assemble(basis)
              + surcharge.assemble(FacetBasis(m, basis.elem, facets="surface")))
    return Loading(d_all, d_end, forces, forces.copy()), footing_y


@dataclass
class Curve:
    """Settlement [m], bearing pressure [Pa], Newton's work and the unconfined points of
    every committed step (step 0 first)."""

    settlement: list[float] = field(default_factory=list)
    pressure: list[float] = field(default_factory=list)
    iterations: list[int] = field(default_factory=list)
    cutbacks: list[int] = field(default_factory=list)
    stalled: list[int] = field(default_factory=list)
    unconfined: list[int] = field(default_factory=list)
    stopped: str = ""

    @property
    def peak(self) -> int:
        """The step of the highest bearing pressure."""
        return int(np.argmax(self.pressure))


class ParaViewSeries:
    """One VTU file a step (``DIR/step_0003.vtu``) and ``DIR/fields.pvd`` listing them:
    the vertices' displacement [m] and each triangle's mean stress [Pa], mean pressure [Pa]
    and unconfined flag. Open ``fields.pvd`` in ParaView."""

    def __init__(self, folder: Path, basis: Basis) -> None:
        self.folder, self.basis = folder, basis
        self.entries: list[tuple[float, str]] = []
        folder.mkdir(parents=True, exist_ok=True)

    def write(self, time: float, u: np.ndarray, stress: np.ndarray, loose: np.ndarray) -> None:
        import meshio

        m, nqp = self.basis.mesh, self.basis.X.shape[-1]
        vertex = self.basis.nodal_dofs[:, : m.p.shape[1]]  # (2, vertices): their u dofs
        disp = np.column_stack([u[vertex[0]], u[vertex[1]], np.zeros(m.p.shape[1])])
        cell = stress.reshape(-1, nqp, 2, 2).mean(axis=1)  # element means
        name = f"step_{len(self.entries):04d}.vtu"
        meshio.write(self.folder / name, meshio.Mesh(
            np.column_stack([m.p.T, np.zeros(m.p.shape[1])]), [("triangle", m.t.T)],
            point_data={"displacement": disp},
            cell_data={"sxx": [cell[:, 0, 0]], "syy": [cell[:, 1, 1]], "sxy": [cell[:, 0, 1]],
                       "pressure": [-0.5 * (cell[:, 0, 0] + cell[:, 1, 1])],
                       "unconfined": [loose.reshape(-1, nqp).any(axis=1).astype(float)]}))
        self.entries.append((time, name))
        rows = "\n".join(f'    <DataSet timestep="{t:.9g}" file="{f}"/>' for t, f in self.entries)
        (self.folder / "fields.pvd").write_text(
            '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
            f"  <Collection>\n{rows}\n  </Collection>\n</VTKFile>\n")


def main(material_name: str = "mohr-coulomb", steps: int = 16, settlement: float = 0.04,
         out: str | Path | None = None, progress: bool = True,
         elements: tuple[int, int] = (6, 3), internal_length: float = 0.0) -> Curve:
    """Push the footing down by ``settlement`` [m] in ``steps`` steps; returns the curve
    (``Curve.stopped`` says why a run ended early). ``internal_length`` > 0 [m]: the
    second gradient past the peak (docs/guide/regularisation.md)."""
    basis = Basis(mesh(*elements), ElementVector(ElementTriP2()))  # 3 Gauss points a triangle
    points = to_points(np.asarray(basis.global_coordinates()))  # (n, 2) [m]
    sigma0 = geostatic_stress(points, surface_y=DEPTH, unit_weight=GAMMA, surcharge=Q, k0=K0)
    material = create_material(material_name, **soil(material_name, sigma0))
    material.allocate(len(points))
    load, footing_y = loading(basis, settlement)
    # the absolute tolerance: the residual ‖R‖ [N/m] that a stress error of 0.5 % of q at
    # every Gauss point leaves, τ·h·√(free dofs), h the elements' mean size
    h = math.sqrt(WIDTH * DEPTH / basis.nelems)
    atol = 5e-3 * Q * h * math.sqrt(basis.N - load.dirichlet_dofs.size)
    noisy = material_name == "dem"
    settings = NewtonSettings(
        convergence="force", rtol=0.005, atol=atol,  # ‖R‖/‖R0‖ ≤ rtol or ‖R‖ ≤ atol
        stall_rtol=0.02 if noisy else 0.0,  # a DEM residual may stall on its noise floor
        accept_correction=0.01 if noisy else 0.0,  # ... then a small correction accepts it
        relaxation="aitken" if noisy else "none", tangent_update="hold" if noisy else "none",
        predictor="extrapolate", max_iterations=50, max_cutbacks=8)
    regularisation = (Regularisation("second-gradient", internal_length) if internal_length
                      else Regularisation())
    solver = NewtonSolver(basis, material, load, settings, regularisation)
    initial_pressure = -0.5 * np.trace(sigma0, axis1=1, axis2=2)
    curve = Curve()
    series = None if out is None else ParaViewSeries(Path(out), basis)

    def on_step(s: NewtonSolver, record: StepRecord | None) -> None:
        stress = s.response.stress
        loose = unconfined(stress, np.ones(len(stress), bool), initial_pressure)
        fy = float(s.reaction[footing_y].sum())  # force of the footing on the soil [N/m]
        curve.settlement.append(0.0 - float(s.u[footing_y].mean()))
        curve.pressure.append(-fy / B)
        for name, value in (("iterations", 0), ("cutbacks", 0), ("stalled", 0)):
            getattr(curve, name).append(getattr(record, name) if record else value)
        curve.unconfined.append(int(loose.sum()))
        tqdm.write(f"step {len(curve.pressure) - 1:2d}: settlement "
                   f"{curve.settlement[-1] * 1e3:5.2f} mm, bearing pressure "
                   f"{curve.pressure[-1] / 1e3:6.1f} kPa, {curve.iterations[-1]} iterations, "
                   f"{curve.cutbacks[-1]} cut-backs, {curve.stalled[-1]} stalled, "
                   f"{curve.unconfined[-1]} unconfined points")
        if series is not None:
            series.write(curve.settlement[-1], s.u, stress, loose)

    on_step(solver, None)  # step 0: the geostatic state, q under the footing
    try:
        solver.run(steps, on_step=on_step, progress=progress, description=material_name)
    except NewtonError as error:  # the steps committed before it are in the curve
        curve.stopped = str(error)
        tqdm.write(f"stopped: {error}")
    return curve


def cli(argv: list[str] | None = None) -> int:
    """The command line (see the module docstring); exit 1 when a step failed."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--material", default="mohr-coulomb", choices=["mohr-coulomb", "dem"])
    p.add_argument("--steps", type=int, default=16, help="load steps (default 16)")
    p.add_argument("--settlement", type=float, default=0.04,
                   help="the footing's settlement at the end [m] (default 0.04)")
    p.add_argument("--out", default=None, help="folder for the ParaView series")
    p.add_argument("--internal-length", type=float, default=0.0,
                   help="the second gradient's internal length [m] (default 0: none)")
    a = p.parse_args(argv)
    curve = main(a.material, a.steps, a.settlement, a.out,
                 internal_length=a.internal_length)
    k = curve.peak
    print(f"peak {curve.pressure[k] / 1e3:.1f} kPa at {curve.settlement[k] * 1e3:.1f} mm "
          f"(step {k}); last {curve.pressure[-1] / 1e3:.1f} kPa at "
          f"{curve.settlement[-1] * 1e3:.1f} mm; {sum(curve.iterations)} iterations")
    return 1 if curve.stopped else 0


if __name__ == "__main__":
    sys.exit(cli())
