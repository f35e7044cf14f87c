"""The FEM commands: ``single-element`` and ``biaxial``."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import re
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from granular_material.cli.options import (
    DISC_BYTES,
    RVE_MATERIAL_DEFAULTS,
    UsageError,
    add_convergence,
    add_device,
    add_element,
    add_json,
    add_out,
    add_progress,
    add_rve_material_options,
    check_memory,
    check_output_dir,
    cleanup_on_rejection,
    emit,
    interrupt_exit_code,
    packing_parameters,
    positive,
    positive_int,
    progress_enabled,
    rve_file_shape,
    rve_material_given,
)
from granular_material.fem import (
    DEM_REUSE_TOL,
    BiaxialResult,
    BiaxialSetup,
    CheckpointError,
    Material,
    NewtonSettings,
    RunCheckpoint,
    Tracking,
    available_postprocessors,
    create_material,
    default_settings,
    default_stress_tol,
    load_material,
    run_biaxial,
)
from granular_material.fem.kinematics import FORMULATIONS
from granular_material.fem.presets import load_presets
from granular_material.results import (
    BiaxialWriter,
    band_summary,
    find_peak,
    run_summary,
    write_csv,
    write_json,
    write_outputs,
)
from granular_material.results.lock import FolderLock

if TYPE_CHECKING:
    from granular_material.procedures.packing import PackingParameters

__all__ = ["register", "run_biaxial_command", "run_single_element"]

#: the Newton settings of the commands (fem.default_settings), shown as the option defaults
_NEWTON = default_settings("dem")
#: the RVEs' tangents the commands offer, and their default
TANGENTS = ("objective", "kruyt-rothenburg", "perturbation", "condensed")
DEFAULT_TANGENT = "objective"
#: the DEM material's default strain per DEM step [-]
DEFAULT_STRAIN_PER_STEP = 1e-5
#: single-element's default discs per prepared RVE
DEFAULT_PARTICLES = 400

#: reduced CPU scale of the biaxial specimen: elements (nx, ny) and discs per RVE; 5 × 10 is
#: the coarsest mesh on which a band showed (50 steps to 10 %: about 23 min on 2 CPU cores)
REDUCED_SCALE = ((5, 10), 64)
#: full scale (Wu et al. 2025): 10 × 15 Q4 elements, 600 Gauss points, 400-disc RVEs
FULL_SCALE = ((10, 15), 400)


def _newton_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("Newton solver")
    g.add_argument("--rtol", type=float, default=_NEWTON.rtol,
                   help="relative tolerance of the --convergence test: ||du||/||Du|| "
                        f"(default {_NEWTON.rtol:g}, Guo & Zhao) or ||R||/||R0|| (Wu et al. "
                        "use 0.005)")
    g.add_argument("--stress-tol", type=float, default=None,
                   help="absolute tolerance as a stress error [Pa] at the Gauss points, for "
                        "DEM noise (default 0.005 x confining for dem, 0 for linear-elastic)")
    g.add_argument("--stall-rtol", type=float, default=None,
                   help="accept an iterate with ||R||/||R0|| below this once the residual has "
                        "stopped falling for 8 iterations (DEM stress noise; default 2 x rtol "
                        "for dem, off for linear-elastic; 0: off)")
    g.add_argument("--max-iterations", type=int, default=_NEWTON.max_iterations,
                   help="iterations per increment before it is halved "
                        f"(default {_NEWTON.max_iterations})")
    g.add_argument("--max-cutbacks", type=int, default=_NEWTON.max_cutbacks,
                   help=f"how often an increment may be halved (default {_NEWTON.max_cutbacks})")
    add_convergence(g, _NEWTON.convergence, _NEWTON.rtol)
    g.add_argument("--predictor", choices=("tangent", "extrapolate"), default=_NEWTON.predictor,
                   help="first guess of a step: committed-tangent solve or the last increment "
                        f"scaled (default {_NEWTON.predictor})")
    g.add_argument("--formulation", choices=FORMULATIONS, default=_NEWTON.formulation,
                   help="kinematics: updated-lagrangian (finite strain as Guo & Zhao: "
                        "equilibrium on the current configuration, RVEs driven by grad du on "
                        "the committed one, the confining pressure on the current sides; "
                        f"default {_NEWTON.formulation}) or small-strain")
    g.add_argument("--accept-correction", type=float, default=None, metavar="RATIO",
                   help="accept an increment whose residual has stalled once the Newton "
                        "correction ||du||/||Du|| is at most this (Guo & Zhao's test; default "
                        "1e-2 for dem, off for linear-elastic; 0: off)")
    g.add_argument("--tangent", choices=TANGENTS, default=DEFAULT_TANGENT,
                   help="dem: tangent of the RVEs: objective (Kruyt-Rothenburg on sym grad u "
                        "plus the stress's spin, symmetric: a rigid rotation costs nothing; "
                        "default), kruyt-rothenburg (Wu et al. eq. 6 as published), forward "
                        "differences of each RVE's response (perturbation: 4 more DEM runs per "
                        "iteration) or condensed (the contact network's stiffness with the "
                        "discs' fluctuations condensed out, plus the stress's spin; no DEM run)")
    g.add_argument("--perturbation", type=float, default=0.1,
                   help="dem, --tangent perturbation: perturbation of grad u relative to its "
                        "largest component (default 0.1)")
    g.add_argument("--relaxation", choices=("none", "aitken"), default=_NEWTON.relaxation,
                   help=f"relaxation of Newton corrections (default {_NEWTON.relaxation}: the "
                        "DEM tangent leaves out the discs' rearrangement and is too stiff)")
    g.add_argument("--tangent-update", choices=("none", "secant"),
                   default=_NEWTON.tangent_update,
                   help=f"none: the material's tangent at every iterate (default "
                        f"{_NEWTON.tangent_update}); secant: "
                        "each point's tangent corrected by Broyden updates from the stress "
                        "change its RVE gave (use with --relaxation none)")
    g.add_argument("--secant-min-change", type=float, default=_NEWTON.secant_min_change,
                   help="--tangent-update secant: smallest change of a point's grad u that "
                        f"updates its tangent (default {_NEWTON.secant_min_change:g}; smaller "
                        "changes carry DEM noise)")


def _dem_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("DEM material: what is stepped, and what is post-processed")
    g.add_argument("--reuse-tol", type=float, default=DEM_REUSE_TOL,
                   help="a Gauss point whose grad u moved by at most this strain (every "
                        "component) since its RVE was last driven keeps that response instead "
                        f"of being stepped; 0: every RVE every iteration (default "
                        f"{DEM_REUSE_TOL:g})")
    g.add_argument("--reuse-correction", choices=("none", "tangent"), default="none",
                   help="a reused response as it is (none, default) or corrected to first "
                        "order by its tangent")
    g.add_argument("--drive", choices=("restart", "continue"), default="restart",
                   help="restart: each iteration drives an RVE from its committed state along "
                        "the whole step (Guo & Zhao, default); continue: from its last trial "
                        "state by the change of grad u (fewer DEM steps, path-dependent)")
    g.add_argument("--max-strain-per-step", type=positive, default=DEFAULT_STRAIN_PER_STEP,
                   metavar="STRAIN",
                   help="largest strain of one DEM step while an RVE is driven along grad u "
                        "(the quasi-static criterion; see the trade study; default 1e-5)")
    g.add_argument("--max-dem-steps", type=int, default=10**6,
                   help="cap on the DEM steps of one RVE's path in one Newton iteration: an "
                        "iterate that needs more is an error naming the point (default 1e6, "
                        "a strain of 10 at 1e-5 a step)")
    g.add_argument("--track", nargs="+", default=None, metavar="POINT",
                   help="Gauss point ids (or 'all') whose RVEs the post-processors analyse; "
                        "results in tracked.csv")
    g.add_argument("--every", type=int, default=1,
                   help="with --track: every this many load steps, step 0 included (default 1)")
    g.add_argument("--postprocess", nargs="+", default=["pore-fractal"], metavar="NAME",
                   help="with --track: post-processors to run (installed: "
                        f"{', '.join(available_postprocessors()) or 'none'}; default "
                        "pore-fractal)")


def _rve_material_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group(
        "RVE material", "dem: the material of the RVEs the run prepares, each consolidated to "
        "--confining: the options of `granular-material prepare` (not with --rve, whose file "
        "carries its own; refused there)")
    add_rve_material_options(g)


def _packing(args: argparse.Namespace, particles: int) -> PackingParameters | None:
    """The material and packing of the RVEs the run prepares, checked before any work as
    ``prepare`` checks them (their pressure is --confining); None where it prepares none
    (an --rve file, or --material linear-elastic), and then no RVE material option may be
    given (UsageError naming it)."""
    material = getattr(args, "material", "dem")
    if args.rve is None and material == "dem":
        return packing_parameters(args, particles, args.confining, "--confining")
    given = rve_material_given(args)
    if given:
        why = (f"--rve {args.rve} carries its own (give them to `granular-material prepare` "
               "instead)" if material == "dem" else f"--material {material} has no RVEs")
        raise UsageError(f"{', '.join(given)} set{'s' if len(given) == 1 else ''} the "
                         f"material of the RVEs a run prepares, but {why}")
    return None


def _rve_material(args: argparse.Namespace, packing: PackingParameters | None,
                  ) -> dict[str, Any] | None:
    """The material of the run's RVEs for its summary: the prepared ones' (``packing``) or
    the ``--rve`` file's (its meta, its radii); None without RVEs. SI units, angles in rad."""
    if getattr(args, "material", "dem") != "dem":
        return None
    if packing is None:
        from granular_material.dem import load_rve

        data = load_rve(args.rve)
        meta, source, target = data.meta, str(args.rve), None
        radii = (float(data.radius.min()), float(data.radius.max()))
    else:
        meta, source, target = packing.meta, "prepared", packing.target_void_ratio
        radii = packing.radius_range
    return {"source": source, "radius_min": radii[0], "radius_max": radii[1],
            "target_void_ratio": target, "stiffness": dict(meta.stiffness),
            "friction_angle": meta.friction_angle, "damping": meta.damping,
            "density": meta.density, "thickness": meta.thickness}


def _dem_parameters(args: argparse.Namespace) -> dict[str, Any]:
    """The DEM material's keywords of the reuse and stepping options."""
    return {"reuse_tol": args.reuse_tol, "reuse_correction": args.reuse_correction,
            "drive": args.drive, "max_dem_steps": args.max_dem_steps,
            "max_strain_per_step": args.max_strain_per_step}


def _tracking(args: argparse.Namespace, n_points: int) -> Tracking | None:
    """The ``--track`` request, checked against the mesh's ``n_points`` before any work."""
    if args.track is None:
        return None
    if getattr(args, "material", "dem") != "dem":
        raise ValueError("--track needs --material dem (its Gauss points carry RVEs)")
    tracking = Tracking.parse(args.postprocess, args.track, args.every)
    tracking.check_points(n_points)
    return tracking


def _common_arguments(parser: argparse.ArgumentParser) -> None:
    add_element(parser)
    parser.add_argument("--axial-strain", type=float, default=0.1,
                        help="final axial strain, compression positive (default 0.1)")
    parser.add_argument("--confining", type=float, default=100e3,
                        help="lateral confining pressure [Pa], compression positive; also "
                             "the consolidation pressure of the RVEs a dem run prepares "
                             "(default 100e3)")
    parser.add_argument("--steps", type=int, default=100, help="load steps (default 100)")
    add_out(parser, "output folder: steps.csv, points.csv, fields.xdmf, summary.json, figures")
    add_json(parser, "a summary")
    add_device(parser, "DEM device")
    parser.add_argument("--shards", type=int, default=None,
                        help="CPU threads (shards) of the DEM batch, per rank with --backend "
                             "mpi (default: one per core, shared by a node's ranks)")
    parser.add_argument("--backend", choices=("inprocess", "mpi"), default="inprocess",
                        help="dem: where the RVEs live: this process (default) or shards on "
                             "the ranks of an MPI job (launch with mpiexec -n K; rank 0 runs "
                             "the FEM and alone writes and prints; the same results)")
    parser.add_argument("--map-strain", type=float, nargs="+", default=[0.02],
                        help="axial strain(s) of the displacement/shear-strain maps and of the "
                             "shear-band measures (default 0.02)")
    parser.add_argument("--preset", choices=tuple(load_presets()), default=None,
                        help="settings the trade study recommends (docs/trade-study): discs "
                             "per RVE, strain per DEM step, Newton stress floor, tangent, "
                             "predictor and relaxation, reuse; an option given beside it (not "
                             "at its default) wins")
    g = parser.add_argument_group("checkpoints (with --out)")
    g.add_argument("--checkpoint-every", type=positive_int, default=1, metavar="N",
                   help="save the committed state (RVEs with contact history, displacement, "
                        "Newton state) in OUT/checkpoint after every N load steps and after "
                        "the last (default 1); the tables of every step are kept regardless")
    g.add_argument("--resume", type=Path, default=None, metavar="DIR",
                   help="continue the stopped or killed run whose --out was DIR, in DIR, "
                        "from its last checkpoint (give the other options as then); the "
                        "result is the one of a run that never stopped")
    add_progress(parser)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``single-element`` and ``biaxial`` commands."""
    p = subparsers.add_parser(
        "single-element",
        help="one element (Q4, 4 Gauss points, unless --element) in a drained biaxial test",
        description="One element (Q4 with 2x2 Gauss points unless --element/--quadrature "
                    "say otherwise): sides under the confining "
                    "traction, bottom on rollers with one node pinned, top compressed by a "
                    "prescribed displacement; dem: an --rve file, or RVEs prepared at "
                    "--confining of the RVE material options. Stresses tension positive in "
                    "tables; plots compression positive.",
    )
    p.add_argument("--material", choices=("dem", "linear-elastic"), default="dem",
                   help="material at the Gauss points (default dem)")
    p.add_argument("--E", type=float, default=60e6, help="linear-elastic: Young's modulus [Pa]")
    p.add_argument("--nu", type=float, default=0.3, help="linear-elastic: Poisson's ratio")
    p.add_argument("--rve", type=Path, default=None,
                   help="dem: RVE file (one RVE, replicated to the 4 points, or four)")
    p.add_argument("--particles", type=int, default=DEFAULT_PARTICLES,
                   help=f"dem: discs per prepared RVE (default {DEFAULT_PARTICLES})")
    p.add_argument("--seed", type=int, default=1, help="dem: seed of the prepared RVE")
    p.add_argument("--independent", action="store_true",
                   help="dem: four independent RVEs (seeds seed..seed+3) instead of one "
                        "replicated")
    p.add_argument("--compare-dem", action="store_true",
                   help="dem: also run the pure-DEM drained biaxial of the same RVE")
    _common_arguments(p)
    _newton_arguments(p)
    _dem_arguments(p)
    _rve_material_arguments(p)
    p.set_defaults(func=run_single_element)

    b = subparsers.add_parser(
        "biaxial",
        help="biaxial specimen (50 mm x 100 mm) of DEM Gauss points",
        description="Drained biaxial test of a plane-strain specimen (smooth or rough "
                    "platens), one independently prepared DEM RVE per Gauss point (seed, "
                    "seed+1, ...; at --confining, of the RVE material options) or an --rve "
                    "file. "
                    "--scale full is Wu et al.'s 10x15 elements with 400-disc RVEs; "
                    "--scale reduced (5x10 elements, 64 discs) runs on a CPU.",
    )
    b.add_argument("--scale", choices=("full", "reduced"), default=None,
                   help="preset mesh and RVE size (default: full on CUDA, reduced on CPU)")
    b.add_argument("--elements", type=int, nargs=2, metavar=("NX", "NY"), default=None,
                   help="elements across the width and along the height (overrides --scale)")
    b.add_argument("--particles", type=int, default=None,
                   help="discs per RVE (overrides --scale)")
    b.add_argument("--seed", type=int, default=1, help="seed of the first RVE")
    b.add_argument("--rve", type=Path, default=None,
                   help="RVE file with one RVE per Gauss point (or one, replicated)")
    b.add_argument("--width", type=float, default=0.05, help="specimen width [m]")
    b.add_argument("--height", type=float, default=0.10, help="specimen height [m]")
    b.add_argument("--platens", choices=("smooth", "rough"), default="smooth",
                   help="smooth: platen nodes slide freely, one bottom node pinned (default); "
                        "rough: no platen node moves sideways")
    _common_arguments(b)
    _newton_arguments(b)
    _dem_arguments(b)
    _rve_material_arguments(b)
    b.set_defaults(func=run_biaxial_command)


def _settings(args: argparse.Namespace, material: str) -> NewtonSettings:
    return default_settings(material, rtol=args.rtol, stall_rtol=args.stall_rtol,
                            max_iterations=args.max_iterations, max_cutbacks=args.max_cutbacks,
                            predictor=args.predictor, relaxation=args.relaxation,
                            tangent_update=args.tangent_update,
                            secant_min_change=args.secant_min_change,
                            convergence=args.convergence, formulation=args.formulation,
                            accept_correction=args.accept_correction)


def _stress_tol(args: argparse.Namespace, material: str) -> float:
    if args.stress_tol is not None:
        return args.stress_tol
    return default_stress_tol(material, args.confining)


#: options that may differ between a run and its resume: where it writes, how it reports, how
#: often it saves, the CPU threads and the backend (neither sharding nor MPI ranks change a
#: result)
_RESUME_FREE = frozenset({"resume", "out", "progress", "json", "checkpoint_every", "shards",
                          "backend", "func", "command"})


#: options added after checkpoints were first written, with the value older runs had (the
#: RVE material options: RVE_MATERIAL_DEFAULTS)
_ADDED_OPTIONS = {"element": "quad4", "quadrature": None, "convergence": "force",
                  "formulation": "small-strain", "accept_correction": 0.0}


def _run_options(args: argparse.Namespace) -> dict[str, Any]:
    """The options that decide a run's result, as JSON values (kept in its checkpoint)."""
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in sorted(vars(args).items())
            if k not in _RESUME_FREE}


def _check_resume(args: argparse.Namespace) -> None:
    """``--resume DIR``: the output folder is DIR, and a checkpoint there is of a run with
    the options given now (UsageError naming what differs). DIR with no checkpoint yet (a
    run killed before it saved one, or none started) is allowed: the run starts there."""
    if args.resume is None:
        return
    if args.out is not None and Path(args.out).resolve() != Path(args.resume).resolve():
        raise UsageError(f"--resume {args.resume} continues in that folder; --out {args.out} "
                         "names another (leave --out out)")
    args.out = args.resume
    check_output_dir(args.out, "--resume")
    _lock_out(args.out)
    checkpoint = RunCheckpoint(Path(args.resume) / "checkpoint")
    if not checkpoint.has_options():
        if checkpoint.has_state():
            raise UsageError(f"--resume {args.resume}: {checkpoint.folder / 'options.json'} "
                             "is missing, so the options the run was started with cannot be "
                             "checked; nothing in the folder was changed")
        return
    try:
        saved = checkpoint.read_options()
    except CheckpointError as exc:
        raise UsageError(f"--resume {args.resume}: {exc}; nothing in the folder was "
                         "changed") from None
    given = json.loads(json.dumps(_run_options(args), default=str))
    if saved.get("command") not in (None, args.command):
        raise UsageError(f"--resume {args.resume} is a {saved['command']} run, not "
                         f"{args.command}")
    saved.pop("command", None)
    # a checkpoint of a version without these options ran with their defaults
    for key, default in {**RVE_MATERIAL_DEFAULTS, **_ADDED_OPTIONS}.items():
        saved.setdefault(key, default)
    differ = [f"--{k.replace('_', '-')} {given.get(k)!r} (the run had {saved.get(k)!r})"
              for k in sorted(set(saved) | set(given)) if saved.get(k) != given.get(k)]
    if differ:
        raise UsageError(f"--resume {args.resume}: give the options the run was started with; "
                         f"these differ: {'; '.join(differ)} (nothing in the folder was "
                         "changed)")


#: the output folders this process holds locked while a command runs (:func:`_locked`)
_HELD: dict[Path, FolderLock] = {}


def _lock_out(out: Path | None) -> None:
    """Take the lock of the output folder ``out`` (None: none) before anything is written
    there: a second run or resume into it is refused at once (exit 2, naming the holder's
    pid). Held until the command ends (:func:`_locked`), or the process dies."""
    if out is None or Path(out).resolve() in _HELD:
        return
    lock = FolderLock(out)
    lock.acquire()
    _HELD[Path(out).resolve()] = lock


def _locked(command: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """``command`` that lets go of the output folders it locked when it ends, however."""
    def run(args: argparse.Namespace) -> int:
        try:
            return command(args)
        finally:
            while _HELD:
                _HELD.popitem()[1].release()
    return run


def _open_checkpoint(args: argparse.Namespace) -> tuple[RunCheckpoint | None, bool]:
    """The run's checkpoint (None without --out) and whether it resumes from a saved state
    (else it starts afresh: see :func:`_checkpointed`)."""
    if args.out is None:
        return None, False
    checkpoint = RunCheckpoint(Path(args.out) / "checkpoint", every=args.checkpoint_every)
    if args.resume is not None and checkpoint.has_state():
        try:  # read and checked whole before anything in the folder is touched
            saved = checkpoint.verify()
        except CheckpointError as exc:
            raise UsageError(f"--resume {args.resume}: {exc}; nothing in the folder was "
                             "changed") from None
        if saved.step > args.steps:
            raise UsageError(f"--resume {args.resume}: its checkpoint is of load step "
                             f"{saved.step}, past --steps {args.steps}; nothing in the "
                             "folder was changed")
        return checkpoint, True
    if args.resume is not None:
        print(f"granular-material {args.command}: {args.resume} holds no saved step yet; "
              "the run starts from the beginning", file=sys.stderr)
    return checkpoint, False


@contextlib.contextmanager
def _checkpointed(args: argparse.Namespace, checkpoint: RunCheckpoint | None,
                  resuming: bool) -> Iterator[None]:
    """The block that writes under ``--out``: a fresh run first empties the checkpoint and
    records its options; input rejected in the block (``ValueError``) leaves neither the
    fresh checkpoint nor the folders made for it behind."""
    with cleanup_on_rejection(args.out):
        if checkpoint is None or resuming:
            yield
            return
        checkpoint.start({"command": args.command, **_run_options(args)})
        try:
            yield
        except ValueError:
            checkpoint.remove()
            raise


def _preset_tangent(preset: Any) -> str:
    """The RVE tangent of a preset: its Kruyt–Rothenburg (the affine estimate the trade
    study measured, before the objective form existed) is taken in the objective form."""
    return DEFAULT_TANGENT if preset.tangent == "kruyt-rothenburg" else preset.tangent


def _apply_preset(args: argparse.Namespace) -> None:
    """``--preset NAME``: its values for every option it sets that is at its default."""
    if args.preset is None:
        return
    if getattr(args, "material", "dem") != "dem":
        raise UsageError(f"--preset {args.preset} sets DEM and Newton settings; it needs "
                         "--material dem")
    preset = load_presets()[args.preset]
    predictor, relaxation = preset.acceleration.split("/")
    secant = preset.tangent == "secant"
    values = {  # option: (its default, the preset's value)
        "rtol": (_NEWTON.rtol, preset.rtol),
        # the presets were measured with the force test and 25 iterations an increment
        "convergence": (_NEWTON.convergence, "force"),
        "max_iterations": (_NEWTON.max_iterations, 25),
        "stress_tol": (None, preset.stress_floor * args.confining),
        "tangent": (DEFAULT_TANGENT, DEFAULT_TANGENT if secant else _preset_tangent(preset)),
        "tangent_update": (_NEWTON.tangent_update, "secant" if secant else "none"),
        "predictor": (_NEWTON.predictor, predictor),
        "relaxation": (_NEWTON.relaxation, relaxation),
        "reuse_tol": (DEM_REUSE_TOL, preset.reuse_tol),
        "max_strain_per_step": (DEFAULT_STRAIN_PER_STEP, preset.strain_per_step),
    }
    if args.rve is None:  # the discs of a given file are the file's
        values["particles"] = (DEFAULT_PARTICLES if args.command == "single-element" else None,
                               preset.discs)
    for dest, (default, value) in values.items():
        if getattr(args, dest) == default:
            setattr(args, dest, value)


def _check(args: argparse.Namespace) -> None:
    _apply_preset(args)
    _check_resume(args)
    if args.steps < 1:
        raise ValueError(f"--steps must be >= 1, got {args.steps}")
    if not (math.isfinite(args.confining) and args.confining > 0):
        raise UsageError(f"--confining must be a positive number of Pa (σxx is held at "
                         f"−confining, σ1/σ3 divides by it), got {args.confining:g}")
    check_output_dir(args.out)
    _lock_out(args.out)
    if args.rve is not None and not args.rve.exists():
        raise FileNotFoundError(f"--rve {args.rve} does not exist")
    material = getattr(args, "material", "dem")
    try:  # the Newton settings refused now, not after the RVEs are made
        _settings(args, material)
    except ValueError as exc:  # name the option too: secant_min_change: --secant-min-change
        field = re.match(r"[a-z]+(?:_[a-z]+)*", str(exc))
        option = (f"--{field.group(0).replace('_', '-')}: "
                  if field and hasattr(args, field.group(0)) else "")
        raise UsageError(f"{option}{exc}") from None
    if not (math.isfinite(_stress_tol(args, material)) and _stress_tol(args, material) >= 0):
        raise UsageError(f"--stress-tol must be a stress >= 0 Pa, got {args.stress_tol:g}")
    if getattr(args, "reuse_tol", 0.0) > 0 and args.convergence == "displacement":
        raise UsageError(f"--reuse-tol {args.reuse_tol:g} needs --convergence force (with "
                         "--relaxation aitken, as measured): a reused RVE answers the same "
                         "stress for any change of grad u below the tolerance, so the Newton "
                         "corrections stall above --rtol and no increment passes the "
                         "displacement test")


#: memory of one element of the mesh beside its RVEs, about [bytes]: its stiffness entries
#: in assembly, its Gauss points' tables and tangents, with room for the solver
_ELEMENT_BYTES = 16_384
#: memory of one Gauss point's row of one load step, kept for the tables [bytes]
_POINT_ROW_BYTES = 400


def _check_size(args: argparse.Namespace, setup: BiaxialSetup, particles: int,
                biaxial: bool = False) -> None:
    """Before any work: the mesh, its RVEs (``particles`` discs at each Gauss point; 0
    without) and the tables of every step fit in memory (UsageError with the estimate);
    a biaxial specimen has the 4 Gauss points its shear-band measures need."""
    if biaxial and setup.n_points < 4:
        raise UsageError(f"--element {setup.element} on --elements {setup.nx} {setup.ny} has "
                         f"{setup.n_points} Gauss points; the shear-band measures of a "
                         "biaxial run need at least 4 (more elements)")
    needed = (float(setup.n_elements) * _ELEMENT_BYTES
              + float(setup.n_points) * particles * DISC_BYTES
              + float(setup.n_points) * (args.steps + 1) * _POINT_ROW_BYTES)
    discs = f" of {particles}-disc RVEs" if particles else ""
    check_memory(needed, f"{setup.n_elements} {setup.element} elements ({setup.n_points} "
                         f"Gauss points{discs}) over {args.steps} load steps")


def _replicate(args: argparse.Namespace, n_points: int = 4) -> bool:
    """single-element, dem: whether one RVE is replicated to the ``n_points`` Gauss points
    (else one per point is used: --independent, or those of an --rve file); checked before
    any work."""
    if args.rve is None:
        return not args.independent
    n_rve, _ = rve_file_shape(args.rve)
    if n_rve == n_points:
        return False
    if n_rve != 1:
        raise UsageError(f"--rve {args.rve} holds {n_rve} RVEs; single-element takes 1 "
                         f"(replicated to the {n_points} Gauss points) or {n_points} (one per "
                         "point)")
    if args.independent:
        raise UsageError(f"--independent needs {n_points} RVEs, --rve {args.rve} holds 1")
    return True


def _scale_name(scale: str, elements: tuple[int, int], particles: int) -> str:
    """The preset that ran (``scale``) when mesh and discs are its own, else ``custom``."""
    preset = FULL_SCALE if scale == "full" else REDUCED_SCALE
    return scale if (tuple(elements), particles) == (tuple(preset[0]), preset[1]) else "custom"


def _report(args: argparse.Namespace, summary: dict[str, Any],
            interrupt: KeyboardInterrupt | None = None) -> int:
    """Print the summary and, with ``--out``, write it there as ``summary.json`` too (whole,
    or not at all); the exit code: 0, 1 when the run stopped short, 130/143 when Ctrl-C or
    SIGTERM (``interrupt``) stopped it."""
    if args.out is not None and Path(args.out).is_dir():
        write_json(summary, Path(args.out) / "summary.json")
    emit(args, summary)
    if interrupt is not None:
        print(f"error: {summary['error']}", file=sys.stderr)
        if args.out is not None:
            print(f"continue it with --resume {args.out} and the same options",
                  file=sys.stderr)
        return interrupt_exit_code(interrupt)
    if summary["error"]:
        print(f"error: {summary['error']}", file=sys.stderr)
        return 1
    return 0


def _run(args: argparse.Namespace, setup: BiaxialSetup, material: Material,
         material_name: str, tracking: Tracking | None = None,
         checkpoint: RunCheckpoint | None = None, resuming: bool = False,
         ) -> tuple[BiaxialResult, dict[str, Any]]:
    """The FEM run, written under ``--out`` as it goes (and checkpointed there), resumed
    from its checkpoint when ``resuming``; the result and its summary."""
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        writer = (stack.enter_context(BiaxialWriter(args.out)) if args.out is not None
                  else None)
        result = run_biaxial(setup, material, args.steps, _settings(args, material_name),
                             progress=progress_enabled(args), observer=writer,
                             stress_tol=_stress_tol(args, material_name), tracking=tracking,
                             checkpoint=checkpoint, resume=resuming)
    summary = run_summary(result, time.perf_counter() - t0)
    summary["resumed_from_step"] = result.resumed_from
    summary["preset"] = args.preset
    summary.update(element=setup.element, points_per_element=setup.points_per_element,
                   convergence=args.convergence)
    if tracking is not None:
        summary["tracked_rows"] = len(result.tracked)
        summary["tracking_time_s"] = (float(result.tracked["seconds"].sum())
                                      if len(result.tracked) else 0.0)
    return result, summary


def _on_backend(args: argparse.Namespace,
                command: Callable[[argparse.Namespace], int]) -> int:
    """``command`` as the DEM material's ``--backend`` runs it: here, or with ``mpi`` on
    rank 0 of the job while the other ranks serve its RVE shards (they write and print
    nothing); this process's exit code."""
    if args.backend == "inprocess":
        return command(args)
    return load_material("dem").launch(args.backend, lambda: command(args))


def run_single_element(args: argparse.Namespace) -> int:
    """The ``single-element`` command; returns the exit code."""
    return _on_backend(args, _locked(_single_element))


def _single_element(args: argparse.Namespace) -> int:
    _check(args)
    if args.material != "dem" and args.backend != "inprocess":
        raise UsageError(f"--backend {args.backend} needs --material dem")
    setup = BiaxialSetup(width=1.0, height=1.0, nx=1, ny=1, confining=args.confining,
                         axial_strain=args.axial_strain, element=args.element,
                         gauss=args.quadrature)
    _check_size(args, setup, 0 if args.material != "dem" else
                args.particles if args.rve is None else rve_file_shape(args.rve)[1])
    tracking = _tracking(args, setup.n_points)
    packing = _packing(args, args.particles)
    progress = progress_enabled(args)
    material: Material
    if args.material == "linear-elastic":
        material = create_material("linear-elastic", young=args.E, poisson=args.nu,
                                   initial_stress=-args.confining)
    else:
        material = create_material("dem", rve=args.rve, particles=args.particles,
                                   seed=args.seed, pressure=args.confining,
                                   replicate=_replicate(args, setup.n_points),
                                   device=args.device,
                                   shards=args.shards, progress=progress,
                                   tangent=args.tangent, perturbation=args.perturbation,
                                   backend=args.backend, packing=packing,
                                   **_dem_parameters(args))
    checkpoint, resuming = _open_checkpoint(args)
    with _checkpointed(args, checkpoint, resuming):
        if not resuming:
            material.allocate(setup.n_points)
        reference = None
        if args.material == "dem" and args.compare_dem:
            reference = _reference(material, args, progress, checkpoint)
        result, summary = _run(args, setup, material, args.material, tracking, checkpoint,
                               resuming)
    if reference is not None:
        peak, ratio = find_peak(reference["axial_strain"].to_numpy(),
                                reference["stress_ratio"].to_numpy())
        summary["dem_peak_stress_ratio"] = ratio
        summary["dem_axial_strain_at_peak"] = float(reference["axial_strain"].iloc[peak])
    summary["rve_material"] = _rve_material(args, packing)
    if args.out is not None:
        write_outputs(result, args.out, map_strain=args.map_strain, reference=reference)
        if reference is not None:
            write_csv(reference, Path(args.out) / "pure_dem.csv")
        summary["out"] = str(args.out)
    return _report(args, summary, result.interrupt)


def _reference(material: Any, args: argparse.Namespace, progress: bool,
               checkpoint: RunCheckpoint | None) -> pd.DataFrame:
    """The pure-DEM curve beside the element: computed once, from the RVE before the first
    load step, and kept in the checkpoint (a resumed run reads it back)."""
    saved = None if checkpoint is None else checkpoint.load_table("pure_dem")
    if saved is not None:
        return saved
    curve = _pure_dem(material, args, progress)
    if checkpoint is not None:
        checkpoint.save_table("pure_dem", curve)
    return curve


def _pure_dem(material: Any, args: argparse.Namespace, progress: bool) -> pd.DataFrame:
    """Drained biaxial test of RVE 0 of the DEM ``material`` (a
    :class:`~granular_material_skfem.DEMMaterial`; its committed state)."""
    from granular_material.dem import DEMBatch
    from granular_material.procedures import biaxial_test

    rve0 = material.committed_rves().take([0])
    batch = DEMBatch(rve0, device=args.device, shards=1)
    curve = biaxial_test(batch, axial_strain=args.axial_strain, confining=args.confining,
                         progress=progress)
    return curve[curve["rve"] == 0].reset_index(drop=True)


def run_biaxial_command(args: argparse.Namespace) -> int:
    """The ``biaxial`` command; returns the exit code."""
    return _on_backend(args, _locked(_biaxial))


def _biaxial(args: argparse.Namespace) -> int:
    _check(args)
    from granular_material.dem import resolve_device

    device = resolve_device(args.device)
    scale = args.scale or ("full" if device.startswith("cuda") else "reduced")
    (nx, ny), particles = FULL_SCALE if scale == "full" else REDUCED_SCALE
    if args.elements is not None:
        nx, ny = args.elements
    particles = args.particles or particles
    if args.rve is not None:  # the discs that run are the file's
        particles = rve_file_shape(args.rve)[1]
    setup = BiaxialSetup(width=args.width, height=args.height, nx=nx, ny=ny,
                         confining=args.confining, axial_strain=args.axial_strain,
                         platens=args.platens, element=args.element, gauss=args.quadrature)
    _check_size(args, setup, particles, biaxial=True)
    tracking = _tracking(args, setup.n_points)
    packing = _packing(args, particles)
    progress = progress_enabled(args)
    material = create_material("dem", rve=args.rve, particles=particles, seed=args.seed,
                               pressure=args.confining, device=device, shards=args.shards,
                               progress=progress, tangent=args.tangent,
                               perturbation=args.perturbation, backend=args.backend,
                               packing=packing, **_dem_parameters(args))
    checkpoint, resuming = _open_checkpoint(args)
    with _checkpointed(args, checkpoint, resuming):
        if not resuming:
            material.allocate(setup.n_points)
        result, summary = _run(args, setup, material, "dem", tracking, checkpoint, resuming)
    summary.update(scale=_scale_name(scale, (nx, ny), particles), elements=[nx, ny],
                   gauss_points=setup.n_points,
                   particles=particles, device=device,
                   rve_material=_rve_material(args, packing))
    summary.update(band_summary(result, args.map_strain, summary["peak_stress_ratio"]))
    if args.out is not None:
        write_outputs(result, args.out, map_strain=args.map_strain)
        summary["out"] = str(args.out)
    return _report(args, summary, result.interrupt)
