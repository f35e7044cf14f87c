"""Our engine's side of the cross-runs: its DEM in this process, its FEM through the CLI.

The DEM runs (:func:`ours_prepare`, :func:`ours_biaxial`, :func:`ours_drive`) call in this
process the library functions that the commands ``prepare``, ``biaxial-dem`` and
``dem-drive`` call (``prepare_packing`` and ``save_rve``; ``DEMBatch`` of ``load_rve`` and
``biaxial_test``; ``drive_grad_u`` on ``path_increment``), with the commands' default
options, and write the same RVE file or CSV table as the command, bit for bit; each returns
the summary the command prints with ``--json``. Where the command would exit non-zero (bad
input, a blow-up, a servo that lost σxx) :class:`EngineError` is raised instead, after
writing what the command keeps. Their ``wall_s`` [s] and ``cpu_s`` [s]
(``time.process_time``: this process, all its threads) measure the call alone: the
interpreter's start-up and the imports are not in them, while the first DEM call of a
process does include warp's initialisation and its kernels' loading. YADE's ``wall_s``
(:mod:`granular_material_validation.yade_runner`) is its whole process, its own start-up
included; its ``run_s`` is its stepping alone. :func:`ours_tangents` applies a ∇u path in
this process too, the way ``dem-drive`` does, and reads the tangents on the way.

The FEM × DEM runs (:func:`ours_single_element`, :func:`ours_femxdem_biaxial`) are run
specifications run in this process (:func:`granular_material.runs.run`, what the
``single-element`` and ``biaxial`` commands call); their ``wall_s`` and ``cpu_s`` are the
call's, as the DEM runs'.
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Iterator
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from granular_material.procedures.element_tests import DEFAULT_AXIAL_STRAIN
from granular_material.procedures.packing import DEFAULT_DISCS, DEFAULT_PRESSURE
from granular_material.procedures.strain_path import DEFAULT_MAX_DEM_STEPS, DEFAULT_STRAIN_PER_STEP
from granular_material.results.writers import read_points

__all__ = [
    "EngineError",
    "engine_available",
    "ours_biaxial",
    "ours_drive",
    "ours_femxdem_biaxial",
    "ours_prepare",
    "ours_single_element",
    "ours_tangents",
    "voigt_tangent",
]



class EngineError(RuntimeError):
    """Our engine's run failed: a command (the tail of its stderr in the message) failed or
    timed out, or an in-process DEM run ended where its command would exit non-zero."""


def engine_available() -> bool:
    """True when the engine's DEM commands are importable (``granular_material.cli.dem``)."""
    try:
        import granular_material.cli.dem  # noqa: F401
    except ImportError:
        return False
    return True


#: the exceptions of an engine call that the command reports with exit code 2 (bad input:
#: ``UsageError``, ``ValueError``, ``OSError``) or 1 (``RuntimeError``, e.g. a blow-up)
_FAILURES = (ValueError, RuntimeError, OSError)


@contextlib.contextmanager
def _engine_call(command: str, timing: dict[str, float]) -> Iterator[None]:
    """Time the block (``wall_s``, ``cpu_s`` into ``timing``); the failures the command would
    end on (:data:`_FAILURES`) are raised as :class:`EngineError` naming ``command``."""
    cpu0 = time.process_time()
    start = time.perf_counter()
    try:
        yield
    except _FAILURES as exc:
        raise EngineError(f"granular-material {command} (in process) failed: "
                          f"{type(exc).__name__}: {exc}") from exc
    finally:
        timing["wall_s"] = time.perf_counter() - start
        timing["cpu_s"] = time.process_time() - cpu0


def _summary(report: dict[str, Any], timing: dict[str, float], command: str
             ) -> dict[str, Any]:
    """``report`` as the command's ``--json`` prints it (read back through JSON, ``error``
    set), ``cpu_s`` and ``wall_s`` added; :class:`EngineError` when it has an ``error``."""
    error = report.pop("error", None)
    result = json.loads(json.dumps({**report, "error": error}, default=str))
    if error is not None:
        raise EngineError(f"granular-material {command} (in process) failed: {error}")
    result["cpu_s"] = timing["cpu_s"]
    result["wall_s"] = timing["wall_s"]
    return result


def _rve_zero(csv: str | Path) -> pd.DataFrame:
    """The rows of RVE 0 of a CSV the command wrote, as read back from the file."""
    frame = pd.read_csv(csv)
    if "rve" in frame.columns:
        frame = frame[frame["rve"] == 0].reset_index(drop=True)
    return frame


def ours_prepare(out: str | Path, particles: int = DEFAULT_DISCS, seed: int = 1,
                 pressure: float = DEFAULT_PRESSURE, device: str | None = None,
                 ) -> dict[str, Any]:
    """``granular-material prepare`` in this process: one RVE of ``particles`` discs, the
    command's default material and radii, consolidated to ``pressure`` [Pa], written to
    ``out``; the command's JSON summary plus ``wall_s`` and ``cpu_s`` [s] of the call.
    """
    from types import SimpleNamespace

    from granular_material.checks import RVE_MATERIAL_DEFAULTS, packing_parameters
    from granular_material.dem import save_rve
    from granular_material.procedures import prepare_packing

    out = Path(out)
    timing: dict[str, float] = {}
    with _engine_call("prepare", timing):
        # the options of add_rve_material_options at their defaults, made into the
        # packing's parameters (and checked) as the command does
        options = SimpleNamespace(**RVE_MATERIAL_DEFAULTS, seed=int(seed))
        packing = packing_parameters(options, int(particles), float(pressure))
        batch = prepare_packing(
            n_disc=int(particles), n_rve=1, seed=int(seed), pressure=float(pressure),
            meta=packing.meta, target_void_ratio=packing.target_void_ratio,
            radius_range=packing.radius_range, device=device, dtype="float64",
            progress=False)
        h = batch.homogenize()
        out.parent.mkdir(parents=True, exist_ok=True)
        save_rve(out, batch.to_data())
    report: dict[str, Any] = {**batch.summary(h),
                              "warnings": [],  # only --target-void-ratio warns, not set here
                              "out": str(out)}
    return _summary(report, timing, "prepare")


def ours_biaxial(rve: str | Path, out_csv: str | Path,
                 axial_strain: float = DEFAULT_AXIAL_STRAIN,
                 confining: float = DEFAULT_PRESSURE,
                 strain_per_step: float = DEFAULT_STRAIN_PER_STEP,
                 record_every: int = 10, device: str | None = None,
                 ) -> tuple[pd.DataFrame, dict[str, Any]]:
    """``granular-material biaxial-dem`` in this process: ``biaxial_test`` of every RVE of
    the file, the curve written to ``out_csv``; returns the rows of RVE 0 read back from it
    and the command's JSON summary plus ``wall_s`` and ``cpu_s`` [s] of the call.

    :class:`EngineError` (the CSV written) where the command exits 1: the servo did not
    hold σxx (off by more than ``SERVO_FAIL`` in most records).
    """
    from granular_material.cli.dem import SERVO_FAIL, SERVO_WARN
    from granular_material.cli.options import scalar_or_list
    from granular_material.dem import DEMBatch, load_rve
    from granular_material.procedures import biaxial_test
    from granular_material.procedures.element_tests import lateral_stress_error
    from granular_material.results import summarize_biaxial, write_csv

    confining = float(confining)
    out_csv = Path(out_csv)
    timing: dict[str, float] = {}
    with _engine_call("biaxial-dem", timing):
        batch = DEMBatch(load_rve(rve), device=device, dtype="float64")
        curve = biaxial_test(batch, axial_strain=float(axial_strain), confining=confining,
                             strain_per_step=float(strain_per_step),
                             record_every=int(record_every), progress=False,
                             max_steps=DEFAULT_MAX_DEM_STEPS)
        out_csv.parent.mkdir(parents=True, exist_ok=True)
        write_csv(curve, out_csv)
    summaries = [summarize_biaxial(g) for _, g in curve.groupby("rve")]
    keys = ("peak_stress_ratio", "axial_strain_at_peak", "max_contraction", "final_void_ratio")
    report: dict[str, Any] = {key: scalar_or_list(np.array([getattr(s, key) for s in summaries]))
                              for key in keys}
    held = lateral_stress_error(curve, confining)
    report |= {"steps": int(curve["step"].max()),
               "final_sxx": scalar_or_list(held["final_sxx"].to_numpy()),
               "max_confining_error": scalar_or_list(held["max_error"].to_numpy())}
    warnings: list[str] = []
    lost = np.flatnonzero(held["median_error"].to_numpy() > SERVO_FAIL)
    loose = np.flatnonzero(held["max_error"].to_numpy() > SERVO_WARN)
    if lost.size:
        report["error"] = (f"the servo did not hold σxx at −{confining:g} Pa, off by more than "
                           f"{SERVO_FAIL:.0%} in most records of RVE(s) {lost.tolist()}")
    elif loose.size:
        warnings.append(f"σxx strayed from −{confining:g} Pa by more than {SERVO_WARN:.0%} in "
                        f"some records of RVE(s) {loose.tolist()}")
    report["warnings"] = warnings
    report["out"] = str(out_csv)
    result = _summary(report, timing, "biaxial-dem")
    return _rve_zero(out_csv), result


def ours_drive(rve: str | Path, out_csv: str | Path, grad_u: list[float], increments: int,
               device: str | None = None) -> tuple[pd.DataFrame, dict[str, Any]]:
    """``granular-material dem-drive`` in this process: the total ∇u ``grad_u`` = [Gxx,
    Gxy, Gyx, Gyy] in ``increments`` equal increments (``drive_grad_u`` on
    ``path_increment``, at most 1e-5 strain a DEM step) on every RVE of the file, the path
    written to ``out_csv``; returns the rows of RVE 0 read back from it and the command's
    JSON summary plus ``wall_s`` and ``cpu_s`` [s] of the call.

    :class:`EngineError` where the command refuses the path or exits 1 (a blow-up: the path
    to the last finished increment is written first).
    """
    from granular_material.dem import DEMBatch, load_rve
    from granular_material.procedures import drive_path, plan_path
    from granular_material.results import write_csv

    if len(grad_u) != 4 or increments < 1:
        raise ValueError(f"grad_u needs 4 numbers and increments >= 1, got {grad_u}, "
                         f"{increments}")
    grad = np.array([float(g) for g in grad_u]).reshape(2, 2)
    n = int(increments)
    max_strain_per_step = DEFAULT_STRAIN_PER_STEP  # dem-drive's --max-strain-per-step
    cap = DEFAULT_MAX_DEM_STEPS
    out_csv = Path(out_csv)
    timing: dict[str, float] = {}
    with _engine_call("dem-drive", timing):
        # dem-drive's checks of the whole path (--max-dem-steps among them), before any work
        plan_path(grad, n, max_strain_per_step, cap)
        batch = DEMBatch(load_rve(rve), device=device, dtype="float64")
        path = drive_path(batch, grad, n, max_strain_per_step=max_strain_per_step,
                          max_steps=cap)
        if path.interrupt is not None:
            raise path.interrupt
        out_csv.parent.mkdir(parents=True, exist_ok=True)
        write_csv(path.table, out_csv)
    report: dict[str, Any] = {**path.summary(), "warnings": [], "out": str(out_csv)}
    error = path.failure_message(n)
    if error is not None:
        report["error"] = error
    finished = path.finished
    report["increments_completed"] = finished
    result = _summary(report, timing, "dem-drive")
    return _rve_zero(out_csv), result


def _resolved(flat: dict[str, Any]) -> dict[str, Any]:
    """The run the flat spec fields ``flat`` make today: every field of the spec with its
    default filled in and the Newton settings the DEM material gets, so that a cached run
    made under other defaults is not taken for it."""
    from granular_material.runs import from_flat
    from granular_material.runs.serial import to_flat

    spec = from_flat({"material": "dem", **flat})
    settings = json.loads(json.dumps(asdict(spec.newton.settings(noisy=True)), default=str))
    return {**to_flat(spec), "newton_settings": settings}


def _fem_run(flat: dict[str, Any]) -> dict[str, Any]:
    """The FEM × DEM run of the flat spec fields ``flat`` in this process
    (:func:`granular_material.runs.run`); its summary as ``--json`` prints it, plus
    ``wall_s`` and ``cpu_s`` [s] of the call. A Newton failure raises :class:`EngineError`."""
    from granular_material.runs import from_flat, run

    spec = from_flat({"material": "dem", **flat})
    cpu0, start = time.process_time(), time.perf_counter()
    outcome = run(spec)
    result = json.loads(json.dumps(outcome.summary, default=str))
    result.update(wall_s=time.perf_counter() - start, cpu_s=time.process_time() - cpu0)
    if outcome.interrupt is not None:
        raise outcome.interrupt
    if result.get("error"):
        raise EngineError(f"granular-material {spec.problem.test} failed: {result['error']}")
    return result


def ours_single_element(rve: str | Path, out_dir: str | Path,
                        axial_strain: float = DEFAULT_AXIAL_STRAIN,
                        confining: float = DEFAULT_PRESSURE, steps: int = 100,
                        device: str | None = None,
                        ) -> tuple[pd.DataFrame, dict[str, Any]]:
    """The ``single-element`` run of the DEM material on the RVE file (FEM × DEM).

    One Q4 element, its four Gauss points each holding a copy of the RVE, loaded like the
    drained biaxial test: sides under ``confining`` [Pa] (compression positive), the top
    compressed to ``axial_strain`` (compression positive) in ``steps`` Newton load steps.
    Returns ``DIR/steps.csv`` (step 0 included: ``axial_strain``, ``sxx``, ``syy``, ``sxy``
    [Pa] tension positive, volume averages over the Gauss points, ``volumetric_strain``,
    ``void_ratio``, Newton ``iterations`` ...) and the run's summary plus ``wall_s`` and
    ``cpu_s`` [s] (the call). A Newton failure raises :class:`EngineError`.
    """
    if steps < 1 or not axial_strain > 0:
        raise ValueError(f"steps must be >= 1 and axial_strain > 0, got {steps}, "
                         f"{axial_strain}")
    out_dir = Path(out_dir)
    result = _fem_run({"test": "single-element", "rve": rve, "axial_strain": axial_strain,
                       "confining": confining, "steps": steps, "out": out_dir,
                       "device": device})
    curve = pd.read_csv(out_dir / "steps.csv")
    return curve.drop(columns=["residual_history"], errors="ignore"), result


def ours_femxdem_biaxial(rve: str | Path, out_dir: str | Path,
                         elements: tuple[int, int] = (2, 4), axial_strain: float = 0.03,
                         steps: int = 30, confining: float = DEFAULT_PRESSURE,
                         width: float = 0.05,
                         height: float = 0.1, extra: dict[str, Any] | None = None,
                         device: str | None = None,
                         ) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """The ``biaxial`` run of the DEM material with RVE 0 of ``rve`` at every Gauss point.

    Smooth platens, ``elements`` (nx, ny) on a ``width`` × ``height`` [m] specimen, ``steps``
    equal load steps to ``axial_strain`` (compression positive) at ``confining`` [Pa];
    ``extra``: further run spec fields by their flat names (element, Newton settings; e.g.
    ``{"element": "quad8"}``). Returns ``DIR/steps.csv`` (step 0 included;
    ``platen_stress``, ``stress_ratio``, volume-average ``sxx``, ``syy``, ``sxy`` [Pa] tension
    positive, ``volumetric_strain``, ``void_ratio``, ``iterations``, ``particle_steps``,
    ``wall_time`` [s] ...), ``DIR/points.csv`` (Gauss-point states of every step) and the
    summary plus ``wall_s`` and ``cpu_s`` [s] (the call). A finished run in ``DIR`` of the
    same spec (``DIR/run.json``) is read back.
    """
    if steps < 1 or not axial_strain > 0:
        raise ValueError(f"steps must be >= 1 and axial_strain > 0, got {steps}, "
                         f"{axial_strain}")
    out_dir = Path(out_dir)
    flat = {"test": "biaxial", "rve": str(rve), "elements": [int(n) for n in elements],
            "width": float(width), "height": float(height), "platens": "smooth",
            "axial_strain": float(axial_strain), "steps": int(steps),
            "confining": float(confining), "out": str(out_dir), "device": device,
            **(extra or {})}
    done = out_dir / "run.json"
    cached = json.loads(done.read_text()) if done.is_file() else {}
    key = _resolved(flat)
    if cached.get("spec") == key:
        result = cached["result"]
    else:
        result = _fem_run(flat)
        done.write_text(json.dumps({"spec": key, "result": result}, indent=1))
    curve = pd.read_csv(out_dir / "steps.csv").drop(columns=["residual_history"],
                                                    errors="ignore")
    return curve, read_points(out_dir), result


def voigt_tangent(tangent: np.ndarray) -> np.ndarray:
    """Symmetrised Voigt (xx, yy, xy) matrix (3, 3) [Pa] of a 4th-order tangent (2, 2, 2, 2)."""
    tangent = np.asarray(tangent, dtype=np.float64)
    if tangent.shape != (2, 2, 2, 2):
        raise ValueError(f"tangent must have shape (2, 2, 2, 2), got {tangent.shape}")
    sym = 0.25 * (tangent + tangent.transpose(1, 0, 2, 3) + tangent.transpose(0, 1, 3, 2)
                  + tangent.transpose(1, 0, 3, 2))
    idx = ((0, 0), (1, 1), (0, 1))
    return np.array([[sym[i, j, k, m] for (k, m) in idx] for (i, j) in idx])


def ours_tangents(rve: str | Path, grad_u: list[float], increments: int, at: list[int],
                  device: str | None = "cpu") -> dict[int, np.ndarray]:
    """Voigt tangents (3, 3) [Pa] of our engine after the increments ``at`` of a ∇u path.

    Runs in this process through the engine's API (``DEMBatch`` and ``drive_grad_u``), the
    way ``dem-drive`` applies the increments; the homogenised tangent is Kruyt–Rothenburg's.
    """
    from granular_material.dem.batch import DEMBatch
    from granular_material.dem.rve.file import load_rve
    from granular_material.procedures import drive_grad_u, path_increment

    data = load_rve(rve).select(0)
    batch = DEMBatch(data, device=device)
    grad = np.asarray(grad_u, dtype=np.float64).reshape(2, 2)
    wanted = sorted(set(int(k) for k in at))
    if any(k < 0 or k > increments for k in wanted):
        raise ValueError(f"tangent increments must lie in [0, {increments}], got {wanted}")
    out: dict[int, np.ndarray] = {}
    if 0 in wanted:
        out[0] = voigt_tangent(batch.homogenize().tangent[0])
    for k in range(1, (wanted[-1] if wanted else 0) + 1):
        drive_grad_u(batch, path_increment(grad, k, increments))
        if k in wanted:
            out[k] = voigt_tangent(batch.homogenize().tangent[0])
    return out
