"""The continuum at continuum speed (issue 62): the Mohr–Coulomb biaxial specimen, timed by
phase, on several meshes and commits in one run.

Usage::

    python benchmarks/continuum_speed.py REV [REV ...] [--meshes 4x8,8x16,16x32]
        [--steps 50] [--repeats 3] [--growth-steps 200] [--out out/continuum-speed]

Each REV is a git revision of this repository (checked out into a temporary worktree) or
``.``, this working tree; the first is the one the others are compared with. ``REV+OPTION``
runs that revision with the command's ``--OPTION`` added (``.+no-figures``: this tree
without its figures). Every case runs
the command of the issue (``granular-material biaxial --material mohr-coulomb --phi 35
--phi-cs 28 --softening-strain 0.02 --psi 5 --platens rough``, to 5 % axial strain in
``--steps`` steps, with its output folder) in a fresh process per revision, the revisions
taking turns ``--repeats`` times so that a drifting load hits them alike. From its
``summary.json`` (``timing_s``) it reports, per mesh and revision, the median seconds of
each phase, the share of the run that is neither material, assembly nor solve (tables,
outputs, checkpoints, other), the cost per point-step [µs] of the whole run and of its
Newton work alone, and the ratio of the total to the first revision's (the median of the
repeats' ratios, with their smallest and largest). Beside them, per mesh, the same specimen
as a scikit-fem user would run it (``plain``): the material this tree's command builds, then
plain Newton in small strain with scikit-fem's forms, ``condense`` and ``solve``, nothing
written (its row: ``plain scikit-fem``, its evaluations and unconverged steps in ``commit``;
``--no-plain`` leaves it out). Two more cases, per revision: the wall
time of the whole process of one step on 1 × 2 elements (imports, set-up, figures), and
the tables' seconds per step at step 5 and at the end of a ``--growth-steps`` run to the same
5 % on the first mesh (their ratio: 1 when the tables cost the same at every step). Measures; never
passes or fails.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
# the old spellings of the Mohr-Coulomb options (--phi, --phi-cs, --psi): the commits measured
# beside each other include those from before the renames, which know no other; today's code
# reads them as --friction-angle, --critical-friction-angle, --dilation-angle, with a warning
#: the command of issue 62, less its steps, mesh and folder
COMMAND = ["biaxial", "--material", "mohr-coulomb", "--phi", "35", "--phi-cs", "28",
           "--softening-strain", "0.02", "--psi", "5", "--platens", "rough", "--no-progress"]
#: the phases of ``timing_s`` that are the run's own overhead, not its material or Newton work
OVERHEAD = ("tables", "outputs", "checkpoint", "other")
#: the Newton work of a run: the material, assembly and solve
NEWTON = ("material_other", "dem", "homogenization", "tangent", "assembly", "linear_solve",
          "newton_other")


def worker(nx: int, ny: int, steps: int, axial_strain: float, growth: bool) -> dict:
    """One run of the command in this process (whichever package it imports): its
    ``timing_s`` and, with ``growth``, the tables' seconds of every step."""
    per_step: list[float] = []
    if growth:
        from granular_material import timing

        phase = timing.PhaseTimes.phase

        @contextlib.contextmanager
        def timed(self: object, name: str):  # every entry of ``tables``, one by one
            start = time.perf_counter()
            try:
                with phase(self, name):
                    yield
            finally:
                if name == "tables":
                    per_step.append(time.perf_counter() - start)

        timing.PhaseTimes.phase = timed
    from granular_material.cli import main

    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "run"
        code = main([*COMMAND, *json.loads(os.environ.get(_OPTIONS, "[]")),
                     "--axial-strain", str(axial_strain), "--steps", str(steps),
                     "--elements", str(nx), str(ny), "--out", str(out)])
        summary = json.loads((out / "summary.json").read_text())
    # the runner enters ``tables`` twice a step (its rows, then their writing and saving)
    pairs = np.asarray(per_step[: 2 * (len(per_step) // 2)]).reshape(-1, 2).sum(axis=1)
    return {"code": code, "timing": summary["timing_s"], "tables_per_step": pairs.tolist()}


class _Captured(BaseException):
    """Stops the command once its material and specimen are built (not an Exception, which
    the command line would report)."""


def plain(nx: int, ny: int, steps: int, axial_strain: float, max_iterations: int = 25,
          rtol: float = 1e-4) -> dict:
    """The same specimen as a scikit-fem user would run it: the material the command builds
    (its arrays, on the same Gauss points), then plain Newton in small strain with
    scikit-fem's forms, ``condense`` and ``solve``, the residual's interior norm below
    ``rtol`` times the predictor's, no cut-backs, tables, files or checkpoints. Seconds by
    part, material evaluations and the steps that did not converge."""
    from skfem import condense, solve

    import granular_material.runs.execute as execute
    from granular_material.cli import main
    from granular_material.fem import build_biaxial
    from granular_material.fem.forms import stress_form, tangent_form
    from granular_material.fem.layout import to_points, to_quadrature

    captured: dict = {}

    def capture(setup: object, material: object, *args: object, **kwargs: object) -> None:
        captured.update(setup=setup, material=material)
        raise _Captured

    execute.run_biaxial = capture
    with tempfile.TemporaryDirectory() as scratch, contextlib.suppress(_Captured):
        main([*COMMAND, "--axial-strain", str(axial_strain), "--steps", str(steps),
              "--elements", str(nx), str(ny), "--out", str(Path(scratch) / "run")])
    setup, material = captured["setup"], captured["material"]
    problem = build_biaxial(setup)
    basis, loading = problem.basis, problem.loading
    nqp, fixed = basis.X.shape[-1], loading.dirichlet_dofs
    interior = np.setdiff1d(np.arange(basis.N), fixed)
    times = {"material": 0.0, "assembly": 0.0, "solve": 0.0}

    def timed(part: str, f, *args, **kwargs):
        start = time.perf_counter()
        try:
            return f(*args, **kwargs)
        finally:
            times[part] += time.perf_counter() - start

    def forms(response) -> tuple:
        return (tangent_form.assemble(basis, D=to_quadrature(response.tangent, nqp)),
                stress_form.assemble(basis, sigma=to_quadrature(response.stress, nqp)))

    started = time.perf_counter()
    u = np.zeros(basis.N)
    response = timed("material", material.evaluate, np.zeros((setup.n_points, 2, 2)))
    evaluations, unconverged = 0, 0
    k, f_int = timed("assembly", forms, response)
    for step in range(1, steps + 1):
        u_d, f_ext = loading.at(step / steps)
        du = np.zeros_like(u)
        du[fixed] = u_d - u[fixed]
        a, b, x, inner = condense(k, f_ext - f_int, x=du, D=fixed)
        r0 = float(np.linalg.norm(b))
        du = timed("solve", solve, a, b, x, inner)
        for _ in range(max_iterations):
            grad = to_points(basis.interpolate(du).grad)
            response = timed("material", material.evaluate, grad)
            evaluations += 1
            k, f_int = timed("assembly", forms, response)
            residual = f_int - f_ext
            if np.linalg.norm(residual[interior]) <= rtol * r0:
                break
            du = du + timed("solve", solve, *condense(k, -residual, D=fixed))
        else:
            unconverged += 1
        material.commit()
        u += du
    total = time.perf_counter() - started
    return {"total_s": total, **{f"{k}_s": v for k, v in times.items()},
            "evaluations": evaluations, "unconverged_steps": unconverged}


#: the environment variable that hands a worker the command's added options (JSON)
_OPTIONS = "CONTINUUM_SPEED_OPTIONS"


def _options(rev: str) -> list[str]:
    """The command options a revision ``REV+OPTION`` adds (none without a ``+``)."""
    return [f"--{o}" for o in rev.split("+")[1:]]


def _run(source: Path, *arguments: str, options: list[str] | None = None,
         ) -> tuple[dict, float]:
    """A worker in a fresh process importing the package found at ``source`` (the command
    with ``options`` added); what it returns and the process's wall time [s]."""
    command = [sys.executable, str(Path(__file__).resolve()), "--worker", *arguments]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        filter(None, [str(source), os.environ.get("PYTHONPATH")])),
        _OPTIONS: json.dumps(options or [])}
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, env=env, check=False,
                          cwd=tempfile.gettempdir())
    wall = time.perf_counter() - started
    if done.returncode != 0:
        raise RuntimeError(f"worker {arguments} ({source}) failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1]), wall


def _label(rev: str) -> str:
    """A revision's short commit (``.``: HEAD's, with ``+dirty`` where the tree differs),
    and the options it adds."""
    from granular_material.provenance import code_commit

    base = rev.split("+")[0]
    commit = code_commit() if base == "." else code_commit(base).removesuffix("+dirty")
    return " ".join([commit, *_options(rev)])


def _growth_ratio(per_step: list[float], early: int = 5) -> tuple[float, float, float]:
    """The tables' seconds per step about step ``early`` and at the end (medians of the ten
    steps from ``early`` − 2 on and of the last ten; a step's few milliseconds vary with the
    load) and their ratio."""
    v = np.asarray(per_step)
    start = float(np.median(v[max(early - 2, 1): early + 8]))
    end = float(np.median(v[-10:]))
    return start, end, end / start


def _row(rev: str, label: str, nx: int, ny: int, steps: int, results: list[dict],
         first: list[dict]) -> dict:
    """The medians of one mesh and revision over its repeats."""
    points = 4 * nx * ny
    timings = pd.DataFrame([r["timing"] for r in results]).fillna(0.0)
    totals = timings["total"].to_numpy()
    newton = timings[[c for c in NEWTON if c in timings]].sum(axis=1).to_numpy()
    overhead = timings[[c for c in OVERHEAD if c in timings]].sum(axis=1).to_numpy()
    ratios = totals / np.array([r["timing"]["total"] for r in first])
    row = {"rev": rev, "commit": label, "elements": f"{nx}x{ny}", "points": points,
           "steps": steps, "repeats": len(results), "total_s": float(np.median(totals))}
    for phase in ("material_other", "assembly", "linear_solve", "newton_other", *OVERHEAD):
        row[f"{phase}_s"] = float(np.median(timings[phase])) if phase in timings else 0.0
    row.update(overhead_pct=float(np.median(100 * overhead / totals)),
               us_per_point_step=float(np.median(totals)) / (points * steps) * 1e6,
               newton_us_per_point_step=float(np.median(newton)) / (points * steps) * 1e6,
               ratio=float(np.median(ratios)), ratio_min=float(ratios.min()),
               ratio_max=float(ratios.max()))
    return row


def _plain_row(nx: int, ny: int, steps: int, loops: list[dict], first: list[dict]) -> dict:
    """The medians of the plain scikit-fem loop on one mesh, as a row of the table."""
    points = 4 * nx * ny
    frame = pd.DataFrame(loops)
    totals = frame["total_s"].to_numpy()
    ratios = totals / np.array([r["timing"]["total"] for r in first])
    return {"rev": "plain scikit-fem", "commit": f"{int(frame['evaluations'].median())} "
            f"evaluations, {int(frame['unconverged_steps'].max())} unconverged",
            "elements": f"{nx}x{ny}", "points": points, "steps": steps,
            "repeats": len(loops), "total_s": float(np.median(totals)),
            "material_other_s": float(frame["material_s"].median()),
            "assembly_s": float(frame["assembly_s"].median()),
            "linear_solve_s": float(frame["solve_s"].median()),
            "overhead_pct": 0.0,
            "us_per_point_step": float(np.median(totals)) / (points * steps) * 1e6,
            "newton_us_per_point_step": float(np.median(totals)) / (points * steps) * 1e6,
            "ratio": float(np.median(ratios)), "ratio_min": float(ratios.min()),
            "ratio_max": float(ratios.max())}


def _markdown_table(table: pd.DataFrame) -> str:
    """``table`` as a Markdown table, numbers to 4 significant digits."""
    def cell(value: object) -> str:
        return f"{value:.4g}" if isinstance(value, float) else str(value)

    lines = ["| " + " | ".join(map(str, table.columns)) + " |",
             "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |"
              for row in table.itertuples(index=False)]
    return "\n".join(lines)


def _markdown(table: pd.DataFrame, extras: pd.DataFrame, labels: list[str]) -> str:
    """The report: the per-mesh table and the start-up and growth cases."""
    lines = [f"Mohr–Coulomb biaxial specimen (issue 62), medians; ratio = total / {labels[0]}'s",
             "", _markdown_table(table), "", _markdown_table(extras), ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict[str, pd.DataFrame] | None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("revs", nargs="*", help="git revisions, or . for this working tree")
    parser.add_argument("--meshes", default="4x8,8x16,16x32",
                        help="meshes NXxNY; the first is also the one of the growth run")
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--growth-steps", type=int, default=200,
                        help="steps of the run whose tables are timed step by step (0: none)")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--no-plain", action="store_true",
                        help="leave out the plain scikit-fem loop of the same specimen")
    parser.add_argument("--worker", nargs=5, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker is not None:
        nx, ny, steps, strain, mode = args.worker
        if mode == "plain":
            print(json.dumps(plain(int(nx), int(ny), int(steps), float(strain))))
        else:
            print(json.dumps(worker(int(nx), int(ny), int(steps), float(strain), mode == "1")))
        return None
    if not args.revs:
        parser.error("give one revision or more (. is this working tree)")
    meshes = [tuple(int(k) for k in m.split("x")) for m in args.meshes.split(",")]
    labels = [_label(rev) for rev in args.revs]
    rows, extras = [], []
    with tempfile.TemporaryDirectory() as scratch:
        sources = []
        for index, rev in enumerate(args.revs):
            base = rev.split("+")[0]
            if base == ".":
                sources.append(REPO)
                continue
            path = Path(scratch) / f"rev{index}"
            subprocess.run(["git", "worktree", "add", "--detach", "-q", str(path), base],
                           cwd=REPO, check=True)
            sources.append(path)
        options = [_options(rev) for rev in args.revs]
        try:
            for nx, ny in meshes:
                runs: list[list[dict]] = [[] for _ in sources]
                for _ in range(args.repeats):  # the revisions take turns
                    for index, source in enumerate(sources):
                        runs[index].append(_run(source, str(nx), str(ny), str(args.steps),
                                                "0.05", "0", options=options[index])[0])
                rows += [_row(rev, label, nx, ny, args.steps, result, runs[0])
                         for rev, label, result in zip(args.revs, labels, runs, strict=True)]
                if not args.no_plain:  # this tree's material in a plain scikit-fem loop
                    loops = [_run(REPO, str(nx), str(ny), str(args.steps), "0.05", "plain")[0]
                             for _ in range(args.repeats)]
                    rows.append(_plain_row(nx, ny, args.steps, loops, runs[0]))
                print(f"{nx}x{ny} done", file=sys.stderr, flush=True)
            walls: list[list[float]] = [[] for _ in sources]
            for _ in range(args.repeats):
                for index, source in enumerate(sources):
                    walls[index].append(_run(source, "1", "2", "1", "0.001", "0",
                                             options=options[index])[1])
            growth = []
            if args.growth_steps:
                nx, ny = meshes[0]
                growth = [[] for _ in sources]
                for _ in range(args.repeats):  # the revisions take turns here too
                    for index, source in enumerate(sources):
                        growth[index].append(_growth_ratio(_run(
                            source, str(nx), str(ny), str(args.growth_steps), "0.05",
                            "1", options=options[index])[0]["tables_per_step"]))
            for index, (rev, label) in enumerate(zip(args.revs, labels, strict=True)):
                extra = {"rev": rev, "commit": label,
                         "wall_1x2_one_step_s": float(np.median(walls[index])),
                         "wall_ratio": float(np.median(np.array(walls[index])
                                                       / np.array(walls[0])))}
                if growth:
                    start, end, ratio = np.median(np.array(growth[index]), axis=0)
                    extra.update({"growth_mesh": f"{meshes[0][0]}x{meshes[0][1]}",
                                  "growth_steps": args.growth_steps,
                                  "tables_s_per_step_at_5": float(start),
                                  "tables_s_per_step_at_end": float(end),
                                  "tables_end_over_5": float(ratio)})
                extras.append(extra)
        finally:
            for rev, source in zip(args.revs, sources, strict=True):
                if rev.split("+")[0] != ".":
                    subprocess.run(["git", "worktree", "remove", "--force", str(source)],
                                   cwd=REPO, check=False)
    table, extra_table = pd.DataFrame(rows), pd.DataFrame(extras)
    report = _markdown(table, extra_table, labels)
    print(report)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        table.to_csv(args.out / "continuum_speed.csv", index=False)
        extra_table.to_csv(args.out / "continuum_speed_extras.csv", index=False)
        (args.out / "continuum_speed.md").write_text(report)
    return {"meshes": table, "extras": extra_table}


if __name__ == "__main__":
    main()
