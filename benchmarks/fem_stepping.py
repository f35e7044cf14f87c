"""What stepping only what needs it saves: FEM × DEM runs with each RVE-stepping setting
beside the exact one (every RVE driven from its committed state at every Newton iteration),
from the same RVEs, in one run.

Usage::

    python benchmarks/fem_stepping.py [--elements 5 10] [--particles 64] [--steps 50]
        [--axial-strain 0.1] [--repeats 1] [--variants exact,continue,...] [--out DIR]

One RVE file (``--particles`` discs, seed 1, 100 kPa, one RVE per Gauss point) is prepared
and every variant runs the drained biaxial specimen (or, with ``--elements 1 1``, the single
element) from it, each a run spec run in a fresh process (``granular-material run
SPEC.toml``), the variants taking turns ``--repeats`` times.
The table (``stepping.csv`` and ``stepping.md`` under ``--out``) holds, per variant, over
the load steps every run completed: the median wall time of those steps, the counts (Newton
iterations, RVE paths, DEM particle-steps), the ratios to the exact run, and the errors
against it: peak σ1/σ3 and its axial strain, the RMS difference of the stress-ratio and εv
curves (relative to the exact curve's largest value) and the final shear-band inclination.
Measures; never passes or fails.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.dem import save_rve
from granular_material.procedures import prepare_packing
from granular_material.results.compare import markdown_table

#: the variants: name -> the run spec fields (flat names) each sets
VARIANTS: dict[str, dict[str, Any]] = {
    "exact": {"drive": "restart", "reuse_tol": 0.0},
    "reuse-1e-6": {"drive": "restart", "reuse_tol": 1e-6},
    "reuse-3e-6-tangent": {"drive": "restart", "reuse_tol": 3e-6,
                           "reuse_correction": "tangent"},
    "continue": {"drive": "continue", "reuse_tol": 0.0},
    "continue-reuse-1e-6": {"drive": "continue", "reuse_tol": 1e-6},
}
#: the Newton settings of every run (the force test: reuse needs it)
NEWTON = {"convergence": "force", "max_iterations": 60, "max_cutbacks": 8}


def _options(fields: dict[str, Any]) -> str:
    """Spec fields as ``name=value`` words (the table's ``options`` column)."""
    return " ".join(f"{k}={v}" for k, v in fields.items())


def _run(rve: Path, out: Path, elements: tuple[int, int], steps: int, axial_strain: float,
         fields: dict[str, Any]) -> dict:
    """One FEM run in a fresh process (``granular-material run SPEC.toml``: its own start-up,
    none of the variant before it in memory); its summary and steps table."""
    from granular_material.runs import from_flat, save

    problem = ({"test": "single-element"} if elements == (1, 1) else
               {"test": "biaxial", "elements": elements, "map_strain": (0.02,)})
    spec = from_flat({**problem, "material": "dem", "rve": rve, "steps": steps,
                      "axial_strain": axial_strain, "out": out, "progress": False,
                      **NEWTON, **fields})
    spec_file = out.with_suffix(".toml")
    save(spec, spec_file)
    done = subprocess.run([sys.executable, "-m", "granular_material.cli", "run",
                           str(spec_file)], capture_output=True, text=True)
    if done.returncode not in (0, 1) or not (out / "summary.json").is_file():
        raise RuntimeError(f"the run of {spec_file} failed ({done.returncode}): "
                           f"{done.stderr[-2000:]}")
    summary = json.loads((out / "summary.json").read_text())
    summary["table"] = pd.read_csv(out / "steps.csv")
    return summary


def _errors(run: dict, exact: dict) -> dict:
    """Errors of ``run`` against ``exact`` over the steps both completed."""
    a, b = run["table"], exact["table"]
    n = min(len(a), len(b))
    q_a, q_b = a["stress_ratio"].to_numpy()[1:n], b["stress_ratio"].to_numpy()[1:n]
    e_a, e_b = a["volumetric_strain"].to_numpy()[1:n], b["volumetric_strain"].to_numpy()[1:n]
    rms = lambda x, y: float(np.sqrt(np.mean((x - y) ** 2))) if len(x) else np.nan  # noqa: E731
    band = run.get("shear_band_final") or {}
    return {
        "peak_stress_ratio": run["peak_stress_ratio"],
        "peak_error_pct": 100 * (run["peak_stress_ratio"] / exact["peak_stress_ratio"] - 1),
        "axial_strain_at_peak_pct": 100 * run["axial_strain_at_peak"],
        "stress_ratio_rms_pct": 100 * rms(q_a, q_b) / np.abs(q_b).max() if n > 1 else np.nan,
        "volumetric_strain_rms": rms(e_a, e_b),
        "volumetric_strain_rms_pct": (100 * rms(e_a, e_b) / np.abs(e_b).max()
                                      if n > 1 and np.abs(e_b).max() > 0 else np.nan),
        "band_inclination_deg": band.get("inclination_deg", np.nan),
        "compared_steps": n - 1,
    }


def main(argv: list[str] | None = None) -> pd.DataFrame:
    """Run the benchmark; returns the table (also written under ``--out``)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--elements", type=int, nargs=2, default=(5, 10))
    parser.add_argument("--particles", type=int, default=64)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--axial-strain", type=float, default=0.1)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--variants", default=",".join(VARIANTS),
                        help=f"comma-separated, from {', '.join(VARIANTS)}; exact comes first")
    parser.add_argument("--out", type=Path, default=Path("out/stepping"))
    args = parser.parse_args(argv)
    names = [v for v in args.variants.split(",") if v]
    unknown = sorted(set(names) - set(VARIANTS))
    if unknown:
        parser.error(f"unknown variants {unknown}; choose from {', '.join(VARIANTS)}")
    names = ["exact", *[n for n in names if n != "exact"]]
    elements = tuple(args.elements)
    points = 4 * elements[0] * elements[1]
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        rve = Path(tmp) / "rves.npz"
        save_rve(rve, prepare_packing(n_disc=args.particles, n_rve=points, seed=1).to_data())
        runs: dict[str, list[dict]] = {n: [] for n in names}
        for repeat in range(args.repeats):
            for name in names:
                out = Path(tmp) / f"{name}-{repeat}"
                runs[name].append(_run(rve, out, elements, args.steps, args.axial_strain,
                                       VARIANTS[name]))
                print(f"{name} #{repeat + 1}: {runs[name][-1]['wall_time_s']:.1f} s",
                      file=sys.stderr)
    exact = runs["exact"][0]
    common = min(r["steps_completed"] for rs in runs.values() for r in rs)
    rows = []
    for name in names:
        first = runs[name][0]
        done = first["table"].iloc[1:common + 1]
        row = {"variant": name, "options": _options({**NEWTON, **VARIANTS[name]}),
               "wall_s": float(np.median([r["table"]["wall_time"].iloc[1:common + 1].sum()
                                          for r in runs[name]])),
               "newton_iterations": int(done["iterations"].sum()),
               "rve_evaluations": int(done["rve_evaluations"].sum()),
               "particle_steps": int(done["particle_steps"].sum()),
               "steps_completed": first["steps_completed"], "error": first["error"],
               **_errors(first, exact)}
        rows.append(row)
    table = pd.DataFrame(rows)
    base = table.iloc[0]
    table["wall_ratio"] = base["wall_s"] / table["wall_s"]
    table["particle_steps_ratio"] = base["particle_steps"] / table["particle_steps"]
    table.to_csv(args.out / "stepping.csv", index=False)
    (args.out / "stepping.md").write_text(markdown_table(table.drop(columns=["options"])))
    print(table.drop(columns=["options"]).to_string(index=False))
    return table


if __name__ == "__main__":
    main()
