"""What a Newton correction sees: the derivative of an RVE's response to a whole load step,
against the tangents the FEM can hold, along a drained biaxial path (issue 26).

Usage::

    python benchmarks/newton_tangent.py [--particles 400] [--seeds 1,2,3]
        [--strains 0.1,0.5,1.5,3,6] [--step 1e-3] [--width 0.05] [--out DIR]

The FEM drives an RVE from its committed state along the whole step every time Newton
evaluates it (``--drive restart``, the default): an iterate ∇u gives the stress S(∇u) after
the path from the committed state to ∇u. A correction δ then changes the stress by
J:δ, J = ∂S/∂∇u, the derivative of that whole path. A tangent measured at the end of
the path (Kruyt–Rothenburg, objective, condensed) describes what one more small increment
would do from there: a different quantity where contacts slide along the path.

RVEs of ``--particles`` discs (one per seed, ``prepare_packing``: 100 kPa, friction 0.5 rad)
go through the pure-DEM biaxial test (σxx held at −100 kPa, 1e-5 axial strain a DEM step)
to each of ``--strains`` (axial, %). At each state the load step is Δ = diag(εl, −``--step``),
with εl the lateral strain the test itself makes over the next ``--step`` of axial strain.
From that state:

- J by central differences: the path to Δ ± h E (h = ``--width`` × ``--step``; E = xx, yy
  and the symmetric xy), driven at the FEM's 1e-5 strain a DEM step, so that the drift of
  the state and what the path's own speed does cancel;
- at the end of the path to Δ: the Kruyt–Rothenburg tangent (``homogenize``), the
  objective one, the condensed one (free sliding, Coulomb, and every contact sticking), and
  the perturbation tangent as the DEM material computes it (forward differences of the same
  path, h = 0.1 × max|Δ|).

Each tangent C is compared with J on the three symmetric directions (Voigt xx, yy, 2xy, a
3 × 3 block): ``error`` = ‖C − J‖/‖J‖ (Frobenius) and ``xx ratio`` = C_xxxx/J_xxxx, the
entry a single element's Newton corrections move (its lateral strain). Writes
``newton_tangent.csv`` and ``newton_tangent.md`` under ``--out``. Measures; never passes or
fails.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from granular_material.dem import DEMBatch, Homogenized, RVEData
from granular_material.dem.batch import BatchSnapshot
from granular_material.dem.condensed.tangent import condensed_tangent
from granular_material.dem.homogenization import objective_tangent
from granular_material.procedures import biaxial_test, drive_grad_u, prepare_packing
from granular_material.results.compare import markdown_table

#: the symmetric unit directions of ∇u, in Voigt order xx, yy, xy (a symmetric shear of
#: engineering strain 1)
DIRECTIONS = (np.diag([1.0, 0.0]), np.diag([0.0, 1.0]), np.array([[0.0, 0.5], [0.5, 0.0]]))
CONFINING = 100e3  #: [Pa]
PERTURBATION = 0.1  #: the DEM material's default relative perturbation


def _voigt_stress(stress: np.ndarray) -> np.ndarray:
    """Stresses (B, 2, 2) as Voigt rows (B, 3): σxx, σyy, σxy."""
    return np.stack([stress[:, 0, 0], stress[:, 1, 1], stress[:, 0, 1]], axis=1)


def _voigt(tangent: np.ndarray) -> np.ndarray:
    """C (B, 2, 2, 2, 2) [Pa] as the (B, 3, 3) block acting on the symmetric directions,
    rows σxx, σyy, σxy."""
    return np.stack([_voigt_stress(np.einsum("bijkl,kl->bij", tangent, e))
                     for e in DIRECTIONS], axis=2)


def _after(batch: DEMBatch, snap: BatchSnapshot, grad_u: np.ndarray) -> Homogenized:
    """The RVEs' response at the end of the path from ``snap`` to ``grad_u`` (B, 2, 2)."""
    batch.restore(snap)
    drive_grad_u(batch, grad_u)
    return batch.homogenize()


def _differences(batch: DEMBatch, snap: BatchSnapshot, step: np.ndarray, width: float,
                 base: np.ndarray | None = None) -> np.ndarray:
    """(B, 3, 3) [Pa]: differences of the path's end stress at ``step`` along
    :data:`DIRECTIONS`, central without ``base``, forward from the stress ``base`` (B, 2, 2)
    at ``step`` with it (the perturbation tangent)."""
    columns = []
    for e in DIRECTIONS:
        plus = _after(batch, snap, step + width * e).stress
        if base is None:
            d = (plus - _after(batch, snap, step - width * e).stress) / (2 * width)
        else:
            d = (plus - base) / width
        columns.append(_voigt_stress(d))
    return np.stack(columns, axis=2)


def _final(curve: pd.DataFrame) -> pd.DataFrame:
    """The last record of a :func:`biaxial_test` curve, one row per RVE in batch order."""
    return curve[curve["step"] == curve["step"].max()].sort_values("rve")


def _lateral_rate(batch: DEMBatch, snap: BatchSnapshot, step: float) -> np.ndarray:
    """Lateral strain [-] (B,) the biaxial test makes over the next ``step`` of axial
    strain from ``snap`` (the state is restored after)."""
    batch.restore(snap)
    lateral = _final(biaxial_test(batch, axial_strain=step, confining=CONFINING))
    batch.restore(snap)
    return lateral["lateral_strain"].to_numpy()


def measure(particles: int, seeds: list[int], strains: list[float], step: float,
            width: float) -> pd.DataFrame:
    """One row per seed, state and tangent (module docstring)."""
    batch = DEMBatch(RVEData.concatenate([
        prepare_packing(n_disc=particles, seed=s, device="cpu").to_data() for s in seeds]),
        device="cpu")
    rows = []
    reached = 0.0
    for strain in strains:
        curve = biaxial_test(batch, axial_strain=(strain - reached) / (1 - reached),
                             confining=CONFINING)
        reached = strain
        last = _final(curve)
        snap = batch.snapshot()
        lateral = _lateral_rate(batch, snap, step)
        load = np.zeros((batch.n_rve, 2, 2))
        load[:, 0, 0], load[:, 1, 1] = lateral, -step
        exact = _differences(batch, snap, load, width * step)
        h = _after(batch, snap, load)
        data = batch.to_data()
        condensed = {mode: condensed_tangent(data, sliding=mode).tangent
                     for mode in ("free", "coulomb", "stick")}
        tangents = {
            "kruyt-rothenburg": _voigt(h.tangent),
            "objective": _voigt(objective_tangent(h.tangent, h.stress)),
            "condensed": _voigt(condensed["free"]),
            "condensed-coulomb": _voigt(condensed["coulomb"]),
            "condensed-sticking": _voigt(condensed["stick"]),
            "perturbation": _differences(batch, snap, load, PERTURBATION * step, h.stress),
        }
        for name, c in tangents.items():
            for b, seed in enumerate(seeds):
                j = exact[b]
                rows.append({
                    "seed": seed, "axial strain %": 100 * strain,
                    "stress ratio": float(last["stress_ratio"].iloc[b]),
                    "lateral/axial": float(lateral[b] / step), "tangent": name,
                    "error %": 100 * float(np.linalg.norm(c[b] - j) / np.linalg.norm(j)),
                    "xx ratio": float(c[b, 0, 0] / j[0, 0]),
                    "J_xxxx MPa": float(j[0, 0] / 1e6),
                })
        batch.restore(snap)
    return pd.DataFrame(rows)


def summary(table: pd.DataFrame) -> pd.DataFrame:
    """Median and range over the seeds, per state and tangent."""
    def spread(x: pd.Series) -> str:
        return f"{x.median():.2f} ({x.min():.2f}–{x.max():.2f})"
    grouped = table.groupby(["axial strain %", "tangent"], sort=False)
    out = grouped.agg(**{"stress ratio": ("stress ratio", "median"),
                         "J_xxxx MPa": ("J_xxxx MPa", "median")})
    out["error %"] = grouped["error %"].apply(spread)
    out["xx ratio"] = grouped["xx ratio"].apply(spread)
    return out.reset_index().round({"stress ratio": 3, "J_xxxx MPa": 2})


def main(argv: list[str] | None = None) -> pd.DataFrame:
    """Run the measurement and write the tables; returns the per-seed table."""
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--particles", type=int, default=400)
    parser.add_argument("--seeds", default="1,2,3")
    parser.add_argument("--strains", default="0.1,0.5,1.5,3,6",
                        help="axial strains [%%] of the states, increasing")
    parser.add_argument("--step", type=float, default=1e-3,
                        help="axial strain of the load step (the single element's 0.1 %%)")
    parser.add_argument("--width", type=float, default=0.05,
                        help="central-difference width, a share of --step")
    parser.add_argument("--out", type=Path, default=Path("newton-tangent"))
    args = parser.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    strains = [float(s) / 100 for s in args.strains.split(",")]
    table = measure(args.particles, seeds, strains, args.step, args.width)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "newton_tangent.csv", index=False)
    text = (f"# What a Newton correction sees\n\n{args.particles} discs, seeds {args.seeds}, "
            f"load step {args.step:g} axial, central differences of width "
            f"{args.width:g} × step. Median (range) over the seeds.\n\n"
            + markdown_table(summary(table)) + "\n")
    (args.out / "newton_tangent.md").write_text(text, encoding="utf-8")
    print(text)
    return table


if __name__ == "__main__":
    main()
