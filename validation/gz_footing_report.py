"""The side-by-side of Guo & Zhao's footing and ours (:mod:`gz_footing`): tables and figures.

Reads a folder written by ``python -m granular_material_validation.gz_footing`` (``guo_zhao/``
and ``ours/``) and writes ``footing_curves.png``, ``footing_mechanism.png``,
``footing_iterations.png`` and ``comparison.json`` next to them; :func:`markdown` turns
the comparison into the report's tables.

Run: ``python -m granular_material_validation.gz_footing_report DIR`` (the tables), or
``... gz_footing_report DEST LABEL=DIR [LABEL=DIR ...]`` (``report.md`` and the figures in
DEST, :func:`write_report`).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from granular_material_validation.guo_zhao_runner import gauss_fields
from granular_material_validation.gz_footing_mesh import (
    HALF_WIDTH,
    SETTLEMENT_PER_STEP,
    SURCHARGE,
    FootingMesh,
    footing_nodal_reaction,
    footing_traction_force,
    match_elements,
    read_gmsh22,
)

from granular_material.results.writers import read_points

__all__ = ["compare", "element_gamma", "markdown", "projected_forces", "write_report"]


def _stress(frame: pd.DataFrame) -> np.ndarray:
    s = np.zeros((len(frame), 2, 2))
    s[:, 0, 0], s[:, 1, 1] = frame["sxx"], frame["syy"]
    s[:, 0, 1] = s[:, 1, 0] = frame["sxy"]
    return s


def projected_forces(mesh: FootingMesh, points: pd.DataFrame) -> pd.DataFrame:
    """Per step of a Gauss-point table (``step``, ``point``, ``x``, ``y``, ``sxx``, ``syy``,
    ``sxy``; points element by element): their footing force [N/m] computed from it
    (:func:`~granular_material_validation.gz_footing_mesh.footing_traction_force`,
    ``force_y``) and the nodal reaction (``reaction_y``,
    :func:`~granular_material_validation.gz_footing_mesh.footing_nodal_reaction`)."""
    rows = []
    for step, g in points.groupby("step"):
        g = g.sort_values("point")
        xy, sigma = g[["x", "y"]].to_numpy(), _stress(g)
        force, length = footing_traction_force(mesh, xy, sigma)
        reaction = footing_nodal_reaction(mesh, xy, sigma, SURCHARGE)
        rows.append({"step": int(step), "force_x": force[0], "force_y": force[1],
                     "base_length": length, "reaction_y": reaction[1]})
    return pd.DataFrame(rows)


def element_gamma(mesh: FootingMesh, points: pd.DataFrame, step: int) -> np.ndarray:
    """Mean deviatoric shear strain γ = √((εxx − εyy)² + 4εxy²) of the Gauss points of each
    triangle of ``mesh`` (its order) at ``step``."""
    g = points[points["step"] == step].sort_values("point")
    gamma = np.hypot(g["exx"] - g["eyy"], 2.0 * g["exy"]).to_numpy().reshape(-1, 3).mean(1)
    out = np.empty(len(mesh.triangles))
    out[match_elements(mesh, g[["x", "y"]].to_numpy())] = gamma
    return out


def compare(folder: str | Path) -> dict[str, Any]:
    """Read both runs in ``folder`` (on the mesh of ``guo_zhao/mesh.msh``), write the
    figures and ``comparison.json``; return it."""
    folder = Path(folder)
    mesh = read_gmsh22(folder / "guo_zhao" / "mesh.msh")
    theirs = pd.read_csv(folder / "guo_zhao" / "gz_curve.csv")
    tsum = json.loads((folder / "guo_zhao" / "gz_summary.json").read_text())
    tpoints = gauss_fields(folder / "guo_zhao")
    osteps = pd.read_csv(folder / "ours" / "run" / "steps.csv")
    opoints = read_points(folder / "ours" / "run")
    osum = json.loads((folder / "ours" / "summary.json").read_text())
    tproj = projected_forces(mesh, tpoints)
    oproj = projected_forces(mesh, opoints)
    n = int(min(theirs["step"].max(), osteps["step"].max(), tproj["step"].max()))
    b = HALF_WIDTH
    table = pd.DataFrame({"step": np.arange(n + 1)})
    table["settlement_mm"] = table["step"] * SETTLEMENT_PER_STEP * 1e3
    def col(frame: pd.DataFrame, name: str, scale: float = 1.0) -> np.ndarray:
        return frame.set_index("step")[name].reindex(table["step"]).to_numpy() * scale

    kpa = -1.0 / b / 1e3
    table["q_theirs_kpa"] = col(theirs, "force_y", kpa)
    table["q_theirs_reference_kpa"] = col(tproj, "force_y", kpa)
    table["q_theirs_nodal_kpa"] = col(tproj, "reaction_y", kpa)
    table["q_ours_nodal_kpa"] = col(osteps, "footing_force_y", kpa)
    table["q_ours_nodal_reference_kpa"] = col(oproj, "reaction_y", kpa)
    table["q_ours_projected_kpa"] = col(oproj, "force_y", kpa)
    table["iterations_theirs"] = col(theirs, "iterations")
    table["iterations_ours"] = col(osteps, "iterations")
    table["wall_theirs_s"] = col(theirs, "wall_time")
    table["wall_ours_s"] = col(osteps, "wall_time")
    gt, go = element_gamma(mesh, tpoints, n), element_gamma(mesh, opoints, n)
    centres = mesh.points[mesh.corners].mean(axis=1)
    mech = {"step": n, "settlement_mm": n * SETTLEMENT_PER_STEP * 1e3,
            "gamma_correlation": float(np.corrcoef(gt, go)[0, 1]),
            "theirs": {"gamma_max": float(gt.max()), "at": centres[gt.argmax()].tolist(),
                       "gamma_mean": float(gt.mean())},
            "ours": {"gamma_max": float(go.max()), "at": centres[go.argmax()].tolist(),
                     "gamma_mean": float(go.mean())}}
    steps_t = theirs[(theirs.step > 0) & (theirs.step <= n)]
    steps_o = osteps[(osteps.step > 0) & (osteps.step <= n)]
    cost = {"theirs": {"steps": len(steps_t), "wall_s": tsum["wall_s"],
                       "cpu_s": tsum["cpu_s"], "processes": tsum["processes"],
                       "stepping_s": float(steps_t["wall_time"].sum()),
                       "stepping_s_all": float(theirs["wall_time"].iloc[1:].sum()),
                       "iterations_mean": float(steps_t["iterations"].mean()),
                       "dem_steps_per_point": float(steps_t["dem_steps"].sum())
                       / (3 * len(mesh.triangles)),
                       "steps_done": tsum["steps_done"], "timed_out": tsum["timed_out"]},
            "ours": {"steps": len(steps_o), "wall_s": osum["driver_wall_s"],
                     "cpu_s": osum["driver_cpu_s"], "timing_s": osum.get("timing_s"),
                     "stepping_s": float(steps_o["wall_time"].sum()),
                     "stepping_s_all": float(osteps["wall_time"].iloc[1:].sum()),
                     "iterations_mean": float(steps_o["iterations"].mean()),
                     "steps_done": int(osteps["step"].max()), "error": osum.get("error")}}
    if "particle_steps" in steps_o:  # disc-steps over the discs of an RVE and the points
        cost["ours"]["dem_steps_per_point"] = float(steps_o["particle_steps"].sum()) / (
            tsum["rve_state"]["particles"] * 3 * len(mesh.triangles))
    out = {"table": table.to_dict(orient="list"), "mechanism": mech, "cost": cost,
           "elements": len(mesh.triangles), "gauss_points": 3 * len(mesh.triangles),
           "rve_state": tsum["rve_state"], "patches": tsum["patches"],
           "ours_initial_residual": osum.get("initial_residual")}
    (folder / "comparison.json").write_text(json.dumps(out, indent=1, default=float))
    full = pd.DataFrame({"settlement_mm": osteps["step"] * SETTLEMENT_PER_STEP * 1e3,
                         "nodal": osteps["footing_force_y"] * kpa,
                         "projected": oproj.set_index("step")["force_y"]
                         .reindex(osteps["step"]).to_numpy() * kpa})
    _figures(folder, mesh, table, gt, go, n, full)
    return out


def _figures(folder: Path, mesh: FootingMesh, table: pd.DataFrame, gt: np.ndarray,
             go: np.ndarray, step: int, full: pd.DataFrame) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.tri import Triangulation

    s = table["settlement_mm"]
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    ax.plot(s, table["q_theirs_kpa"], "k-o", ms=3,
            label="Guo & Zhao (their projected traction)")
    ax.plot(s, table["q_theirs_reference_kpa"], "k:",
            label="theirs, our projection (reference mesh)")
    ax.plot(s, table["q_theirs_nodal_kpa"], "k--", label="theirs: nodal reaction (from their "
            "stresses)")
    ax.plot(s, table["q_ours_nodal_kpa"], "C3-s", ms=3, label="ours: nodal reaction")
    ax.plot(s, table["q_ours_projected_kpa"], "C0--^", ms=3, label="ours: projected traction")
    if len(full) > len(table):  # ours past their last step
        ax.plot(full["settlement_mm"], full["nodal"], "C3-", lw=0.8, alpha=0.6,
                label="ours past their last step")
        ax.plot(full["settlement_mm"], full["projected"], "C0--", lw=0.8, alpha=0.6)
    ax.set_xlabel("settlement [mm]")
    ax.set_ylabel("bearing pressure q = −F/B [kPa]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(folder / "footing_curves.png", dpi=120)
    plt.close(fig)
    tri = Triangulation(mesh.points[:, 0], mesh.points[:, 1], mesh.corners)
    top = float(max(gt.max(), go.max()))
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.4), sharey=True)
    for ax, g, title in ((axes[0], gt, "Guo & Zhao"), (axes[1], go, "ours")):
        im = ax.tripcolor(tri, facecolors=g, cmap="viridis", vmin=0.0, vmax=top,
                          edgecolors="w", linewidth=0.2)
        ax.set_aspect("equal")
        ax.set_xlim(0.0, 0.25)
        ax.set_ylim(-0.2, 0.0)
        ax.set_title(f"{title}: shear strain γ, step {step} "
                     f"({step * SETTLEMENT_PER_STEP * 1e3:.2f} mm)", fontsize=9)
        ax.set_xlabel("x [m]")
    axes[0].set_ylabel("y [m]")
    fig.colorbar(im, ax=axes, shrink=0.8)
    fig.savefig(folder / "footing_mechanism.png", dpi=120)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6.4, 3.2))
    ax.plot(s[1:], table["iterations_theirs"][1:], "k-o", ms=3, label="Guo & Zhao")
    ax.plot(s[1:], table["iterations_ours"][1:], "C3-s", ms=3, label="ours")
    ax.set_xlabel("settlement [mm]")
    ax.set_ylabel("Newton iterations a step")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(folder / "footing_iterations.png", dpi=120)
    plt.close(fig)


def markdown(result: dict[str, Any]) -> str:
    """The report's tables (curves, mechanism, cost) of a :func:`compare` result."""
    t = pd.DataFrame(result["table"])
    lines = ["| step | settlement [mm] | theirs: projected (their number) | theirs: "
             "projected, ours from their stresses | theirs: nodal, from their stresses | "
             "ours: projected | ours: nodal reaction | iterations theirs | iterations ours |",
             "|" + "---|" * 9]
    for r in t.itertuples():
        lines.append(f"| {r.step} | {r.settlement_mm:.2f} | {r.q_theirs_kpa:.1f} | "
                     f"{r.q_theirs_reference_kpa:.1f} | {r.q_theirs_nodal_kpa:.1f} | "
                     f"{r.q_ours_projected_kpa:.1f} | {r.q_ours_nodal_kpa:.1f} | "
                     f"{r.iterations_theirs:.0f} | {r.iterations_ours:.0f} |")
    m = result["mechanism"]
    lines += ["", f"Mechanism at step {m['step']} ({m['settlement_mm']:.2f} mm): "
              f"correlation of the element-mean γ fields {m['gamma_correlation']:.3f}.", "",
              "| code | γ max | at (x, y) [m] | γ mean |", "|---|---|---|---|"]
    for side in ("theirs", "ours"):
        g = m[side]
        lines.append(f"| {side} | {g['gamma_max']:.4f} | ({g['at'][0]:.3f}, {g['at'][1]:.3f}) "
                     f"| {g['gamma_mean']:.4f} |")
    c = result["cost"]
    lines += ["", f"Over the {c['theirs']['steps']} load steps compared:", "",
              "| code | stepping wall [s] | Newton iterations a step | DEM steps a point |",
              "|---|---|---|---|"]
    for side in ("theirs", "ours"):
        k = c[side]
        lines.append(f"| {side} | {k['stepping_s']:.0f} | {k['iterations_mean']:.2f} | "
                     f"{k.get('dem_steps_per_point', float('nan')):.0f} |")
    lines += ["", "Whole runs (ours ran further):", "",
              "| code | load steps done | wall [s] | CPU [s] | processes |",
              "|---|---|---|---|---|"]
    for side, procs in (("theirs", c["theirs"]["processes"]), ("ours", 1)):
        k = c[side]
        lines.append(f"| {side} | {k['steps_done']} | {k['wall_s']:.0f} | {k['cpu_s']:.0f} | "
                     f"{procs} |")
    return "\n".join(lines) + "\n"


def write_report(runs: dict[str, Path], dest: str | Path) -> Path:
    """``report.md`` in ``dest`` with one section per run folder (label → folder, each
    compared by :func:`compare`) and its three figures copied as ``{label}_*.png``."""
    import shutil

    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    parts = ["# gz-footing: the tables\n",
             "Written by `python -m granular_material_validation.gz_footing_report "
             "DEST LABEL=DIR ...` from the run folders of `gz_footing`; bearing pressures "
             "q = −F/B [kPa].\n"]
    for label, folder in runs.items():
        result = compare(folder)
        for name in ("curves", "mechanism", "iterations"):
            shutil.copy(Path(folder) / f"footing_{name}.png", dest / f"{label}_{name}.png")
        c = result["cost"]
        parts += [f"## {label}\n", f"{result['elements']} tri6, {result['gauss_points']} "
                  f"Gauss points, RVE: {result['rve_state']['particles']} discs, e = "
                  f"{result['rve_state']['void_ratio']:.4f}, stress (σxx, σyy, σxy) = "
                  f"({', '.join(f'{v:.0f}' for v in result['rve_state']['stress'])}) Pa; "
                  f"their run: {c['theirs']['steps_done']} load steps"
                  f"{' (stopped at its time limit)' if c['theirs']['timed_out'] else ''}, "
                  f"ours: {c['ours']['steps_done']}; compared over the first "
                  f"{result['mechanism']['step']}.\n",
                  markdown(result),
                  f"![curves]({label}_curves.png)\n\n![mechanism]({label}_mechanism.png)"
                  f"\n\n![iterations]({label}_iterations.png)\n"]
    path = dest / "report.md"
    path.write_text("\n".join(parts))
    return path


if __name__ == "__main__":
    if len(sys.argv) == 2:
        print(markdown(compare(sys.argv[1])))
    else:
        print(write_report(dict(a.split("=", 1) for a in sys.argv[2:]), sys.argv[1]))
