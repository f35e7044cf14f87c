"""Input checks made before any work, whoever asks (the command line, a scene, a run
specification, a library caller): output folders and files that can be written, memory
that a run will need, RVE files that exist, the material and packing of RVEs to prepare.

Each refusal is a :class:`UsageError` (a ``ValueError``) whose message names what set the
value, as the caller names it (``option``: a command-line flag by default).
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from granular_material.procedures.packing import PackingParameters

__all__ = ["DISC_BYTES", "MEMORY_LIMIT", "RVE_MATERIAL_DEFAULTS", "UsageError",
           "available_memory", "check_memory", "check_output_dir", "check_output_file",
           "cleanup_on_rejection", "make_parents", "packing_parameters", "rve_file_shape"]


class UsageError(ValueError):
    """Bad input from the user: reported on stderr with exit code 2."""


def _writable_folder(path: Path, option: str, given: Path) -> None:
    """The folder ``path`` or, where it does not exist yet, its nearest existing ancestor must
    be a folder this process may create files in (nothing is created here); messages name
    the option's value ``given``."""
    folder = path
    while not folder.exists():
        if folder.parent == folder:
            break
        folder = folder.parent
    if not folder.is_dir():
        raise UsageError(f"{option} {given}: {folder} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {given}: cannot write in {folder} (permission denied or a "
                         "read-only file system)")


def check_output_file(path: Path | None, option: str = "--out") -> None:
    """Before any work: ``path`` (an output file; None: none) can be written — it is not a
    folder and its folder exists or can be made. Creates nothing (:func:`make_parents` does,
    when the file is written), so a rejected run leaves nothing behind."""
    if path is None:
        return
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"{option} {path} is a folder; give a file name")
    if path.exists() and not os.access(path, os.W_OK):
        raise UsageError(f"{option} {path} exists and cannot be overwritten")
    _writable_folder(path.parent, option, path)


#: memory one disc of an RVE takes while it is run, about [bytes]: its state, the committed
#: and trial copies, and 16 neighbour slots (partner and shear history) each, a safe margin
DISC_BYTES = 2048


#: a request for more memory than this is refused whatever the machine [bytes]: 1 TiB
MEMORY_LIMIT = 2**40


def _size(n_bytes: float) -> str:
    """``n_bytes`` in words: 12.3 GB, 4.1 TB, 2e+25 B."""
    if n_bytes >= 1e21:
        return f"{n_bytes:.3g} B"
    for unit, scale in (("EB", 1e18), ("PB", 1e15), ("TB", 1e12), ("GB", 1e9), ("MB", 1e6),
                        ("kB", 1e3)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.3g} {unit}"
    return f"{n_bytes:.0f} B"


def available_memory() -> int | None:
    """Memory the system can give this process now [bytes] (MemAvailable of Linux, else the
    free pages), or None where it cannot be told."""
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    with contextlib.suppress(OSError, ValueError, AttributeError):
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    return None


def check_memory(needed: float, what: str) -> None:
    """Before any allocation: ``what`` (the options, in words) needs about ``needed`` bytes;
    refused (UsageError with the estimate) beyond :data:`MEMORY_LIMIT`, which no machine
    this runs on has, or beyond the memory available now."""
    if not needed <= MEMORY_LIMIT:  # NaN and inf too
        raise UsageError(f"{what} needs about {_size(needed)} of memory, more than the "
                         f"{_size(MEMORY_LIMIT)} any run may take; ask for less")
    available = available_memory()
    if available is not None and needed > available:
        raise UsageError(f"{what} needs about {_size(needed)} of memory; this machine has "
                         f"{_size(available)} available now; ask for less")


def check_output_dir(path: Path | None, option: str = "--out") -> None:
    """Before any work: ``path`` (an output folder; None: none) is a folder, or can be made,
    and can be written in. Creates nothing."""
    if path is None:
        return
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UsageError(f"{option} {path} exists and is not a folder")
    _writable_folder(path, option, path)


@contextlib.contextmanager
def cleanup_on_rejection(folder: Path | None) -> Iterator[None]:
    """Folders the block makes at and above the output folder ``folder`` (None: none) are
    removed again, where still empty, when it raises ``ValueError`` (rejected input, e.g.
    settings checked once the writer is open): a rejected run leaves nothing behind."""
    if folder is None:
        yield
        return
    made = []
    path = Path(folder)
    while not path.exists() and path.parent != path:
        made.append(path)
        path = path.parent
    try:
        yield
    except ValueError:
        for path in made:  # deepest first
            with contextlib.suppress(OSError):
                path.rmdir()
        raise


def make_parents(path: Path | None) -> None:
    """Create the folders of the output file ``path`` (None: nothing), when it is written."""
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)


def rve_file_shape(path: Path, option: str = "--rve") -> tuple[int, int]:
    """(B, N): the RVEs and discs per RVE of the RVE file ``path``, read before any work."""
    from granular_material.dem import load_rve

    if not Path(path).exists():
        raise UsageError(f"{option} {path} does not exist")
    data = load_rve(path)
    return data.n_rve, data.n_disc


#: the options of :func:`add_rve_material_options`, by ``dest``, with their defaults (those of
#: ``RVEMeta`` and of the packing: Wu et al. 2025, Table 1)
RVE_MATERIAL_DEFAULTS: dict[str, Any] = {
    "target_void_ratio": None, "radius_min": 3e-3, "radius_max": 7e-3, "law": "constant",
    "kn": 3e6, "kt": 2.4e6, "young": 6e8, "kt_over_kn": 0.8, "friction_angle": 0.5,
    "damping": 0.1, "density": 2650.0, "thickness": 0.1,
}


def _option_named(message: str) -> str:
    """A message of ``RVEMeta.validate`` with its field named as the option that sets it
    (``meta.friction_angle`` → ``--friction-angle``, ``meta.stiffness.kn`` → ``--kn``)."""
    return re.sub(r"meta\.(?:stiffness\.)?([a-z_]+)",
                  lambda m: "--" + m.group(1).replace("_", "-"), message)


def packing_parameters(args: Any, particles: int, pressure: float,
                       pressure_option: str = "--pressure") -> PackingParameters:
    """The options of :func:`add_rve_material_options` in ``args`` as the parameters of a
    packing of ``particles`` discs consolidated to ``pressure`` [Pa] (set by
    ``pressure_option``), checked before any work: ``UsageError`` naming the option when the
    radii, the contact law, the discs or the pressure cannot make a packing."""
    from granular_material.dem import RVEMeta
    from granular_material.procedures.packing import (
        MAX_OVERLAP,
        PackingParameters,
        max_pressure,
        min_discs,
        min_pressure,
        smallest_normal_stiffness,
    )

    if args.radius_min > args.radius_max:
        raise UsageError(f"--radius-min {args.radius_min} exceeds --radius-max "
                         f"{args.radius_max}")
    if args.law == "constant":
        stiffness = {"law": "constant", "kn": args.kn, "kt": args.kt}
    else:
        stiffness = {"law": "frictmat", "young": args.young, "kt_over_kn": args.kt_over_kn}
    meta = RVEMeta(thickness=args.thickness, density=args.density,
                   friction_angle=args.friction_angle, damping=args.damping,
                   stiffness=stiffness, seed=getattr(args, "seed", None))
    try:
        meta.validate()
    except ValueError as exc:
        raise UsageError(_option_named(str(exc))) from None
    radius_range = (args.radius_min, args.radius_max)
    fewest = min_discs(radius_range)
    if particles < fewest:
        raise UsageError(
            f"--particles {particles} is too few: with radii {args.radius_min:g}–"
            f"{args.radius_max:g} m the consolidated cell must stay wider than twice the "
            f"contact cut-off (2·r_max + skin; the engine sees one periodic image of each "
            f"pair), which takes at least {fewest} discs"
        )
    # the estimated overlap of a contact as a share of the radius, 2·p·t/kn
    overlap = 2 * pressure * args.thickness / smallest_normal_stiffness(meta, radius_range)
    lowest = min_pressure(meta, radius_range)
    if pressure < lowest:
        raise UsageError(
            f"{pressure_option} {pressure:g} Pa is too low for these stiffnesses: the "
            f"contacts would overlap by about {overlap:.2g} of their radius, below which the "
            f"consolidation servo does not settle a packing; at least {lowest:.4g} Pa (or a "
            "softer --kn / --young)"
        )
    highest = max_pressure(meta, radius_range)
    if pressure > highest:
        raise UsageError(
            f"{pressure_option} {pressure:g} Pa would press the discs about {overlap:.0%} of "
            f"their radius into each other (2·p·thickness/kn); the linear contact law holds "
            f"to {MAX_OVERLAP:.0%} (the void space is gone near 20%): at most "
            f"{highest:.4g} Pa with these stiffnesses (or stiffer --kn / --young)"
        )
    return PackingParameters(meta=meta, radius_range=radius_range,
                             target_void_ratio=args.target_void_ratio)
