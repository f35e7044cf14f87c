"""The DEM material's settings, each declared once, in three frozen layers.

- :class:`DEMDriving`: how the RVEs are driven and measured (tangent, drive, reuse, strain
  per DEM step, cap on a path's steps): all a backend takes, in this process or on each
  rank of an MPI job.
- :class:`DEMRVEs`: those plus where the RVEs come from (a file, or packings of a number of
  discs from a seed) and whether they are first relaxed to an isotropic stress; the part a
  run specification and a Python material share.
- :class:`DEMMaterialParameters`: those plus what a material built in Python is told
  directly and a run takes from its problem and its ``[run]`` fields (the confining pressure
  or the initial stress of every point, replication, device, CPU shards, backend, the
  packings' material).

The run specification's own :class:`~granular_material.multiscale.run_hooks.DEMParameters`
extends :class:`DEMRVEs` in the same way. Every check is made here, once, as a
:class:`~granular_material.errors.ParameterError` naming the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from numbers import Real
from pathlib import Path

import numpy as np

from granular_material.dem.tangents import TangentMethod, tangent_method
from granular_material.errors import ParameterError
from granular_material.procedures.packing import (
    MAX_OVERLAP,
    PACKING_NAMES,
    PackingParameters,
    check_packing,
    max_pressure,
    min_discs,
    smallest_normal_stiffness,
)
from granular_material.reference_values import (
    DEFAULT_DISCS,
    DEFAULT_MAX_DEM_STEPS,
    DEFAULT_PRESSURE,
    DEFAULT_STRAIN_PER_STEP,
)
from granular_material.typed_fields import conform_fields

__all__ = ["BACKENDS", "DRIVES", "MAX_SHARDS", "MIN_PERTURBATION", "REUSE_CORRECTIONS",
           "DEMDriving", "DEMMaterialParameters", "DEMRVEs"]

#: how an RVE that must move is driven to a new trial ∇u: from the committed state along the
#: whole path of the step (``restart``, Guo & Zhao), or from its last trial state by the change
DRIVES = ("restart", "continue")
#: what a reused RVE returns: its last response as it is, or corrected to first order by
#: its tangent for the change of ∇u
REUSE_CORRECTIONS = ("none", "tangent")
#: who holds the RVEs: this process (``inprocess``), or contiguous shards of them on the ranks
#: of an MPI job (``mpi``, :mod:`granular_material.multiscale.mpi`)
BACKENDS = ("inprocess", "mpi")
#: the smallest perturbation of ∇u the perturbation tangent takes [-]
MIN_PERTURBATION = 1.0e-4
#: most CPU shards (threads) of a batch: a batch runs min(shards, RVEs) threads, each with its
#: own build of the DEM kernels (a CPU kernel module cannot serve two threads at once,
#: :func:`~granular_material.dem.kernels.sets.kernels_for`), and no machine this runs on has more
#: cores than this, so more threads only add builds and never step faster
MAX_SHARDS = 1024


def _one_of(name: str, value: object, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ParameterError(name, f"must be one of {', '.join(choices)}, got {value!r}")


def _finite(value: object) -> bool:
    """``value`` is a real number (no bool) that a float holds finite: an integer beyond any
    float is not (``math.isfinite`` overflows on it)."""
    if isinstance(value, bool) or not isinstance(value, Real):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def _count(name: str, value: object, lowest: int, what: str = "") -> None:
    """``value`` is an integer >= ``lowest``; else a ParameterError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, Real) \
            or int(value) != value or value < lowest:
        raise ParameterError(name, f"must be an integer >= {lowest}{what}, got {value!r}")


@dataclass(frozen=True, kw_only=True)
class DEMDriving:
    """How the RVEs are driven to a ∇u and what they answer (SI; strains dimensionless).

    Attributes:
        tangent: the RVEs' tangent (:data:`~granular_material.dem.tangents.TANGENTS`):
            "objective" (Kruyt–Rothenburg applied to sym ∇u plus the stress's spin),
            "kruyt-rothenburg" (Wu et al. 2025, eq. 6 as published), "perturbation" (forward
            differences of the RVE's response: four more DEM runs an evaluation),
            "condensed" (the discs' fluctuations condensed out of the contact network,
            contacts at their Coulomb cap sliding freely) or "condensed-sticking" (every
            touching contact keeping kt: an upper bound of the RVE's stiffness). A material
            built in Python defaults to "objective": a user's own Newton loop asks for the
            tangent at every iterate, and a condensation costs more than the DEM run itself;
            a run specification (and so the commands) defaults to "condensed-sticking",
            held over each increment by its Newton loop
            (:data:`~granular_material.fem.solver.defaults.NOISY_DEFAULTS`).
        perturbation: relative perturbation of ∇u of the "perturbation" tangent [-], > 0
            (at least :data:`MIN_PERTURBATION` in absolute terms).
        reuse_tol: strain [-]: an RVE whose ∇u moved by at most this (every component) since
            it was last driven keeps its response instead of being stepped; 0: never.
        reuse_correction: "none" or "tangent" (a reused response corrected to first order).
        drive: "restart" (every trial from the committed state, Guo & Zhao) or "continue"
            (from the last trial state by the change of ∇u).
        max_strain_per_step: largest strain of one DEM step along ∇u [-] (Guo & Zhao: 1e-5).
        max_dem_steps: cap on one RVE path's DEM steps in one evaluation: a point whose path
            needs more is reported failed (Newton cuts back); None: no cap but 10¹⁵.
    """

    tangent: str = "objective"
    perturbation: float = 0.1
    reuse_tol: float = 0.0
    reuse_correction: str = "none"
    drive: str = "restart"
    max_strain_per_step: float = DEFAULT_STRAIN_PER_STEP
    max_dem_steps: int | None = DEFAULT_MAX_DEM_STEPS

    def __post_init__(self) -> None:
        # every field by its annotated type first (a string for a count, a number for the
        # device, 1.5 for a seed: a ParameterError naming it), then the ranges below
        conform_fields(self, skip=("packing", "initial_stress"))
        tangent_method(self.tangent)  # a ParameterError naming the tangent
        for name in ("perturbation", "max_strain_per_step"):
            value = getattr(self, name)
            if not (_finite(value) and value > 0):
                raise ParameterError(name, f"must be a finite number > 0, got {value!r}")
        if not (_finite(self.reuse_tol)
                and self.reuse_tol >= 0):
            raise ParameterError("reuse_tol", f"must be a finite strain >= 0 (0: off), got "
                                              f"{self.reuse_tol!r}")
        _one_of("reuse_correction", self.reuse_correction, REUSE_CORRECTIONS)
        _one_of("drive", self.drive, DRIVES)
        if self.drive == "continue" and self.tangent == "perturbation":
            raise ParameterError("drive", "'continue' does not combine with the "
                                          "'perturbation' tangent (its perturbed runs start "
                                          "from the committed state)")
        if self.max_dem_steps is not None:
            _count("max_dem_steps", self.max_dem_steps, 1, " or None")

    @property
    def method(self) -> TangentMethod:
        """The tangent as a strategy (what it costs, whether it can be held)."""
        return tangent_method(self.tangent)


@dataclass(frozen=True, kw_only=True)
class DEMRVEs(DEMDriving):
    """:class:`DEMDriving` and where the RVEs come from.

    Attributes:
        rve: RVE file (``.npz``, ``granular-material prepare``) holding one RVE (copied to
            every Gauss point) or one per Gauss point; None: prepare packings.
        particles: discs per prepared RVE (ignored with ``rve``); None: 400
            (:data:`~granular_material.reference_values.DEFAULT_DISCS`), in a run of the
            biaxial specimen its scale's.
        seed: seed of the first prepared RVE; RVE p uses seed + p (independent packings).
        isotropic: relax every RVE to the isotropic stress −confining I before the first
            load step (a packing consolidated by a normal stress servo keeps a shear stress:
            σxy ≈ −14 kPa for 64 discs, −7.7 kPa for 400, seed 1, at 100 kPa).
    """

    rve: Path | None = None
    particles: int | None = None
    seed: int = 1
    isotropic: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.rve is not None:
            object.__setattr__(self, "rve", Path(self.rve))
        _count("seed", self.seed, 0)


@dataclass(frozen=True, kw_only=True)
class DEMMaterialParameters(DEMRVEs):
    """Everything a :class:`~granular_material.multiscale.DEMMaterial` is made of: what its
    backends (in process, or every MPI rank) receive unchanged.

    Attributes:
        confining: isotropic pressure [Pa], > 0, compression positive, at which prepared
            RVEs are consolidated (then within what their contact law holds:
            :func:`~granular_material.procedures.packing.max_pressure` and
            :func:`~granular_material.procedures.packing.min_pressure`); also the scale of
            the :class:`~granular_material.multiscale.UnconfinedWarning`. Default 100 kPa.
        replicate: one RVE (the file's first, or one prepared with ``seed``) copied to every
            Gauss point; False: one independent RVE per point.
        device: "cpu", "cuda", "cuda:N" or None (CUDA when present).
        shards: CPU shards (threads) of the batch, per rank with the ``mpi`` backend, at
            most :data:`MAX_SHARDS` (a batch runs no more threads than RVEs); None: one per
            core (with ``mpi`` the cores of a node shared by its ranks). With 1, independent
            RVEs are also prepared one at a time.
        backend: "inprocess" (every RVE in this process) or "mpi" (contiguous shards on the
            ranks of an MPI job; the same results bit for bit).
        packing: the material of prepared RVEs (contact law, friction, damping, density,
            thickness) and how they are packed (radii, target void ratio e0); ignored with
            ``rve`` (the file carries its own). Default: Wu et al.'s Table 1.
        initial_stress: None (the RVEs start at the isotropic ``confining``), or the stress
            tensor σ* [Pa] every Gauss point starts at (a geostatic σv, σh = K0·σv, say):
            shape (n, 2, 2), tension positive, symmetric, both principal stresses < 0, n the
            points :meth:`~granular_material.multiscale.DEMMaterial.allocate` is given
            (checked there). Kept as nested tuples (the parameters compare and hash);
            :attr:`initial_stress_array` is the array. Each point's RVE (prepared, or the
            file's) is brought to its σ* (every component within 1 % of its σv, the shear
            included: :func:`~granular_material.procedures.servo.servo_to_stress`); targets
            below :func:`~granular_material.procedures.anisotropic.lowest_target_pressure`
            are clamped to it (see :mod:`granular_material.procedures.anisotropic`). Does
            not combine with ``isotropic``.
        share_tolerance: with ``initial_stress``: None, one RVE per point (independent
            packings unless ``replicate``); a fraction s >= 0: points whose targets agree
            within s of their σv share one preparation, brought to the midrange of their
            targets (each point's target then missed by at most s/2 of its σv more;
            :func:`~granular_material.procedures.anisotropic.group_targets`).
    """

    confining: float = DEFAULT_PRESSURE
    replicate: bool = False
    device: str | None = None
    shards: int | None = None
    backend: str = "inprocess"
    packing: PackingParameters = field(default_factory=PackingParameters)
    initial_stress: tuple[tuple[tuple[float, float], tuple[float, float]], ...] | None = None
    share_tolerance: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        _one_of("backend", self.backend, BACKENDS)
        self._check_initial_stress()
        if self.shards is not None:
            _count("shards", self.shards, 1, " or None")
            if self.shards > MAX_SHARDS:
                raise ParameterError("shards", f"must be at most {MAX_SHARDS} (a CPU thread "
                                               "each, each building its own DEM kernels; more "
                                               "than the cores never step faster), got "
                                               f"{self.shards!r}")
        if not isinstance(self.packing, PackingParameters):
            raise ParameterError("packing", f"must be PackingParameters, got {self.packing!r}")
        fewest = min_discs(self.packing.radius_range)
        particles = self.discs
        if isinstance(particles, bool) or int(particles) != particles or particles < fewest:
            raise ParameterError("particles", f"must be an integer >= {fewest} (the periodic "
                                              "cell must stay wider than twice the contact "
                                              f"cut-off), got {particles!r}")
        if not (_finite(self.confining) and self.confining > 0):
            raise ParameterError("confining", f"must be a positive number of Pa, got "
                                              f"{self.confining!r}")
        if self.rve is None and self.initial_stress is None:
            self._check_consolidation()
        if self.device is not None:
            try:
                from granular_material.dem import resolve_device  # warp: only when asked

                resolve_device(self.device)  # the engine's one device check
            except ValueError as exc:
                raise ParameterError("device", f"cannot be used: {exc}") from None

    def _check_consolidation(self) -> None:
        """Prepared packings are consolidated to ``confining``: within what their linear
        contact law holds. A disc of radius r carries about F = 2·p·r·t, so its contacts
        overlap δ/r ≈ 2·p·t/kn (:func:`~granular_material.procedures.packing.max_pressure`:
        at most :data:`~granular_material.procedures.packing.MAX_OVERLAP`, the void space
        gone near twice that), and the servo settles a packing only above
        :func:`~granular_material.procedures.packing.min_pressure`; ParameterErrors naming
        ``confining``."""
        meta, radii = self.packing.meta, self.packing.radius_range
        highest = max_pressure(meta, radii)
        if self.confining > highest:
            overlap = 2.0 * self.confining * meta.thickness / smallest_normal_stiffness(meta,
                                                                                         radii)
            raise ParameterError("confining", f"{self.confining:g} Pa would press the discs "
                                              f"{overlap:.3g} of their radius into each other "
                                              f"(2·p·thickness/kn); the linear contact law "
                                              f"holds to {MAX_OVERLAP:g}: at most "
                                              f"{highest:.4g} Pa with these stiffnesses")
        try:
            check_packing(self.discs, float(self.confining), meta, radii,
                          names={**PACKING_NAMES, "pressure": "confining",
                                 "n_disc": "particles"})
        except ValueError as exc:
            raise ParameterError("confining", f"(prepared packings): {exc}") from None

    def _check_initial_stress(self) -> None:
        """``initial_stress`` as nested tuples of compressive symmetric tensors, and
        ``share_tolerance``; ParameterErrors naming them."""
        share = self.share_tolerance
        if share is not None and not (_finite(share)
                                      and share >= 0):
            raise ParameterError("share_tolerance", f"must be None or a finite fraction >= 0, "
                                                    f"got {share!r}")
        if self.initial_stress is None:
            return
        if self.isotropic:
            raise ParameterError("initial_stress", "does not combine with isotropic (which "
                                                   "relaxes every RVE to -confining I)")
        try:
            given = np.asarray(self.initial_stress, dtype=np.float64)
        except (TypeError, ValueError, OverflowError) as exc:
            raise ParameterError("initial_stress", f"must be an array of shape (n, 2, 2) "
                                                   f"[Pa]: {exc}") from None
        if given.ndim != 3 or given.shape[1:] != (2, 2) or given.shape[0] < 1:
            raise ParameterError("initial_stress", f"must be an array of shape (n, 2, 2) [Pa], "
                                                   f"one tensor per Gauss point, got shape "
                                                   f"{given.shape}")
        from granular_material.procedures.servo import check_stress_targets  # the DEM's

        check_stress_targets(given, len(given), "initial_stress")
        object.__setattr__(self, "initial_stress",
                           tuple(tuple(tuple(float(v) for v in row) for row in tensor)
                                 for tensor in given))

    @property
    def initial_stress_array(self) -> np.ndarray | None:
        """``initial_stress`` as an array (n, 2, 2) [Pa], or None."""
        if self.initial_stress is None:
            return None
        return np.array(self.initial_stress, dtype=np.float64)

    @property
    def discs(self) -> int:
        """Discs per prepared RVE: ``particles``, else 400."""
        return DEFAULT_DISCS if self.particles is None else self.particles

    @property
    def pressure(self) -> float:
        """Deprecated name of :attr:`confining` [Pa]."""
        return self.confining
