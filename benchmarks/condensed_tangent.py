"""How well each RVE tangent predicts the DEM's stress change under an unseen increment, and
what the condensed tangent costs beside a DEM evaluation (issue 26's done-when), in one run.

Usage::

    python benchmarks/condensed_tangent.py [--particles 100] [--seeds 1,2,3]
        [--increment 1e-4] [--hold 2000] [--cost-only] [--solver direct|cg|both]
        [--out DIR]

RVEs of ``--particles`` discs (one per seed, ``prepare_packing``: 100 kPa, friction 0.5 rad)
in three states: ``p0`` as prepared; ``shear`` right after a 1 % pure shear
(∇u = diag(+0.5 %, −0.5 %), driven at 1e-5 a step); ``shear-held`` the same held at a fixed
cell for ``--hold`` steps (at rest: unbalanced force < 1e-3). From each state, deviatoric
increments of size ``--increment`` (pure shear on, pure shear back, simple shear xy on and
back) are applied two ways, each less the change the same steps make at a fixed cell (the
packing's own drift, as ``tests/test_extremes.py`` measures it):

- ``drive``: ``drive_grad_u`` as the FEM does (1e-5 strain a step: 10 steps for 1e-4);
- ``drive-30``: the same over 30 steps (as an increment inside a longer FEM load step);
- ``quasi-static``: ``--hold``/2 steps for the increment (1000), then ``--hold`` steps at a
  fixed cell.

The tangents: ``kr`` (Kruyt–Rothenburg, ``homogenize``), ``condensed`` (free sliding),
``condensed-coulomb``, ``condensed-sticking`` (every touching contact keeps kt), and
``perturbation`` (the DEM material's forward differences: four more ``drive`` runs of ∇u =
1e-4 E_kl from the state). Error = |C:Δ∇u − Δσ_DEM| / |Δσ_DEM| (Frobenius). Writes
``prediction.csv``, ``prediction.md`` and ``cost.json`` under ``--out``. ``--solver``: how
the costs time the condensed tangent's solves: ``direct`` (scipy LU per RVE, the default),
``cg`` (``condensed_cg``: the batched warp CG on the CPU device) or ``both`` (each, wall
time of the whole batch's call per RVE, median of the repeats, and the largest difference
between the two tangents). Measures; never passes or fails.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

from granular_material.dem import DEMBatch, RVEData
from granular_material.dem.batch import BatchSnapshot
from granular_material.dem.condensed.cg import condensed_tangent_cg
from granular_material.dem.condensed.tangent import condensed_tangent
from granular_material.procedures import drive_grad_u, prepare_packing
from granular_material.results.compare import markdown_table

SHEAR = np.diag([0.005, -0.005])  #: the 1 % pure shear before the second and third states
DIRECTIONS = {
    "pure-on": np.diag([1.0, -1.0]),
    "pure-back": np.diag([-1.0, 1.0]),
    "xy-on": np.array([[0.0, 1.0], [1.0, 0.0]]),
    "xy-back": np.array([[0.0, -1.0], [-1.0, 0.0]]),
}


def _change(batch: DEMBatch, snap: BatchSnapshot, grad_u: np.ndarray, protocol: str,
            hold: int) -> np.ndarray:
    """Stress change [Pa] (B, 2, 2) that ``grad_u`` (2, 2) causes from the state ``snap``,
    less the drift."""
    batch.restore(snap)
    size = float(np.abs(grad_u).max())
    if protocol == "drive":
        steps = drive_grad_u(batch, grad_u)
    elif protocol == "drive-30":
        steps = drive_grad_u(batch, grad_u, max_strain_per_step=size / 30)
    else:
        steps = drive_grad_u(batch, grad_u, max_strain_per_step=size / hold * 2)
        steps += drive_grad_u(batch, np.zeros((2, 2)), min_steps=hold)
    driven = batch.homogenize().stress
    batch.restore(snap)
    drive_grad_u(batch, np.zeros((2, 2)), min_steps=steps)
    return driven - batch.homogenize().stress


def _perturbation(batch: DEMBatch, snap: BatchSnapshot, size: float = 1e-4) -> np.ndarray:
    """Forward differences [Pa] (B, 2, 2, 2, 2) of the ``drive`` response to ∇u = size·E_kl
    (the DEM material's "perturbation" tangent at ∇u = 0), each less the drift of its
    steps at a fixed cell."""
    tangent = np.zeros((batch.n_rve, 2, 2, 2, 2))
    for k in range(2):
        for m in range(2):
            g = np.zeros((2, 2))
            g[k, m] = size
            tangent[:, :, :, k, m] = _change(batch, snap, g, "drive", 0) / size
    return tangent


def _states(particles: int, seeds: list[int], hold: int) -> dict[str, RVEData]:
    """The RVEs of every seed at p0, right after the 1 % shear, and held after it."""
    batch = DEMBatch(RVEData.concatenate([
        prepare_packing(n_disc=particles, seed=s, device="cpu").to_data() for s in seeds]),
        device="cpu")
    states = {"p0": batch.to_data()}
    drive_grad_u(batch, SHEAR)
    states["shear"] = batch.to_data()
    drive_grad_u(batch, np.zeros((2, 2)), min_steps=hold)
    states["shear-held"] = batch.to_data()
    return states


def _costs(data: RVEData, increment: float, repeats: int = 5, solver: str = "direct") -> dict:
    """Wall time [s] per RVE of the condensed tangent (its state read from the batch
    included) beside one DEM evaluation of the batch (``drive_grad_u`` of ``increment``,
    and of a 1e-3 load step), divided by B; with ``solver`` "cg" or "both" the warp CG's
    (and the scipy path's) whole call per RVE as well."""
    batch = DEMBatch(data, device="cpu")
    snap = batch.snapshot()
    n = data.n_rve
    drive_grad_u(batch, np.diag([increment, -increment]))  # warm-up (modules loaded)
    timings: dict[str, list[float]] = {"condensed": [], "to_data": [], "drive": [],
                                       "drive_1e-3": []}
    for _ in range(repeats):
        for name, size in (("drive", increment), ("drive_1e-3", 1e-3)):
            batch.restore(snap)
            start = time.perf_counter()
            drive_grad_u(batch, np.diag([size, -size]))
            timings[name].append((time.perf_counter() - start) / n)
        start = time.perf_counter()
        state = batch.to_data()
        timings["to_data"].append((time.perf_counter() - start) / n)
        result = condensed_tangent(state)
        timings["condensed"].append(float(np.mean(result.seconds)))
    if solver in ("cg", "both"):
        cg = condensed_tangent_cg(state)  # warm-up: the kernels are built
        calls = {"cg": condensed_tangent_cg}
        if solver == "both":
            calls["direct"] = condensed_tangent
        for name, call in calls.items():
            timings[f"condensed_{name}_call"] = []
            for _ in range(repeats):
                start = time.perf_counter()
                call(state)
                timings[f"condensed_{name}_call"].append((time.perf_counter() - start) / n)
    out = {f"{name}_s_per_rve": float(np.median(v)) for name, v in timings.items()}
    if solver in ("cg", "both"):
        out["cg_iterations_max"] = int(cg.iterations.max())
        out["cg_iterations_mean"] = float(cg.iterations.mean())
        out["cg_vs_direct_max_rel"] = float(np.abs(cg.tangent - result.tangent).max()
                                            / np.abs(result.tangent).max())
    out["unknowns_per_rve"] = float(np.mean(result.n_unknowns))
    out["contacts_per_rve"] = float(np.mean(result.n_contacts))
    return out


def main(argv: list[str] | None = None) -> pd.DataFrame:
    """Run the study; the prediction table (one row per state, protocol, direction, seed)."""
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--particles", type=int, default=100)
    parser.add_argument("--seeds", default="1,2,3")
    parser.add_argument("--increment", type=float, default=1e-4)
    parser.add_argument("--hold", type=int, default=2000)
    parser.add_argument("--cost-only", action="store_true",
                        help="only the costs, of the prepared RVEs (no predictions)")
    parser.add_argument("--solver", choices=("direct", "cg", "both"), default="direct",
                        help="which condensed-tangent solver the costs time")
    parser.add_argument("--out", type=Path, default=Path("condensed-tangent"))
    args = parser.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    args.out.mkdir(parents=True, exist_ok=True)
    if args.cost_only:
        data = RVEData.concatenate([prepare_packing(n_disc=args.particles, seed=s,
                                                    device="cpu").to_data() for s in seeds])
        cost = _costs(data, args.increment, solver=args.solver)
        cost.update(particles=args.particles, seeds=seeds, solver=args.solver)
        (args.out / "cost.json").write_text(json.dumps(cost, indent=2) + "\n")
        print(json.dumps(cost, indent=2))
        return pd.DataFrame([cost])
    states = _states(args.particles, seeds, args.hold)
    rows = []
    for state, data in states.items():
        batch = DEMBatch(data, device="cpu")
        snap = batch.snapshot()
        h = batch.homogenize()
        tangents = {
            "kr": h.tangent,
            "condensed": condensed_tangent(data).tangent,
            "condensed-coulomb": condensed_tangent(data, sliding="coulomb").tangent,
            "condensed-sticking": condensed_tangent(data, sliding="stick").tangent,
            "perturbation": _perturbation(batch, snap),
        }
        for protocol in ("drive", "drive-30", "quasi-static"):
            for direction, unit in DIRECTIONS.items():
                grad = args.increment * unit
                dem = _change(batch, snap, grad, protocol, args.hold)
                for b, seed in enumerate(seeds):
                    row = {"state": state, "protocol": protocol, "direction": direction,
                           "seed": seed, "dem_norm_pa": float(np.linalg.norm(dem[b])),
                           "sliding_fraction": float(h.sliding_fraction[b])}
                    for name, c in tangents.items():
                        predicted = np.einsum("ijkl,kl->ij", c[b], grad)
                        row[f"{name}_err"] = float(np.linalg.norm(predicted - dem[b])
                                                   / np.linalg.norm(dem[b]))
                    rows.append(row)
                print(state, protocol, direction, flush=True)
    table = pd.DataFrame(rows)
    table.to_csv(args.out / "prediction.csv", index=False)
    errors = [c for c in table.columns if c.endswith("_err")]
    summary = table.groupby(["state", "protocol", "direction"], sort=False)[errors].agg(
        lambda v: " / ".join(f"{100 * x:.0f}" for x in v)).reset_index()
    (args.out / "prediction.md").write_text(markdown_table(summary) + "\n")
    cost = _costs(states["p0"], args.increment, solver=args.solver)
    cost.update(particles=args.particles, seeds=seeds, solver=args.solver)
    (args.out / "cost.json").write_text(json.dumps(cost, indent=2) + "\n")
    print(markdown_table(summary))
    print(json.dumps(cost, indent=2))
    return table


if __name__ == "__main__":
    main()
