"""The options of the FEM commands ``single-element`` and ``biaxial``: what ``--help`` shows
(the problem, the outputs, the material's choice) and the advanced groups that ``--help-all``
shows (the elements, where the RVEs run, the Newton solver, the DEM material, the RVE
material); their defaults are the run specification's fields'. What the commands do with
them is :mod:`granular_material.cli.fem`'s."""

from __future__ import annotations

import argparse
from pathlib import Path

from granular_material.cli.material_options import (
    add_material_arguments,
)
from granular_material.cli.options import (
    add_convergence,
    add_device,
    add_element,
    add_json,
    add_max_dem_steps,
    add_out,
    add_progress,
    add_rve_material_options,
    positive,
    positive_int,
)
from granular_material.cli.parsers import CommandParser
from granular_material.fem import available_postprocessors
from granular_material.fem.boundary_value.biaxial import PLATENS
from granular_material.fem.kinematics import FORMULATIONS
from granular_material.fem.regularisation import REGULARISATIONS
from granular_material.fem.solver.newton import PREDICTORS, RELAXATIONS, TANGENT_UPDATES
from granular_material.multiscale.run_hooks import DEMParameters
from granular_material.runs import OutputSpec
from granular_material.runs.presets import PRESET_NAMES
from granular_material.runs.spec import (
    BACKENDS,
    SCALES,
    AdaptivitySpec,
    NewtonSpec,
    ProblemSpec,
    RegularisationSpec,
)

__all__ = ["DEFAULT_MATERIAL", "DEFAULT_PARTICLES", "TANGENTS", "add_fem_commands"]

#: the defaults the options show: those of the run specification's fields
_NEWTON = NewtonSpec()
_OUTPUT = OutputSpec()
_REGULARISATION = RegularisationSpec()
_ADAPTIVITY = AdaptivitySpec()
_PROBLEM = {f: ProblemSpec.__dataclass_fields__[f].default
            for f in ("axial_strain", "confining", "steps")}
#: the material the FEM commands run by default, and its parameters' defaults (the class the
#: ``dem`` material's ``Parameters`` names, taken from its module: loading the material itself
#: would load warp and the DEM for any run, a continuum one too)
DEFAULT_MATERIAL = "dem"
_DEM = DEMParameters()
TANGENTS = _DEM.tangents
DEFAULT_PARTICLES = _DEM.default_particles


def regularisation_arguments(parser: argparse.ArgumentParser) -> None:
    """The FEM's regularisation: ``--regularisation`` and ``--internal-length`` (the spec's
    [regularisation] table, fields ``model`` and ``internal_length``)."""
    g = parser.add_argument_group("regularisation (past the peak)")
    g.add_argument("--regularisation", dest="model", choices=REGULARISATIONS,
                   default=_REGULARISATION.model,
                   help="none (default): the classical medium, whose softening localises in "
                        "one row of elements; second-gradient: Chambon's local second "
                        "gradient, a band whose width follows --internal-length, not the "
                        "mesh (quad8, quad9 or tri6 elements)")
    g.add_argument("--internal-length", type=float, default=_REGULARISATION.internal_length,
                   metavar="L",
                   help="the second gradient's internal length [m]: its modulus is "
                        "D = G0 (L/10)^2 with G0 the material's initial shear modulus; the band is "
                        "a few L wide")


def adaptivity_arguments(parser: argparse.ArgumentParser) -> None:
    """The specimen's adaptivity: ``--adaptivity`` and its settings (the spec's adaptivity
    section, a boundary-value scene's [adaptivity] keys; each setting defaults to None, so
    that one given without ``--adaptivity`` is refused)."""
    from granular_material.multiscale.switching import NEIGHBOURS, STARTS
    from granular_material.runs.spec_sections import SWITCHES

    a = _ADAPTIVITY
    g = parser.add_argument_group(
        "adaptivity (dem: DEM RVEs only where the twin is no longer trusted)", advanced=True,
        description="every Gauss point starts on the Mohr-Coulomb twin calibrated from the "
                    "first point's RVE and moves to its own RVE (the one an all-DEM run "
                    "gives it) once a threshold is met; the settings need --adaptivity")
    g.add_argument("--adaptivity", action="store_true",
                   help="turn it on, every setting at its default")
    g.add_argument("--mobilised-fraction", type=float, default=None, metavar="F",
                   help="a point becomes DEM once its mobilised friction angle reaches this "
                        "fraction, in (0, 1], of the twin's peak friction angle (default "
                        f"{a.mobilised_fraction:g}; with --shear-strain alone: not used)")
    g.add_argument("--shear-strain", type=float, default=None, metavar="GAMMA",
                   help="a point becomes DEM once its accumulated shear strain reaches this "
                        "[-] (default: not used)")
    g.add_argument("--neighbours", choices=NEIGHBOURS, default=None,
                   help="element: the points of a switching point's element switch with it "
                        f"(default {a.neighbours}); point: the point alone")
    g.add_argument("--start", choices=STARTS, default=None,
                   help="how a switching point's RVE starts: strain, driven through the "
                        f"point's deformation (default {a.start}); stress, brought by the "
                        "stress servo to the point's twin stress")
    g.add_argument("--switch", choices=SWITCHES, default=None,
                   help="in-step: a point that meets a threshold in a load step is DEM in "
                        f"that whole step (default {a.switch}); after-step: from the next "
                        "step on")
    g.add_argument("--calibration", type=Path, default=None, metavar="FILE",
                   help="a calibration.json of `granular-material calibrate` whose "
                        "parameters make the twin (default: the first RVE calibrated at "
                        "--confining when the run starts)")
    g.add_argument("--elastic-window", type=positive, default=None, metavar="STRAIN",
                   help="the axial strain [-] the run's calibration reads the twin's E and "
                        f"nu over (default {a.elastic_window:g})")


def _newton_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("Newton solver", advanced=True)
    g.add_argument("--rtol", type=float, default=None,
                   help="relative tolerance of the --convergence test: ||du||/||Du|| "
                        "or ||R||/||R0|| (default 0.01 for dem, Guo & Zhao; 1e-4 for "
                        "linear-elastic and mohr-coulomb; Wu et al. use 0.005)")
    g.add_argument("--stress-tol", type=float, default=None,
                   help="absolute tolerance as a stress error [Pa] at the Gauss points, for "
                        "DEM noise (default 0.005 x confining for dem, 0 for linear-elastic)")
    g.add_argument("--stall-rtol", type=float, default=None,
                   help="accept an iterate with ||R||/||R0|| below this once the residual has "
                        "stopped falling for --stall-window iterations (DEM stress noise; "
                        "default 2 x rtol for dem, off for linear-elastic; 0: off)")
    g.add_argument("--stall-window", type=int, default=_NEWTON.stall_window,
                   help="iterations without a 10 %% drop of the smallest residual (or "
                        "correction) that make a stall, for --stall-rtol and "
                        f"--accept-correction (default {_NEWTON.stall_window})")
    g.add_argument("--max-iterations", type=int, default=_NEWTON.max_iterations,
                   help="iterations per increment before it is halved "
                        f"(default {_NEWTON.max_iterations})")
    g.add_argument("--max-cutbacks", type=int, default=_NEWTON.max_cutbacks,
                   help=f"how often an increment may be halved (default {_NEWTON.max_cutbacks})")
    add_convergence(g, _NEWTON.convergence, None)
    g.add_argument("--predictor", choices=PREDICTORS, default=_NEWTON.predictor,
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
    g.add_argument("--tangent", choices=TANGENTS, default=_DEM.tangent,
                   help="dem: tangent of the RVEs: condensed-sticking (the contact "
                        "network's stiffness with the discs' fluctuations condensed out, "
                        "every touching contact sticking, plus the stress's spin: no DEM run; "
                        "on an H200 a condensation costs about as much as 200 DEM steps of "
                        "the batch; plain Newton without relaxation reached 10 %% on the "
                        "single element with it; default), condensed (the "
                        "same with contacts at their Coulomb cap sliding freely), "
                        "objective (Kruyt-Rothenburg "
                        "on sym grad u plus the stress's spin, symmetric: a rigid rotation "
                        "costs nothing), "
                        "kruyt-rothenburg (Wu et al. eq. 6 as published) or forward "
                        "differences of each RVE's response (perturbation: 4 more DEM runs per "
                        "iteration)")
    g.add_argument("--perturbation", type=float, default=_DEM.perturbation,
                   help="dem, --tangent perturbation: perturbation of grad u relative to its "
                        "largest component (default 0.1)")
    g.add_argument("--relaxation", choices=RELAXATIONS, default=None,
                   help="relaxation of Newton corrections (default aitken for dem: it damps "
                        "the DEM noise a soft tangent turns into displacement; none for "
                        "linear-elastic)")
    g.add_argument("--tangent-update", choices=TANGENT_UPDATES, default=None,
                   help="none: the material's tangent at every iterate (default for "
                        "linear-elastic); secant: "
                        "each point's tangent corrected by Broyden updates from the stress "
                        "change its RVE gave (without relaxation unless --relaxation is "
                        "given: Aitken and the updates fight); hold: the "
                        "tangent of the increment's first evaluation kept for all its "
                        "corrections (modified Newton: a tangent that switches with the "
                        "iterate cannot make it cycle; default for dem)")
    g.add_argument("--secant-min-change", type=float, default=_NEWTON.secant_min_change,
                   help="--tangent-update secant: smallest change of a point's grad u that "
                        f"updates its tangent (default {_NEWTON.secant_min_change:g}; smaller "
                        "changes carry DEM noise)")


def _dem_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("DEM material: what is stepped, and what is post-processed",
                                  advanced=True)
    g.add_argument("--reuse-tol", type=float, default=_DEM.reuse_tol,
                   help="a Gauss point whose grad u moved by at most this strain (every "
                        "component) since its RVE was last driven keeps that response instead "
                        f"of being stepped; 0: every RVE every iteration (default "
                        f"{_DEM.reuse_tol:g})")
    g.add_argument("--reuse-correction", choices=_DEM.reuse_corrections,
                   default=_DEM.reuse_correction,
                   help="a reused response as it is (none, default) or corrected to first "
                        "order by its tangent")
    g.add_argument("--drive", choices=_DEM.drives, default=_DEM.drive,
                   help="restart: each iteration drives an RVE from its committed state along "
                        "the whole step (Guo & Zhao, default); continue: from its last trial "
                        "state by the change of grad u (fewer DEM steps, path-dependent)")
    g.add_argument("--isotropic", action="store_true",
                   help="relax every RVE to the isotropic stress -confining I before the first "
                        "load step (a packing consolidated by the normal servo keeps some "
                        "shear stress: about -14 kPa at 100 kPa for 64 discs)")
    g.add_argument("--max-strain-per-step", type=positive, default=_DEM.max_strain_per_step,
                   metavar="STRAIN",
                   help="largest strain of one DEM step while an RVE is driven along grad u "
                        "(the quasi-static criterion; see the trade study; default "
                        f"{_DEM.max_strain_per_step:g})")
    add_max_dem_steps(g, "one RVE's path", default=_DEM.max_dem_steps,
                      help="cap on the DEM steps of one RVE's path in one Newton iteration: an "
                           "iterate that needs more is an error naming the point (default "
                           f"{_DEM.max_dem_steps:.0e}, a strain of "
                           f"{_DEM.max_dem_steps * _DEM.max_strain_per_step:g} at "
                           f"{_DEM.max_strain_per_step:g} a step)")
    g.add_argument("--track", nargs="+", default=None, metavar="POINT",
                   help="Gauss point ids (or 'all') whose RVEs the post-processors analyse; "
                        "results in tracked.csv")
    g.add_argument("--every", type=positive_int, default=_OUTPUT.every,
                   help="with --track: every this many load steps, step 0 included (default 1)")
    g.add_argument("--postprocess", nargs="+", default=None, metavar="NAME",
                   help="with --track: post-processors to run (installed: "
                        f"{', '.join(available_postprocessors()) or 'none'}; default: every "
                        "installed one)")


def _rve_material_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group(
        "RVE material", advanced=True,
        description="dem: the material of the RVEs the run prepares, each consolidated to "
                    "--confining: the options of `granular-material prepare` (not with "
                    "--rve, whose file carries its own; refused there)")
    add_rve_material_options(g, defaults=False)


def _common_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of both commands: the load, the outputs and the device (what ``--help``
    shows), then the elements, where the RVEs run and the checkpoints (``--help-all``)."""
    parser.add_argument("--axial-strain", type=float, default=_PROBLEM["axial_strain"],
                        help="final axial strain, compression positive (default "
                             f"{_PROBLEM['axial_strain']:g})")
    parser.add_argument("--confining", type=float, default=_PROBLEM["confining"],
                        help="lateral confining pressure [Pa], compression positive; also "
                             "the consolidation pressure of the RVEs a dem run prepares "
                             f"(default {_PROBLEM['confining']:g})")
    parser.add_argument("--steps", type=int, default=_PROBLEM["steps"],
                        help=f"load steps (default {_PROBLEM['steps']})")
    add_out(parser, "output folder: steps.csv, points.npy, fields.xdmf, summary.json, figures")
    parser.add_argument("--points-csv", action="store_true", default=_OUTPUT.points_csv,
                        help="with --out, the Gauss-point table also as text, points.csv "
                             "(points.npy, read by numpy.load, is written regardless)")
    parser.add_argument("--figures", action=argparse.BooleanOptionalAction,
                        default=_OUTPUT.figures,
                        help="with --out, draw the figures (stress_strain.png, maps) at the "
                             "end (default); --no-figures: tables, fields and summary only, "
                             "without matplotlib's second or so")
    add_json(parser, "a summary")
    add_device(parser, "DEM device")
    parser.add_argument("--preset", choices=PRESET_NAMES, default=None,
                        help="settings the trade study recommends (docs/trade-study): discs "
                             "per RVE, strain per DEM step, Newton's test and tolerance, "
                             "tangent, predictor and relaxation, drive, reuse; an option given "
                             "beside it (not at its default) wins")
    parser.add_argument("--resume", type=Path, default=None, metavar="DIR",
                        help="continue the stopped or killed run whose --out was DIR, in DIR, "
                             "from its last checkpoint (give the other options as then); the "
                             "result is the one of a run that never stopped")
    add_progress(parser)
    add_element(parser, advanced=True)
    g = parser.add_argument_group("where the RVEs run, maps and checkpoints", advanced=True)
    g.add_argument("--shards", type=int, default=None,
                   help="CPU threads (shards) of the DEM batch, per rank with --backend "
                        "mpi (default: one per core, shared by a node's ranks)")
    g.add_argument("--backend", choices=BACKENDS, default=BACKENDS[0],
                   help="dem: where the RVEs live: this process (default) or shards on "
                        "the ranks of an MPI job (launch with mpiexec -n K; rank 0 runs "
                        "the FEM and alone writes and prints; the same results)")
    g.add_argument("--map-strain", type=float, nargs="+", default=list(_OUTPUT.map_strain),
                   help="axial strain(s) of the displacement/shear-strain maps and of the "
                        "shear-band measures (default 0.02)")
    g.add_argument("--checkpoint-every", type=positive_int, default=_OUTPUT.checkpoint_every,
                   metavar="N",
                   help="save the committed state (RVEs with contact history, displacement, "
                        "Newton state) in OUT/checkpoint after every N load steps and after "
                        "the last; default: by elapsed time, after the first step at least a "
                        "second and ten times a save's duration after the last save, at the "
                        "latest every --checkpoint-minutes; the tables of every step are kept "
                        "regardless")
    g.add_argument("--checkpoint-minutes", type=positive,
                   default=_OUTPUT.checkpoint_minutes, metavar="M",
                   help="without --checkpoint-every: the longest time between two saves of "
                        f"the committed state (default {_OUTPUT.checkpoint_minutes:g} min)")


def add_fem_commands(subparsers: argparse._SubParsersAction) -> dict[str, CommandParser]:
    """Add the parsers of the ``single-element`` and ``biaxial`` commands; returns them by
    name (the caller sets what each runs)."""
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
    add_material_arguments(p, DEFAULT_MATERIAL)
    p.add_argument("--rve", type=Path, default=None,
                   help="dem: RVE file (one RVE, replicated to the 4 points, or four)")
    p.add_argument("--particles", type=int, default=None,
                   help=f"dem: discs per prepared RVE (default {DEFAULT_PARTICLES})")
    p.add_argument("--seed", type=int, default=_DEM.seed, help="dem: seed of the prepared RVE")
    p.add_argument("--independent", action="store_true",
                   help="dem: four independent RVEs (seeds seed..seed+3) instead of one "
                        "replicated")
    p.add_argument("--compare-dem", action="store_true",
                   help="dem: also run the pure-DEM drained biaxial of the same RVE")
    _common_arguments(p)
    regularisation_arguments(p)
    _newton_arguments(p)
    _dem_arguments(p)
    _rve_material_arguments(p)

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
    b.add_argument("--scale", choices=SCALES, default=None,
                   help="preset mesh and RVE size (default: full on CUDA, reduced on CPU)")
    b.add_argument("--elements", type=int, nargs=2, metavar=("NX", "NY"), default=None,
                   help="elements across the width and along the height (overrides --scale)")
    b.add_argument("--particles", type=int, default=None,
                   help="discs per RVE (overrides --scale)")
    b.add_argument("--seed", type=int, default=_DEM.seed, help="seed of the first RVE")
    b.add_argument("--rve", type=Path, default=None,
                   help="RVE file with one RVE per Gauss point (or one, replicated)")
    b.add_argument("--width", type=float, default=None,
                   help="specimen width [m] (default 0.05)")
    b.add_argument("--height", type=float, default=None,
                   help="specimen height [m] (default 0.10)")
    add_material_arguments(b, DEFAULT_MATERIAL)
    b.add_argument("--platens", choices=PLATENS, default=PLATENS[0],
                   help="smooth: platen nodes slide freely, one bottom node pinned (default); "
                        "rough: no platen node moves sideways")
    _common_arguments(b)
    regularisation_arguments(b)
    adaptivity_arguments(b)
    _newton_arguments(b)
    _dem_arguments(b)
    _rve_material_arguments(b)
    return {"single-element": p, "biaxial": b}
