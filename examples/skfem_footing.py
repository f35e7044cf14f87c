"""A strip footing in a user's own script, from a geostatic start, with public API only.

Half of a plane-strain strip footing (the symmetry line at x = 0): a block of soil 1.0 m
wide and 0.5 m deep under its own weight (γ = 16 kN/m³) and a surcharge q = 20 kPa on the
ground surface, rollers on both sides and a fixed base. A rigid footing of half-width
b = 0.1 m (smooth by default) is pushed down by the settlement s. The soil starts in its
K0 state (σv = q + γ·depth, σh = K0·σv, K0 = 0.5) at every Gauss point, for every material,
so the initial residual is zero with no step taken. Swap the material by changing the one
line marked below:

    MATERIAL = "linear-elastic"   ->   "mohr-coulomb"   ->   "dem"

From the command line (installed with the package)::

    python -m granular_material_examples.skfem_footing [material] [--steps N]
           [--settlement S] [--out DIR] [--plain]

It prints the initial residual against the Newton tolerance, then the bearing pressure
against the settlement at every step (the reaction on the footing), and the Mohr–Coulomb
run's last pressure against Prandtl's bearing capacity. ``--out DIR`` writes the fields
for ParaView (``DIR/fields.xdmf``, its values in ``DIR/fields.h5``) and the curve
(``DIR/bearing.png``). ``--plain`` solves with a plain scikit-fem Newton loop instead of the
project's ``NewtonSolver``. See docs/guide/footing-script.md.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import brentq
from skfem import BilinearForm, LinearForm, condense, solve
from tqdm import tqdm

from granular_material.fem import (
    Fixed,
    Gravity,
    NewtonSolver,
    Pressure,
    Problem,
    RigidBody,
    Roller,
    build_problem,
    create_material,
    default_settings,
    geostatic_stress,
    rectangle_mesh,
    select_boundaries,
)
from granular_material.results.writers import FieldWriter

MATERIAL = "linear-elastic"  # <- the one line: "linear-elastic", "mohr-coulomb" or "dem"
ELEMENT = "tri6"  # "tri6" (P2, 3 Gauss points) or "quad4" (Q1, 2 × 2: locks in plastic flow)
FORMULATION = "small-strain"  # Prandtl's too; "updated-lagrangian": Guo & Zhao's finite strain

WIDTH, DEPTH = 1.0, 0.5  # half domain [m]
B = 0.1  # footing half-width [m]
Q = 20e3  # surcharge on the rest of the surface [Pa], compression positive
GAMMA = 16e3  # unit weight [N/m³]
K0 = 0.5  # σh / σv of the initial state [-]
ELEMENTS = (6, 3)  # elements along x and y (the first column is the footing's)
ROUGH = False  # a smooth footing: only its vertical displacement prescribed
PHI, PSI = 30.0, 30.0  # Mohr–Coulomb friction and dilation angles [°] (ψ = φ: associated)
UNCONFINED = 0.01  # a point below this fraction of its initial mean pressure is unconfined


def parameters(name: str, sigma0: np.ndarray) -> dict:
    """The material's keywords; every one starts at the same stress ``sigma0`` [Pa]
    (n, 2, 2), tension positive."""
    return {
        "linear-elastic": {"young": 20e6, "poisson": 0.3, "initial_stress": sigma0},
        "mohr-coulomb": {"young": 20e6, "poisson": 0.3, "friction_angle": PHI,
                         "dilation_angle": PSI,
                         "initial_stress": sigma0},
        "dem": {"particles": 64, "seed": 1, "initial_stress": sigma0, "share_tolerance": 0.02,
                "tangent": "condensed-sticking", "device": "cpu"},
    }[name]


def footing_problem(settlement: float, elements: tuple[int, int] = ELEMENTS,
                    element: str = ELEMENT) -> Problem:
    """The mesh (the first column b wide, elements growing away from the footing and
    shrinking towards the surface), its named boundaries and the conditions on them."""
    nx, ny = elements
    # geometric sizes: the last column's width over the first's that makes the first b wide
    growth = 1.0
    if not math.isclose(nx * B, WIDTH):
        low, high = (1 + 1e-9, 10.0) if nx * B < WIDTH else (0.1, 1 - 1e-9)
        growth = brentq(lambda g: B * (g**nx - 1) / (g - 1) - WIDTH, low, high)
    mesh = rectangle_mesh(WIDTH, DEPTH, nx, ny, element, grading=(growth ** (nx - 1), 0.5))
    mesh = select_boundaries(mesh, {"footing": f"y = top and x <= {B}",
                                    "surface": f"y = top and x >= {B}"})
    return build_problem(mesh, [
        Roller("left", 0), Roller("right", 0), Fixed("bottom"),  # the symmetry line, far side
        Pressure("surface", Q),
        RigidBody("footing", (0.0, -settlement), rough=ROUGH),
        Gravity(GAMMA),
    ])


@dataclass
class Footing:
    """What a run gave: settlement [m] and bearing pressure [Pa] of every step (step 0
    first), Newton iterations, cut-backs and unconfined points, the initial residual and
    its tolerance [N/m], each point's initial mean pressure [Pa], seconds."""

    material: str
    settlement: list[float] = field(default_factory=list)
    pressure: list[float] = field(default_factory=list)
    iterations: list[int] = field(default_factory=list)
    cutbacks: list[int] = field(default_factory=list)
    unconfined: list[int] = field(default_factory=list)
    initial_residual: float = math.nan
    tolerance: float = math.nan
    initial_pressure: np.ndarray = field(default_factory=lambda: np.zeros(0))
    seconds: dict[str, float] = field(default_factory=dict)


def bearing(problem: Problem, reaction: np.ndarray, u: np.ndarray) -> tuple[float, float]:
    """(settlement [m], bearing pressure [Pa]) of the footing: −u_y and −F_y / b of the
    reaction f_int − f_ext on its nodes (the force of the footing on the soil)."""
    _, fy = problem.boundary_force("footing", reaction)
    _, uy = problem.boundary_displacement("footing", u)
    return 0.0 - uy, -fy / B


def prandtl(phi: float = PHI) -> float:
    """q·N_q + ½·γ·(2b)·N_γ [Pa] (Terzaghi's sum, Prandtl–Reissner N_q, Meyerhof's
    N_γ = (N_q − 1) tan 1.4φ), a rough bound for a smooth strip footing."""
    t = math.tan(math.radians(phi))
    nq = math.exp(math.pi * t) * math.tan(math.radians(45 + phi / 2)) ** 2
    n_gamma = (nq - 1) * math.tan(math.radians(1.4 * phi))
    return Q * nq + 0.5 * GAMMA * 2 * B * n_gamma


def gauss_table(problem: Problem, grad_u: np.ndarray, response) -> pd.DataFrame:
    """The Gauss points' stress [Pa], small strain [-] and material fields, for output."""
    s, e = response.stress, 0.5 * (grad_u + np.swapaxes(grad_u, 1, 2))
    nqp = problem.basis.X.shape[-1]
    return pd.DataFrame({
        "element": np.arange(len(s)) // nqp,
        "sxx": s[:, 0, 0], "syy": s[:, 1, 1], "sxy": s[:, 0, 1],
        "exx": e[:, 0, 0], "eyy": e[:, 1, 1], "exy": e[:, 0, 1],
        "volumetric_strain": e[:, 0, 0] + e[:, 1, 1],
        "shear_strain": np.hypot(e[:, 0, 0] - e[:, 1, 1], 2 * e[:, 0, 1]),
        **{k: np.asarray(v, dtype=float) for k, v in response.fields.items()},
    })


@BilinearForm
def stiffness(u, v, w):
    return np.einsum("ijkl...,kl...,ij...->...", w.D, u.grad, v.grad)  # ∫ ∇v : D : ∇u


@LinearForm
def internal_force(v, w):
    return np.einsum("ij...,ij...->...", w.sigma, v.grad)  # ∫ ∇v : σ


def plain_newton(problem: Problem, material, steps: int, out: Footing,
                 rtol: float = 1e-2, max_iterations: int = 50) -> None:
    """A plain scikit-fem Newton loop (small strain, the total ∇u handed to the material,
    the correction test ‖δu‖ ≤ rtol ‖Δu‖, no cut-backs): what ``NewtonSolver`` replaces."""
    basis, loading = problem.basis, problem.loading
    D = loading.dirichlet_dofs
    u = basis.zeros()
    for step in range(1, steps + 1):
        u_committed = u.copy()
        u_d, f_ext = loading.at(step / steps)
        prescribed = basis.zeros()
        prescribed[D] = u_d - u[D]  # the footing's move, in the first correction only
        iterations = 0
        while iterations < max_iterations:
            iterations += 1
            r = material.response(basis.interpolate(u))  # the total displacement
            if not r.ok:
                raise RuntimeError(f"step {step}: points failed {r.failure_counts()}")
            residual = internal_force.assemble(basis, sigma=r.stress) - f_ext
            K = stiffness.assemble(basis, D=r.tangent)
            du = solve(*condense(K, -residual, x=prescribed, D=D))
            prescribed[D] = 0.0
            u += du
            if np.linalg.norm(du) <= rtol * np.linalg.norm(u - u_committed):
                break
        else:
            raise RuntimeError(f"step {step} did not converge in {max_iterations} iterations")
        r = material.response(basis.interpolate(u))
        material.commit()
        reaction = internal_force.assemble(basis, sigma=r.stress) - f_ext
        record(out, problem, reaction, u, r.points.stress, iterations, 0)


def record(out: Footing, problem: Problem, reaction: np.ndarray, u: np.ndarray,
           stress: np.ndarray, iterations: int, cutbacks: int) -> None:
    """Add a committed step to ``out`` and print it: the footing's settlement and bearing
    pressure, and the points whose mean pressure fell below 1 % of their initial one."""
    settlement, pressure = bearing(problem, reaction, u)
    mean = -0.5 * np.trace(stress, axis1=1, axis2=2)
    unconfined = int(np.sum(mean < UNCONFINED * out.initial_pressure))
    out.settlement.append(settlement)
    out.pressure.append(pressure)
    out.iterations.append(iterations)
    out.cutbacks.append(cutbacks)
    out.unconfined.append(unconfined)
    tqdm.write(f"{out.material}: step {len(out.settlement) - 1:2d} settlement "
               f"{settlement * 1e3:6.2f} mm  bearing pressure {pressure / 1e3:7.1f} kPa  "
               f"({iterations} iterations{f', {cutbacks} cut-backs' if cutbacks else ''}"
               f"{f', unconfined points: {unconfined}' if unconfined else ''})")


def main(name: str = MATERIAL, steps: int = 10, settlement: float = 0.02,
         out_dir: str | Path | None = None, plain: bool = False, progress: bool = True,
         elements: tuple[int, int] = ELEMENTS, element: str = ELEMENT) -> Footing:
    """Push the footing down by ``settlement`` [m] in ``steps`` equal steps; returns the
    curve. ``out_dir``: write ``fields.xdmf`` (ParaView) and ``bearing.png`` there."""
    t0 = time.perf_counter()
    problem = footing_problem(settlement, elements, element)
    sigma0 = geostatic_stress(problem.points, surface_y=DEPTH, unit_weight=GAMMA,
                              surcharge=Q, k0=K0)
    material = create_material(name, **parameters(name, sigma0))
    material.allocate(len(problem.points))  # a DEM material prepares its RVEs here
    noisy = bool(getattr(material, "noisy", False))
    # the Newton settings of the commands for this kind of material, and an absolute
    # tolerance: the residual a stress error of 0.5 % of q at every point leaves
    settings = default_settings(noisy, atol=problem.force_tolerance(5e-3 * Q),
                                formulation=FORMULATION)
    solver = NewtonSolver(problem.basis, material, problem.loading, settings)
    result = Footing(name, tolerance=settings.atol,
                     initial_pressure=-0.5 * np.trace(sigma0, axis1=1, axis2=2),
                     seconds={"preparation": time.perf_counter() - t0})
    # the geostatic start: the residual on the free dofs at load factor 0, no step taken
    free = np.setdiff1d(np.arange(problem.basis.N), problem.loading.dirichlet_dofs)
    result.initial_residual = float(np.linalg.norm(solver.reaction[free]))
    print(f"{name}: {len(problem.points)} Gauss points; initial residual "
          f"{result.initial_residual:.3g} N/m (tolerance {settings.atol:.3g} N/m)")
    record(result, problem, solver.reaction, solver.u, solver.response.stress, 0, 0)

    t1 = time.perf_counter()
    writer = None
    if out_dir is not None:
        writer = FieldWriter(Path(out_dir) / "fields.xdmf", problem).__enter__()
        writer.write(0.0, solver.u, gauss_table(problem, solver.grad_u(), solver.response))
    try:
        if plain:
            plain_newton(problem, material, steps, result)
        else:
            def on_step(s: NewtonSolver, rec) -> None:
                record(result, problem, s.reaction, s.u, s.response.stress, rec.iterations,
                       rec.cutbacks)
                if writer is not None:
                    writer.write(result.settlement[-1], s.u,
                                 gauss_table(problem, s.grad_u(), s.response))

            solver.run(steps, on_step=on_step, progress=progress,
                       description=f"footing, {name}")
    finally:
        if writer is not None:
            writer.__exit__(None, None, None)
    result.seconds["steps"] = time.perf_counter() - t1
    print(f"{name}: {steps} steps in {result.seconds['steps']:.1f} s "
          f"(preparation {result.seconds['preparation']:.1f} s), "
          f"{sum(result.iterations)} iterations")
    if name == "mohr-coulomb":
        bound = prandtl()
        print(f"{name}: last pressure {result.pressure[-1] / 1e3:.0f} kPa; Prandtl with "
              f"self-weight (q·N_q + ½γ·2b·N_γ, Meyerhof's N_γ, φ = {PHI:g}°) "
              f"{bound / 1e3:.0f} kPa, ratio {result.pressure[-1] / bound:.2f} "
              f"(ψ = {PSI:g}°: a rough bound, not a pass mark)")
    if out_dir is not None:
        plot(result, Path(out_dir) / "bearing.png")
    return result


def plot(result: Footing, path: Path) -> None:
    """The bearing pressure [kPa] against the settlement [mm], as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(np.array(result.settlement) * 1e3, np.array(result.pressure) / 1e3, "o-",
            label=result.material)
    if result.material == "mohr-coulomb":
        ax.axhline(prandtl() / 1e3, ls="--", c="k", label="Prandtl + self-weight")
    ax.set(xlabel="settlement [mm]", ylabel="bearing pressure [kPa]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def cli(argv: list[str] | None = None) -> int:
    """The command line (see the module docstring)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("material", nargs="?", default=MATERIAL,
                   choices=["linear-elastic", "mohr-coulomb", "dem"])
    p.add_argument("--steps", type=int, default=10, help="load steps (default 10)")
    p.add_argument("--settlement", type=float, default=0.02,
                   help="settlement of the footing at the end [m] (default 0.02)")
    p.add_argument("--out", default=None, help="folder for fields.xdmf and bearing.png")
    p.add_argument("--plain", action="store_true",
                   help="a plain scikit-fem Newton loop instead of NewtonSolver")
    a = p.parse_args(argv)
    try:
        main(a.material, a.steps, a.settlement, a.out, a.plain)
    except RuntimeError as exc:  # NewtonError too; the committed steps are printed above
        print(f"{a.material}: stopped: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(cli())
