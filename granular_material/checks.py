"""Input checks made before any work, whoever asks (the command line, a scene, a run
specification, a library caller): output folders and files that can be written, memory
that a run will need, RVE files that exist, the material and packing of RVEs to prepare.

Each refusal is a :class:`UsageError` (a ``ValueError``) whose message names what set the
value, as the caller names it (``option``: a command-line flag by default).
"""

from __future__ import annotations

import contextlib
import functools
import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from granular_material.dem.rve_file import FRICTMAT_STIFFNESS, RVEMeta
from granular_material.memory import (
    MEMORY_LIMIT,
    available_memory,
    memory_refusal,
    size_in_words,
)
from granular_material.procedures.packing import (
    DEFAULT_RADIUS_RANGE,
    PackingParameters,
    check_packing,
    check_radius_range,
)

__all__ = ["DISC_BYTES", "MEMORY_LIMIT", "RVE_MATERIAL_DEFAULTS", "UsageError",
           "available_memory", "check_memory", "check_output_dir", "check_output_file",
           "cleanup_on_rejection", "make_parents", "packing_parameters", "rve_file_shape",
           "rve_material_given"]


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
    _not_dangling(path, option)
    if path.is_dir():
        raise UsageError(f"{option} {path} is a folder; give a file name")
    if path.exists() and not os.access(path, os.W_OK):
        raise UsageError(f"{option} {path} exists and cannot be overwritten")
    _writable_folder(path.parent, option, path)


#: memory one disc of an RVE takes while it is run, about [bytes]: its state, the committed
#: and trial copies, and 16 neighbour slots (partner and shear history) each, a safe margin
DISC_BYTES = 2048


def _size(n_bytes: float) -> str:
    """``n_bytes`` in words: 12.3 GB, 4.1 TB, 2e+25 B."""
    return size_in_words(n_bytes)


def check_memory(needed: float, what: str) -> None:
    """Before any allocation: ``what`` (the options, in words) needs about ``needed`` bytes;
    refused (UsageError with the estimate) beyond :data:`MEMORY_LIMIT`, which no machine
    this runs on has, or beyond the memory available now."""
    refusal = memory_refusal(needed, what, available_memory())
    if refusal is not None:
        raise UsageError(refusal)


def check_output_dir(path: Path | None, option: str = "--out") -> None:
    """Before any work: ``path`` (an output folder; None: none) is a folder, or can be made,
    and can be written in. Creates nothing."""
    if path is None:
        return
    path = Path(path)
    _not_dangling(path, option)
    if path.exists() and not path.is_dir():
        raise UsageError(f"{option} {path} exists and is not a folder")
    _writable_folder(path, option, path)
    if path.is_dir():  # a folder where a file is written under its temporary name
        with contextlib.suppress(OSError):
            stray = sorted(p.name for p in path.iterdir()
                           if p.name.endswith(".part") and p.is_dir() and not p.is_symlink())
            if stray:
                raise UsageError(f"{option} {path} holds the folder {stray[0]}, where a file "
                                 "of the run is written before it is renamed into place: "
                                 "remove it")


def _not_dangling(path: Path, option: str) -> None:
    """``path`` is no symbolic link to nothing (which neither exists nor can be made)."""
    if path.is_symlink() and not path.exists():
        raise UsageError(f"{option} {path} is a symbolic link to {os.readlink(path)}, which "
                         "does not exist: make its target, or give another path")


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
    """(B, N): the RVEs and discs per RVE of the RVE file ``path``, read (and so checked)
    before any work; a file asked about again unchanged (same size and modification time)
    is not read again."""
    path = Path(path)
    if not path.exists():
        raise UsageError(f"{option} {path} does not exist")
    stat = path.stat()
    return _rve_file_shape(str(path.resolve()), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=16)
def _rve_file_shape(path: str, mtime_ns: int, size: int) -> tuple[int, int]:
    """(B, N) of the RVE file ``path`` as it is at ``mtime_ns`` and ``size`` (the cache's
    key: a file written since is read anew; a file that cannot be read is not cached)."""
    from granular_material.dem import load_rve

    data = load_rve(path)
    return data.n_rve, data.n_disc


def _rve_material_defaults() -> dict[str, Any]:
    """The options of :func:`add_rve_material_options`, by ``dest``, with their defaults:
    those of :class:`~granular_material.dem.RVEMeta`, its contact laws and the packing
    (Wu et al. 2025, Table 1)."""
    meta = RVEMeta()
    r_min, r_max = DEFAULT_RADIUS_RANGE
    frictmat = {k: v for k, v in FRICTMAT_STIFFNESS.items() if k != "law"}
    return {"target_void_ratio": None, "radius_min": r_min, "radius_max": r_max,
            **meta.stiffness, **frictmat, "friction_angle": meta.friction_angle,
            "damping": meta.damping, "density": meta.density, "thickness": meta.thickness}


#: the options of :func:`add_rve_material_options`, by ``dest``, with their defaults
RVE_MATERIAL_DEFAULTS: dict[str, Any] = _rve_material_defaults()


def rve_material_given(values: Any) -> list[str]:
    """The RVE material options (:data:`RVE_MATERIAL_DEFAULTS`) that ``values`` (parsed
    options, or a material's parameters) sets to other than their defaults, as ``--names``;
    ``--particles`` too where it is set (the discs of the RVEs a run prepares)."""
    given = [f"--{dest.replace('_', '-')}" for dest, default in RVE_MATERIAL_DEFAULTS.items()
             if getattr(values, dest) != default]
    return (["--particles"] if getattr(values, "particles", None) is not None else []) + given


def _option_named(message: str) -> str:
    """A message of ``RVEMeta.validate`` with its field named as the option that sets it
    (``meta.friction_angle`` → ``--friction-angle``, ``meta.stiffness.kn`` → ``--kn``)."""
    return re.sub(r"meta\.(?:stiffness\.)?([a-z_]+)",
                  lambda m: "--" + m.group(1).replace("_", "-"), message)


#: how :func:`packing_parameters` names the values of a packing: by their options
_PACKING_OPTIONS = {"radius_range": ("--radius-min", "--radius-max"), "n_disc": "--particles",
                    "stiffness": "--kn / --young"}


def packing_parameters(args: Any, particles: int, pressure: float,
                       pressure_option: str = "--pressure") -> PackingParameters:
    """The options of :func:`add_rve_material_options` in ``args`` as the parameters of a
    packing of ``particles`` discs consolidated to ``pressure`` [Pa] (set by
    ``pressure_option``), checked before any work (the checks of
    :func:`~granular_material.procedures.packing.check_packing`): ``UsageError`` naming the
    option when the radii, the contact law, the discs or the pressure cannot make a packing."""
    radius_range = (args.radius_min, args.radius_max)
    try:
        check_radius_range(radius_range, _PACKING_OPTIONS["radius_range"])
    except ValueError as exc:
        raise UsageError(str(exc)) from None
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
    try:
        check_packing(particles, pressure, meta, radius_range,
                      names={**_PACKING_OPTIONS, "pressure": pressure_option})
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return PackingParameters(meta=meta, radius_range=radius_range,
                             target_void_ratio=args.target_void_ratio)
