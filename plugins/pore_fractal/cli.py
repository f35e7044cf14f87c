"""``granular-material fractal``: pore image and multifractal spectrum of an RVE file."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from granular_material.cli.options import UsageError, check_figure_file, check_memory, emit
from granular_material.dem.rve.file import load_rve

from .boxes import (
    BOX_RULES,
    DEFAULT_BOX_MAX,
    DEFAULT_BOX_MIN,
    DEFAULT_MIN_FILL,
    DEFAULT_PER_OCTAVE,
    MAX_PER_OCTAVE,
)
from .image import DEFAULT_PIXEL
from .postprocess import analyse_rve, summary

__all__ = ["CURVED_AT_PHYSICAL_HINT", "POOR_FIT_HINT", "register", "run"]

#: one line on what a flagged fit means for a pore image and what to do about it
POOR_FIT_HINT = (
    "R² < {min_r2:g}: the log box moments bend over the boxes used, so the pores are not "
    "self-similar across them (the grains set a scale; at one-pixel boxes the pixels do) "
    "and those D_q depend on the range: compare RVEs only at one --box-rule physical range "
    "and pixel, or narrow --box-min/--box-max"
)

#: the same under ``--box-rule physical`` when the fits at q = 0 (D0, alpha0) pass: the
#: advice of :data:`POOR_FIT_HINT` is followed already, what is left is the packing's own
CURVED_AT_PHYSICAL_HINT = (
    "expected for a disc packing: its pores look alike over about a decade of box sizes only, "
    "so D_q away from q = 0 bend; D0 and alpha0 (q = 0) fit, and every D_q compares between "
    "RVEs analysed at these boxes and pixel"
)

_DESCRIPTION = """\
Rasterise the pore space (pixels whose centre lies in no disc) of one periodic RVE and
compute the multifractal spectrum of the pore pixels by box counting, moment orders q in
[q-min, q-max], Chhabra & Jensen's direct method for alpha(q) and f(alpha), tau(q) and
D_q = tau/(q - 1), D_1 = alpha(1).

Boxes (--box-rule): `cell` (default, Wu et al. 2025): eps = 2^-k L (k = 1..K), fractions
of the window side L, on a window of m * 2^K pixels; the indices then move with the image's
size in pixels and with the RVE's size. `physical`: box sides fixed in metres, --box-min to
--box-max (capped at half the window), --per-octave sides per doubling, on a window at the
pixel nearest --pixel; a box less than --min-fill pore counts as empty. Use `physical` to
compare RVEs of different sizes or images of different pixels.

The image is an axis-aligned square window of the periodic tiling (also for a sheared
cell) with the cell's area. Reported: D0 (capacity dimension), alpha0 (alpha at q = 0),
alpha0/D0 with their standard errors (of the least-squares slopes), the fit range (smallest
and largest box) and R^2 of the fits at q = 0, the image's porosity next to the RVE's own,
the pixel size actually used and the image side in pixels. Fits with R^2 below --min-r2
are flagged.
"""

_EPILOG = """\
examples:
  granular-material fractal rve.npz
  granular-material fractal batch.npz --rve-index 3 --json
  granular-material fractal rve.npz --pixel 0.25e-3 --plot spectrum.png
  granular-material fractal rve.npz --box-rule physical --pixel 0.15e-3
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``fractal`` sub-command to the core command line."""
    parser = subparsers.add_parser(
        "fractal",
        help="pore image and multifractal spectrum (D0, alpha0) of an RVE file",
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("rve", type=Path, help="RVE file (.npz, the engine's format)")
    parser.add_argument(
        "--rve-index", type=int, default=0, metavar="I",
        help="which RVE of a batch file to analyse (default 0; negative counts from the end)",
    )
    parser.add_argument(
        "--pixel", type=float, default=DEFAULT_PIXEL, metavar="M",
        help="requested pixel size in m (default 0.3e-3); the one used is reported",
    )
    parser.add_argument(
        "--box-rule", choices=BOX_RULES, default="cell",
        help="cell: eps = 2^-k L (the paper's, default); physical: boxes fixed in metres, "
             "comparable across RVE sizes and pixels",
    )
    parser.add_argument(
        "--k-max", type=int, default=8, metavar="K",
        help="cell rule: finest box level, eps = 2^-k L for k = 1..K (default 8)",
    )
    parser.add_argument(
        "--box-min", type=float, default=None, metavar="M",
        help=f"physical rule: smallest box in m, at least 2 pixels (default {DEFAULT_BOX_MIN})",
    )
    parser.add_argument(
        "--box-max", type=float, default=None, metavar="M",
        help=f"physical rule: largest box in m, capped at half the window "
             f"(default {DEFAULT_BOX_MAX})",
    )
    parser.add_argument(
        "--per-octave", type=int, default=None, metavar="N",
        help=f"physical rule: box sides per doubling (default {DEFAULT_PER_OCTAVE})",
    )
    parser.add_argument(
        "--min-fill", type=float, default=None, metavar="F",
        help=f"physical rule: a box less than this fraction pore counts as empty "
             f"(default {DEFAULT_MIN_FILL})",
    )
    parser.add_argument("--q-min", type=float, default=-10.0, help="lowest q (default -10)")
    parser.add_argument("--q-max", type=float, default=10.0, help="highest q (default 10)")
    parser.add_argument("--q-step", type=float, default=0.5, help="q step (default 0.5)")
    parser.add_argument(
        "--min-r2", type=float, default=0.99, metavar="R2",
        help="flag q whose fits have R^2 below this (default 0.99)",
    )
    parser.add_argument(
        "--plot", type=Path, metavar="PNG",
        help="write a figure: pore image, q-D_q and alpha-f(alpha) spectra",
    )
    parser.add_argument(
        "--json", action="store_true",
        help="print one JSON object: D0, alpha0, alpha0_over_D0 and their _se, porosity, "
             "rve_porosity, pixel_size, image_size, window_side, box_rule, box_min_m, "
             "box_max_m, box_min_px, box_max_px, box_sizes, r2_q0, min_r2, rve_index, "
             "poor_fit_q",
    )
    parser.set_defaults(func=run)


#: the most moment orders q of one spectrum (41 by default)
_MAX_ORDERS = 10_000
# the most box sides per doubling of the physical rule: boxes.MAX_PER_OCTAVE, declared
# beside the rule (1e8 took 33 s to fail for memory before it was bounded)

#: the physical rule's options and their defaults (None on the parser: given or not)
_PHYSICAL = {"box_min": DEFAULT_BOX_MIN, "box_max": DEFAULT_BOX_MAX,
             "per_octave": DEFAULT_PER_OCTAVE, "min_fill": DEFAULT_MIN_FILL}


def _physical_options(args: argparse.Namespace) -> None:
    """The physical rule's options at their defaults where not given; refused (naming them)
    under ``--box-rule cell``, which would silently ignore them."""
    given = [name for name in _PHYSICAL if getattr(args, name, None) is not None]
    if args.box_rule != "physical" and given:
        flags = ", ".join("--" + name.replace("_", "-") for name in given)
        raise UsageError(f"{flags} set{'s' if len(given) == 1 else ''} the boxes of "
                         f"--box-rule physical; --box-rule {args.box_rule} would ignore "
                         f"{'it' if len(given) == 1 else 'them'} (add --box-rule physical)")
    for name, default in _PHYSICAL.items():
        if getattr(args, name, None) is None:
            setattr(args, name, default)


def _check_per_octave(args: argparse.Namespace) -> None:
    """The physical rule's sides per doubling: an integer in 1..:data:`MAX_PER_OCTAVE`,
    refused with the count of sides it would make before any work."""
    n = args.per_octave
    if n < 1:
        raise UsageError(f"--per-octave must be an integer >= 1, got {n}")
    if n > MAX_PER_OCTAVE:
        octaves = (math.log2(args.box_max / args.box_min)
                   if 0 < args.box_min < args.box_max and math.isfinite(args.box_max) else 1.0)
        raise UsageError(f"--per-octave {n} asks for about {n * octaves:.3g} box sides over "
                         f"{octaves:.3g} doublings (--box-min {args.box_min:g} to --box-max "
                         f"{args.box_max:g} m); sides closer than a pixel are the same box, so "
                         f"at most {MAX_PER_OCTAVE} per doubling are taken")
#: memory per pixel of the image while it is analysed, about [bytes]: the pore mask and the
#: box masses of its finest level (float64), with room for their temporaries
_PIXEL_BYTES = 24
#: memory per (box of the finest level, moment order), about [bytes]: the log-moments and
#: their weights (float64)
_MOMENT_BYTES = 32


def _check_size(args: argparse.Namespace, data: object, n_orders: int) -> None:
    """Before the image is made: its side in pixels and the moments' memory, refused with
    the estimate where the machine cannot hold them."""
    from .image import choose_window

    cells = data.cell  # type: ignore[attr-defined]
    if not -len(cells) <= args.rve_index < len(cells):
        return  # analyse_rve names the index
    try:
        n, _ = choose_window(cells[args.rve_index], args.pixel, 1 << args.k_max)
    except (ValueError, OverflowError):
        return  # analyse_rve says what is wrong with the cell or the pixel
    boxes = 4.0 ** args.k_max
    check_memory(float(n) ** 2 * _PIXEL_BYTES + boxes * n_orders * _MOMENT_BYTES,
                 f"--pixel {args.pixel:g} m ({n} x {n} pixels) with {n_orders} moment "
                 "orders")


def _orders(q_min: float, q_max: float, q_step: float) -> np.ndarray:
    if not all(math.isfinite(v) for v in (q_min, q_max, q_step)):
        raise ValueError("--q-min, --q-max and --q-step must be finite numbers")
    if q_step <= 0 or q_max < q_min:
        raise ValueError(
            f"need --q-step > 0 and --q-max >= --q-min, got step {q_step}, "
            f"range [{q_min}, {q_max}]"
        )
    count = math.floor((q_max - q_min) / q_step + 1e-9) + 1
    if count > _MAX_ORDERS:
        raise UsageError(f"--q-min {q_min:g} to --q-max {q_max:g} by --q-step {q_step:g} is "
                         f"{count:.4g} moment orders, more than {_MAX_ORDERS}; take a larger "
                         "--q-step")
    return q_min + q_step * np.arange(count)


def run(args: argparse.Namespace) -> int:
    """Run ``fractal`` for parsed ``args``; returns the exit code (bad input raises)."""
    if not (math.isfinite(args.pixel) and args.pixel > 0):
        raise ValueError(f"--pixel must be a positive length in m, got {args.pixel}")
    if not 2 <= args.k_max <= 12:
        raise ValueError(f"--k-max must lie in 2..12, got {args.k_max}")
    if not 0.0 <= args.min_r2 <= 1.0:
        raise ValueError(f"--min-r2 must lie in [0, 1], got {args.min_r2}")
    check_figure_file(args.plot, "--plot")
    _physical_options(args)
    _check_per_octave(args)
    q = _orders(args.q_min, args.q_max, args.q_step)
    levels = list(range(1, args.k_max + 1))
    data = load_rve(args.rve)
    _check_size(args, data, q.size)
    image, spectrum = analyse_rve(
        data, args.rve_index, args.pixel, q=q, k=levels, min_r2=args.min_r2,
        box_rule=args.box_rule, box_min=args.box_min, box_max=args.box_max,
        per_octave=args.per_octave, min_fill=args.min_fill,
    )
    result: dict[str, object] = dict(summary(image, spectrum))
    result["box_rule"] = args.box_rule
    result["rve_index"] = args.rve_index
    result["poor_fit_q"] = [float(v) for v in spectrum.q[spectrum.poor_fit]]
    if args.plot is not None:
        from granular_material_pore_fractal.plots import save_figure, spectrum_figure

        save_figure(spectrum_figure(image, spectrum), args.plot)
    if args.json:
        emit(args, result)
    else:
        _print_text(args, result)
    return 0


def _print_text(args: argparse.Namespace, result: dict[str, object]) -> None:
    print(f"{args.rve} [RVE {args.rve_index}]")
    print(f"  image        {result['image_size']}² px, pixel {result['pixel_size']:.6g} m, "
          f"window {result['window_side']:.6g} m")
    print(f"  porosity     {result['porosity']:.5f} image, {result['rve_porosity']:.5f} RVE")
    print(f"  boxes        {args.box_rule}: {1e3 * result['box_min_m']:.4g}–"
          f"{1e3 * result['box_max_m']:.4g} mm ({result['box_min_px']}–{result['box_max_px']} "
          f"px, {result['box_sizes']} sizes); R² at q = 0: {result['r2_q0']:.5f}")
    print(f"  D0           {result['D0']:.6f} ± {result['D0_se']:.2g}")
    print(f"  alpha0       {result['alpha0']:.6f} ± {result['alpha0_se']:.2g}")
    print(f"  alpha0/D0    {result['alpha0_over_D0']:.6f} ± {result['alpha0_over_D0_se']:.2g}"
          "  (± standard error of the fits)")
    poor = result["poor_fit_q"]
    if poor:
        print(f"  poor fits    R² < {args.min_r2:g} at q = {_ranges(poor, args.q_step)}")
        q0_fits = result["r2_q0"] >= args.min_r2
        hint = (CURVED_AT_PHYSICAL_HINT if args.box_rule == "physical" and q0_fits
                else POOR_FIT_HINT.format(min_r2=args.min_r2))
        print(f"  meaning      {hint}")
    else:
        print(f"  fits         all R² >= {args.min_r2:g} (smallest {result['min_r2']:.5f})")
    if args.plot is not None:
        print(f"  figure       {args.plot}")


def _ranges(values: list[float], step: float) -> str:
    """Orders q as runs of consecutive ones (``-10 to -1, 1 to 10``), single ones alone."""
    runs: list[list[float]] = []
    for v in values:
        if runs and abs(v - runs[-1][-1] - step) <= 1e-9 * max(1.0, abs(step)):
            runs[-1].append(v)
        else:
            runs.append([v])
    return ", ".join(f"{r[0]:g}" if len(r) == 1 else
                     f"{r[0]:g}, {r[1]:g}" if len(r) == 2 else f"{r[0]:g} to {r[-1]:g}"
                     for r in runs)
