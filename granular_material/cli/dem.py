"""Core command-line commands: ``prepare``, ``biaxial-dem`` and ``dem-drive``."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

if TYPE_CHECKING:
    from granular_material.dem import DEMBatch as DEMBatchType

__all__ = ["register"]


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive finite number, got {text!r}")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value


def _grad_u(text: str) -> np.ndarray:
    parts = text.split(",")
    if len(parts) != 4:
        raise argparse.ArgumentTypeError(
            f"--grad-u takes four comma-separated numbers Gxx,Gxy,Gyx,Gyy, got {text!r}"
        )
    try:
        values = np.array([float(p) for p in parts])
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--grad-u has a value that is not a number: {text!r}"
        ) from None
    if not np.isfinite(values).all():
        raise argparse.ArgumentTypeError(f"--grad-u must be finite, got {text!r}")
    return values.reshape(2, 2)


def _add_device(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--device", choices=["cpu", "cuda"], default=None,
                        help="warp device (default: CUDA when present, else CPU)")
    parser.add_argument("--dtype", choices=["float64", "float32"], default="float64",
                        help="floating-point precision of the DEM (default: float64)")
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                        help="progress bars on stderr (default: when stderr is a terminal)")
    parser.add_argument("--json", action="store_true",
                        help="print the key results as JSON on stdout")


def _progress(args: argparse.Namespace) -> bool:
    return sys.stderr.isatty() if args.progress is None else bool(args.progress)


def _scalar_or_list(values: np.ndarray) -> Any:
    values = np.asarray(values)
    listed = values.tolist()
    return listed[0] if values.shape[0] == 1 else listed


def _emit(args: argparse.Namespace, result: dict[str, Any]) -> None:
    if args.json:
        json.dump(result, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        for key, value in result.items():
            print(f"{key:>24}: {value}")


def _ensure_parents(*paths: Path | None) -> None:
    """Create the folders of the output files up front, so a bad path fails before the run."""
    for path in paths:
        if path is not None:
            Path(path).parent.mkdir(parents=True, exist_ok=True)


def _write_csv(frame: pd.DataFrame, path: Path) -> None:
    tmp = path.with_name(path.name + ".part")
    frame.to_csv(tmp, index=False)
    os.replace(tmp, path)


def _load_batch(args: argparse.Namespace) -> DEMBatchType:
    from granular_material.dem import DEMBatch, load_rve

    data = load_rve(args.rve)
    return DEMBatch(data, device=args.device, dtype=args.dtype)


# -- prepare -------------------------------------------------------------------------------
def _run_prepare(args: argparse.Namespace) -> int:
    from granular_material.dem import RVEMeta, save_rve
    from granular_material.procedures import prepare_packing

    if args.radius_min > args.radius_max:
        raise ValueError(f"--radius-min {args.radius_min} exceeds --radius-max {args.radius_max}")
    if args.law == "constant":
        stiffness = {"law": "constant", "kn": args.kn, "kt": args.kt}
    else:
        stiffness = {"law": "frictmat", "young": args.young, "kt_over_kn": args.kt_over_kn}
    meta = RVEMeta(thickness=args.thickness, density=args.density,
                   friction_angle=args.friction_angle, damping=args.damping,
                   stiffness=stiffness, seed=args.seed)
    meta.validate()
    _ensure_parents(args.out)
    batch = prepare_packing(
        n_disc=args.particles, n_rve=args.batch, seed=args.seed, pressure=args.pressure,
        meta=meta, target_void_ratio=args.target_void_ratio,
        radius_range=(args.radius_min, args.radius_max), device=args.device, dtype=args.dtype,
        progress=_progress(args),
    )
    h = batch.homogenize()
    save_rve(args.out, batch.to_data())
    _emit(args, {
        "void_ratio": _scalar_or_list(h.void_ratio),
        "mean_stress": _scalar_or_list(h.mean_stress),
        "coordination": _scalar_or_list(h.coordination),
        "cell": _scalar_or_list(batch.cell()),
        "particles": batch.n_disc,
        "batch": batch.n_rve,
        "timestep": _scalar_or_list(batch.dt),
        "out": str(args.out),
    })
    return 0


# -- biaxial-dem ---------------------------------------------------------------------------
def _plot_biaxial(curve: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for rve, group in curve.groupby("rve"):
        eps = 100 * group["axial_strain"]
        ax1.plot(eps, group["stress_ratio"], label=f"RVE {rve}")
        ax2.plot(eps, -100 * group["volumetric_strain"], label=f"RVE {rve}")
    ax1.set_xlabel("axial strain εa [%] (compression positive)")
    ax1.set_ylabel("stress ratio σ1/σ3 [-]")
    ax2.set_xlabel("axial strain εa [%] (compression positive)")
    ax2.set_ylabel("volumetric strain εv [%] (contraction positive)")
    if curve["rve"].nunique() <= 10:
        ax1.legend()
    fig.suptitle("Drained biaxial test of the RVE(s)")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _run_biaxial(args: argparse.Namespace) -> int:
    from granular_material.procedures import biaxial_test, summarize_biaxial

    _ensure_parents(args.out, args.plot)
    batch = _load_batch(args)
    curve = biaxial_test(batch, axial_strain=args.axial_strain, confining=args.confining,
                         strain_per_step=args.strain_per_step,
                         record_every=args.record_every, progress=_progress(args))
    summaries = [summarize_biaxial(g) for _, g in curve.groupby("rve")]
    if args.out:
        _write_csv(curve, Path(args.out))
    if args.plot:
        _plot_biaxial(curve, Path(args.plot))
    keys = ("peak_stress_ratio", "axial_strain_at_peak", "max_contraction", "final_void_ratio")
    _emit(args, {key: _scalar_or_list(np.array([getattr(s, key) for s in summaries]))
                 for key in keys} | {"steps": int(curve["step"].max())})
    return 0


# -- dem-drive -----------------------------------------------------------------------------
def _run_drive(args: argparse.Namespace) -> int:
    from granular_material.procedures import drive_grad_u, path_increment

    _ensure_parents(args.out)
    batch = _load_batch(args)
    grad = args.grad_u
    b = batch.n_rve
    rows = []
    steps = 0

    def record(increment: int) -> None:
        h = batch.homogenize()
        applied = grad * increment / args.increments
        rows.append(pd.DataFrame({
            "rve": np.arange(b), "increment": increment,
            "Gxx": applied[0, 0], "Gxy": applied[0, 1], "Gyx": applied[1, 0],
            "Gyy": applied[1, 1],
            "sxx": h.stress[:, 0, 0], "syy": h.stress[:, 1, 1],
            "sxy": 0.5 * (h.stress[:, 0, 1] + h.stress[:, 1, 0]),
            "void_ratio": h.void_ratio, "coordination": h.coordination,
            "steps": steps,
        }))

    record(0)
    for inc in range(1, args.increments + 1):
        step_grad = path_increment(grad, inc, args.increments)
        steps += drive_grad_u(batch, step_grad, max_strain_per_step=args.max_strain_per_step,
                              progress=_progress(args))
        record(inc)
    table = pd.concat(rows, ignore_index=True)
    if args.out:
        _write_csv(table, Path(args.out))
    last = table[table["increment"] == args.increments]
    _emit(args, {
        "sxx": _scalar_or_list(last["sxx"].to_numpy()),
        "syy": _scalar_or_list(last["syy"].to_numpy()),
        "sxy": _scalar_or_list(last["sxy"].to_numpy()),
        "void_ratio": _scalar_or_list(last["void_ratio"].to_numpy()),
        "coordination": _scalar_or_list(last["coordination"].to_numpy()),
        "steps": steps,
    })
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``prepare``, ``biaxial-dem`` and ``dem-drive`` to the command line."""
    p = subparsers.add_parser(
        "prepare", help="generate and consolidate periodic RVE packings",
        description="Random discs in a periodic cell, frictionless isotropic consolidation "
        "to --pressure, then friction set and re-equilibrated; written as an RVE file.",
    )
    p.add_argument("--particles", type=_positive_int, default=400, help="discs per RVE (400)")
    p.add_argument("--seed", type=int, default=1, help="random seed; RVE b uses seed + b (1)")
    p.add_argument("--pressure", type=_positive, default=100e3,
                   help="isotropic consolidation pressure [Pa] (100e3)")
    p.add_argument("--batch", type=_positive_int, default=1, help="number of RVEs B (1)")
    p.add_argument("--out", type=Path, default=Path("rve.npz"), help="RVE file (rve.npz)")
    p.add_argument("--target-void-ratio", type=_positive, default=None,
                   help="first compress the gas to this 2D void ratio (Wu et al.: 0.18)")
    p.add_argument("--radius-min", type=_positive, default=3e-3, help="[m] (3e-3)")
    p.add_argument("--radius-max", type=_positive, default=7e-3, help="[m] (7e-3)")
    p.add_argument("--law", choices=["constant", "frictmat"], default="constant",
                   help="contact stiffness law (constant: Wu et al. Table 1)")
    p.add_argument("--kn", type=_positive, default=3e6, help="normal stiffness [N/m] (3e6)")
    p.add_argument("--kt", type=_positive, default=2.4e6, help="tangential stiffness [N/m]")
    p.add_argument("--young", type=_positive, default=6e8,
                   help="FrictMat Young's modulus [Pa] for --law frictmat (6e8)")
    p.add_argument("--kt-over-kn", type=_positive, default=0.8, help="FrictMat kt/kn (0.8)")
    p.add_argument("--friction-angle", type=float, default=0.5, help="[rad] (0.5)")
    p.add_argument("--damping", type=float, default=0.1, help="local damping (0.1)")
    p.add_argument("--density", type=_positive, default=2650.0, help="[kg/m³] (2650)")
    p.add_argument("--thickness", type=_positive, default=0.1, help="disc thickness [m] (0.1)")
    _add_device(p)
    p.set_defaults(func=_run_prepare)

    p = subparsers.add_parser(
        "biaxial-dem", help="drained biaxial test of the RVE(s) of a file",
        description="σxx held at -confining by a servo while the axial strain εyy is driven. "
        "CSV columns: rve, step, axial_strain (compression positive), lateral_strain, "
        "volumetric_strain, sxx, syy, sxy [Pa, tension positive], stress_ratio, void_ratio, "
        "coordination.",
    )
    p.add_argument("rve", type=Path, help="RVE file (.npz)")
    p.add_argument("--axial-strain", type=_positive, default=0.1, help="final strain (0.1)")
    p.add_argument("--confining", type=_positive, default=100e3, help="[Pa] (100e3)")
    p.add_argument("--strain-per-step", type=_positive, default=1e-5, help="(1e-5)")
    p.add_argument("--record-every", type=_positive_int, default=100,
                   help="steps between CSV rows (100)")
    p.add_argument("--out", type=Path, default=None, help="CSV of the curve(s)")
    p.add_argument("--plot", type=Path, default=None, help="PNG of σ1/σ3 and εv vs εa")
    _add_device(p)
    p.set_defaults(func=_run_biaxial)

    p = subparsers.add_parser(
        "dem-drive", help="apply a displacement gradient to the RVE(s) of a file",
        description="Applies the total ∇u in K equal strain-driven increments (at most "
        "--max-strain-per-step strain a step, Guo & Zhao). CSV: one row per increment and "
        "RVE (increment 0 = initial state): rve, increment, Gxx, Gxy, Gyx, Gyy (∇u so far), "
        "sxx, syy, sxy [Pa, tension positive], void_ratio, coordination, steps.",
    )
    p.add_argument("rve", type=Path, help="RVE file (.npz)")
    p.add_argument("--grad-u", type=_grad_u, required=True, metavar="Gxx,Gxy,Gyx,Gyy",
                   help="total displacement gradient ∂u_i/∂x_j")
    p.add_argument("--increments", type=_positive_int, default=10, help="K (10)")
    p.add_argument("--max-strain-per-step", type=_positive, default=1e-5, help="(1e-5)")
    p.add_argument("--out", type=Path, default=None, help="CSV of the path")
    _add_device(p)
    p.set_defaults(func=_run_drive)
