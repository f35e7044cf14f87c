"""Input checks made before any work, whoever asks (the command line, a scene, a run
specification, a library caller): output folders and files that can be written, memory
that a run will need, RVE files that exist, the material and packing of RVEs to prepare.

Each refusal of a value is a :class:`~granular_material.errors.ParameterError` naming the
field that set it (``field``: ``out``, ``rve``, ``contact_friction_angle``; another field
the message names is written in backquotes, ```particles```), which the command line shows
as its option (:func:`granular_material.cli.options.flag_of`); a refusal that no one value
makes (the memory a run needs) is a plain ``ValueError``. No message here names a
command-line flag.
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from granular_material.dem.rve.format import FRICTMAT_STIFFNESS, RVEMeta
from granular_material.errors import ParameterError
from granular_material.memory import (
    MEMORY_LIMIT,
    available_memory,
    memory_refusal,
    size_in_words,
)
from granular_material.reference_values import DEFAULT_RADIUS_RANGE
from granular_material.vocabulary import renames

if TYPE_CHECKING:
    from granular_material.procedures.packing import PackingParameters

# The packing's checks (procedures.packing, which loads the DEM and warp) are imported where
# they are used: a run of a continuum material imports this module, never the DEM (issue 62).

__all__ = ["DISC_BYTES", "MEMORY_LIMIT", "RVE_MATERIAL_DEFAULTS", "WordedError",
           "available_memory", "check_memory", "check_output_dir", "check_output_file",
           "cleanup_on_rejection", "make_parents", "packing_parameters", "rve_file_shape",
           "rve_material_given", "rve_meta"]


def _writable_folder(path: Path, field: str, given: Path) -> None:
    """The folder ``path`` or, where it does not exist yet, its nearest existing ancestor must
    be a folder this process may create files in (nothing is created here); messages name
    the value ``given`` of ``field``."""
    folder = path
    while not folder.exists():
        if folder.parent == folder:
            break
        folder = folder.parent
    if not folder.is_dir():
        raise ParameterError(field, f"{given}: {folder} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ParameterError(field, f"{given}: cannot write in {folder} (permission denied or "
                                    "a read-only file system)")


def check_output_file(path: Path | None, field: str = "out") -> None:
    """Before any work: ``path`` (an output file; None: none) can be written — it is not a
    folder and its folder exists or can be made. Creates nothing (:func:`make_parents` does,
    when the file is written), so a rejected run leaves nothing behind."""
    if path is None:
        return
    path = Path(path)
    _not_dangling(path, field)
    if path.is_dir():
        raise ParameterError(field, f"{path} is a folder; give a file name")
    if path.exists() and not os.access(path, os.W_OK):
        raise ParameterError(field, f"{path} exists and cannot be overwritten")
    _writable_folder(path.parent, field, path)


#: memory one disc of an RVE takes while it is run, about [bytes]: its state, the committed
#: and trial copies, and 16 neighbour slots (partner and shear history) each, a safe margin
DISC_BYTES = 2048


def _size(n_bytes: float) -> str:
    """``n_bytes`` in words: 12.3 GB, 4.1 TB, 2e+25 B."""
    return size_in_words(n_bytes)


def check_memory(needed: float, what: str) -> None:
    """Before any allocation: ``what`` (the options, in words) needs about ``needed`` bytes;
    refused (ValueError with the estimate) beyond :data:`MEMORY_LIMIT`, which no machine
    this runs on has, or beyond the memory available now."""
    refusal = memory_refusal(needed, what, available_memory())
    if refusal is not None:
        raise ValueError(refusal)


def check_output_dir(path: Path | None, field: str = "out") -> None:
    """Before any work: ``path`` (an output folder; None: none) is a folder, or can be made,
    and can be written in. Creates nothing."""
    if path is None:
        return
    path = Path(path)
    _not_dangling(path, field)
    if path.exists() and not path.is_dir():
        raise ParameterError(field, f"{path} exists and is not a folder")
    _writable_folder(path, field, path)
    if path.is_dir():  # a folder where a file is written under its temporary name
        with contextlib.suppress(OSError):
            stray = sorted(p.name for p in path.iterdir()
                           if p.name.endswith(".part") and p.is_dir() and not p.is_symlink())
            if stray:
                raise ParameterError(field, f"{path} holds the folder {stray[0]}, where a file "
                                            "of the run is written before it is renamed into "
                                            "place: remove it")


def _not_dangling(path: Path, field: str) -> None:
    """``path`` is no symbolic link to nothing (which neither exists nor can be made)."""
    if path.is_symlink() and not path.exists():
        raise ParameterError(field, f"{path} is a symbolic link to {os.readlink(path)}, which "
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


def rve_file_shape(path: Path, field: str = "rve") -> tuple[int, int]:
    """(B, N): the RVEs and discs per RVE of the RVE file ``path``, read (and so checked)
    before any work; a file asked about again unchanged (same size and modification time)
    is not read again."""
    path = Path(path)
    if not path.exists():
        raise ParameterError(field, f"{path} does not exist")
    stat = path.stat()
    return _rve_file_shape(str(path.resolve()), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=16)
def _rve_file_shape(path: str, mtime_ns: int, size: int) -> tuple[int, int]:
    """(B, N) of the RVE file ``path`` as it is at ``mtime_ns`` and ``size`` (the cache's
    key: a file written since is read anew; a file that cannot be read is not cached)."""
    from granular_material.dem import load_rve

    data = load_rve(path)
    return data.n_rve, data.n_disc


#: the RVE file's meta keys (docs/design.md#rve-file) whose option and field names say they
#: are the contacts': friction [rad] and FrictMat's modulus, the DEM material's old names
#: (:data:`granular_material.vocabulary.RENAMED`)
_META_FIELDS = {old: rename.new for old, rename in renames("dem").items()}


def _rve_material_defaults() -> dict[str, Any]:
    """The RVE material fields (the options of
    :func:`~granular_material.cli.options.add_rve_material_options`) with their defaults:
    those of :class:`~granular_material.dem.RVEMeta`, its contact laws and the packing
    (Wu et al. 2025, Table 1)."""
    meta = RVEMeta()
    r_min, r_max = DEFAULT_RADIUS_RANGE
    frictmat = {_META_FIELDS.get(k, k): v for k, v in FRICTMAT_STIFFNESS.items() if k != "law"}
    return {"target_void_ratio": None, "radius_min": r_min, "radius_max": r_max,
            **meta.stiffness, **frictmat, "contact_friction_angle": meta.friction_angle,
            "damping": meta.damping, "density": meta.density, "thickness": meta.thickness}


#: the fields of the material and packing of prepared RVEs, with their defaults
RVE_MATERIAL_DEFAULTS: dict[str, Any] = _rve_material_defaults()


def rve_material_given(values: Any) -> list[str]:
    """The RVE material fields (:data:`RVE_MATERIAL_DEFAULTS`) that ``values`` (parsed
    options, or a material's parameters) sets to other than their defaults, by name;
    ``particles`` too where it is set (the discs of the RVEs a run prepares)."""
    given = [name for name, default in RVE_MATERIAL_DEFAULTS.items()
             if getattr(values, name) != default]
    return (["particles"] if getattr(values, "particles", None) is not None else []) + given


class WordedError(ParameterError):
    """A refusal worded whole: ``message`` is the sentence, naming ``field`` and any other
    field it speaks of in backquotes (```radius_min`` = 0.007 exceeds ``radius_max`` ...``);
    ``str()`` shows it with the backquotes dropped, the command line with each name as its
    option. Where a check's sentence does not begin with the field (several take part)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(field, message)
        self.args = (message.replace("`", ""),)

    def __str__(self) -> str:
        return str(self.args[0])


def _named(field: str) -> str:
    """How a worded refusal names ``field``: in backquotes."""
    return f"`{field}`"


#: how :func:`packing_parameters` names the values of a packing: by their fields
_PACKING_FIELDS = {"radius_range": ("radius_min", "radius_max"), "n_disc": "particles",
                   "stiffness": "kn"}

#: a message of :meth:`~granular_material.dem.RVEMeta.validate` names its key
#: (``meta.friction_angle``, ``meta.stiffness.kn``): the field that sets it (:data:`_META_FIELDS`)
_META_KEY = re.compile(r"meta\.(?:stiffness\.)?([a-z_]+)")


def _packing_refusal(exc: ValueError, pressure_field: str, particles: int, pressure: float,
                     radius_range: tuple[float, float]) -> WordedError:
    """A refusal of :func:`~granular_material.procedures.packing.check_packing` (which names
    the values as it is told: the fields, in backquotes) with the field it is about: the
    radii's, the discs', else the pressure's."""
    from granular_material.procedures.packing import min_discs

    r_min, r_max = radius_range
    if not (0 < r_min <= r_max and math.isfinite(r_max)):
        field = "radius_min"
    elif math.isfinite(pressure) and pressure > 0 and particles < min_discs(radius_range):
        field = "particles"
    else:
        field = pressure_field
    return WordedError(field, str(exc))


def rve_meta(args: Any) -> RVEMeta:
    """The contact law and material of the RVEs a run prepares, from the RVE material fields
    (:data:`RVE_MATERIAL_DEFAULTS`) of ``args``, validated (a ParameterError naming the
    field)."""
    if args.law == "constant":
        stiffness = {"law": "constant", "kn": args.kn, "kt": args.kt}
    else:
        stiffness = {"law": "frictmat", "young": args.contact_young,
                     "kt_over_kn": args.kt_over_kn}
    meta = RVEMeta(thickness=args.thickness, density=args.density,
                   friction_angle=args.contact_friction_angle, damping=args.damping,
                   stiffness=stiffness, seed=getattr(args, "seed", None))
    try:
        meta.validate()
    except ValueError as exc:
        key = _META_KEY.search(str(exc))
        field = _META_FIELDS.get(key.group(1), key.group(1)) if key else "law"
        raise WordedError(field, _META_KEY.sub(
            lambda m: _named(_META_FIELDS.get(m.group(1), m.group(1))), str(exc))) from None
    return meta


def packing_parameters(args: Any, particles: int, pressure: float,
                       pressure_field: str = "pressure") -> PackingParameters:
    """The RVE material fields (:data:`RVE_MATERIAL_DEFAULTS`) of ``args`` as the parameters
    of a packing of ``particles`` discs consolidated to ``pressure`` [Pa] (set by
    ``pressure_field``), checked before any work (the checks of
    :func:`~granular_material.procedures.packing.check_packing`): a ParameterError naming
    the field when the radii, the contact law, the discs or the pressure cannot make a
    packing."""
    from granular_material.procedures.packing import (
        PackingParameters,
        check_packing,
        check_radius_range,
    )

    radius_range = (args.radius_min, args.radius_max)
    names = {"radius_range": tuple(_named(f) for f in _PACKING_FIELDS["radius_range"]),
             "n_disc": _named("particles"),
             "stiffness": f"{_named('kn')} / {_named('contact_young')}",
             "pressure": _named(pressure_field)}
    try:
        check_radius_range(radius_range, names["radius_range"])
    except ValueError as exc:
        raise WordedError("radius_min", str(exc)) from None
    meta = rve_meta(args)
    try:
        check_packing(particles, pressure, meta, radius_range, names=names)
    except ValueError as exc:
        raise _packing_refusal(exc, pressure_field, particles, pressure, radius_range) from None
    return PackingParameters(meta=meta, radius_range=radius_range,
                             target_void_ratio=args.target_void_ratio)
