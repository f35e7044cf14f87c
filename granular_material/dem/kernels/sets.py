"""warp kernels of the batched periodic disc DEM, generic in the float type.

Every particle array is flat, index ``i = b·N + j`` for disc j of RVE b; per-RVE arrays have
length B; per-slot arrays have length B·N·K (slot ``i·K + k`` is disc i's k-th neighbour).
Positions are fractional, ``s = H⁻¹x`` in [0, 1)², so particles follow the cell's homogeneous
deformation (YADE's homoDeform); velocities are the fluctuation about the affine field
``L·x``, and spins the fluctuation about the cell's spin ``(L₁₀ − L₀₁)/2``, so that a rigid
rotation of the cell is a rigid rotation of the packing (objectivity).

Each contact is computed once per step: the lists are full (j is in i's list iff i is in
j's, at slot ``contact_mirror_slot``), but only the lower index of a pair (its *owner*)
evaluates the force law and keeps the tangential history, writing the pair's force to both
of its slots; every disc then sums its own slots in list order (no atomics on forces,
deterministic, and the same sums in the same order as when each disc evaluated all of its
pairs).

A step is ``contact_forces`` → ``integrate`` (gather, damping, leap-frog) → optionally
``servo`` → ``advance_cell_and_check`` (cell update, and whether the next step must rebuild
the lists); a rebuild is ``begin_build`` → ``fill_bins`` → ``build_lists`` → ``commit_lists``.
On the CPU, where a kernel's threads run one after the other, ``step_serial`` (a thread per
RVE) does the work of the first two in one pass, with the same sums. The block path
(``kernels_block.step_block``, :func:`block_kernels_for`) does a whole step, servo and cell
update included, with one thread block an RVE, many steps a launch.
The kernels are plain functions in ``kernels_lists``, ``kernels_step`` and
``kernels_measures``; :func:`kernels_for` makes one warp module of them per float type and
replica (see there), each specialised to the float type before the module is built.

A scene that makes a term of the step irrelevant need not pay for it: ``contact_forces``,
``integrate`` and ``step_serial`` test the compile-time flags ``TANGENTIAL``, ``DAMPING`` and
``STRESS`` of ``kernels_step`` through ``wp.static``, and :func:`step_kernels_for` builds, for
a :class:`StepFeatures` other than the generic one, copies of the three kernels that see other
values (no tangential force, history or torque; no local damping; no stress sums) as a module
of their own, built on first use only. A variant gives the generic kernels' results bit for
bit (up to the sign of zeros) on the scenes it is made for.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from types import FunctionType
from typing import Any

import warp as wp

from granular_material.dem.kernels import DTYPES
from granular_material.dem.kernels import step as kernels_step
from granular_material.dem.kernels.block import BLOCK_THREADS, block_pending, step_block
from granular_material.dem.kernels.lists import (
    any_rebuild,
    begin_build,
    build_lists,
    check_lists,
    commit_lists,
    fill_bins,
    link_lists,
)
from granular_material.dem.kernels.measures import contact_measures, reduce_measures
from granular_material.dem.kernels.step import (
    advance_cell_and_check,
    contact_forces,
    integrate,
    servo,
    step_serial,
)

__all__ = [
    "DTYPES",
    "GENERIC_STEP",
    "STEP_VARIANTS",
    "BlockKernels",
    "KernelSet",
    "StepFeatures",
    "StepKernels",
    "block_kernels_for",
    "kernel_modules",
    "kernels_for",
    "launch",
    "step_kernels_for",
]


_KERNELS = (
    check_lists, any_rebuild, begin_build, fill_bins, build_lists, commit_lists, link_lists,
    contact_forces, integrate, step_serial, servo, advance_cell_and_check, contact_measures,
    reduce_measures,
)


@dataclass(frozen=True)
class KernelSet:
    """The kernels of one warp module (one replica); attributes named as the functions."""

    check_lists: wp.Kernel
    any_rebuild: wp.Kernel
    begin_build: wp.Kernel
    fill_bins: wp.Kernel
    build_lists: wp.Kernel
    commit_lists: wp.Kernel
    link_lists: wp.Kernel
    contact_forces: wp.Kernel
    integrate: wp.Kernel
    step_serial: wp.Kernel
    servo: wp.Kernel
    advance_cell_and_check: wp.Kernel
    contact_measures: wp.Kernel
    reduce_measures: wp.Kernel


#: what each generic argument of the kernels holds: a scalar, vec2, vec3, mat22 or mat44 of the
#: float type (scalar arguments are passed in the float type; arrays hold these dtypes)
_ROLES = {
    "scalar": ("skin", "cutoff", "damping", "thickness", "gain", "max_strain", "timestep",
               "friction", "radius", "inv_mass", "inv_inertia", "angular_velocity",
               "contact_shear_force", "shear_new"),
    "vec2": ("fractional_position", "velocity", "verlet_displacement", "pair_branch",
             "part_stiffness", "target", "part_counts", "part_forces",
             "counts", "forces"),
    "mat22": ("cell", "cell_at_list_build", "velocity_gradient", "step_map", "part_stress",
              "part_fabric", "stress", "fabric"),
    "vec3": ("pair", "disc_load"),
    "mat44": ("part_tangent", "tangent"),
}


def _concrete_types(kernel: wp.Kernel, ft: Any) -> dict[str, Any]:
    """The concrete type of every generic argument of ``kernel`` for float type ``ft``."""
    dtypes = {"scalar": ft, "vec2": wp.types.vector(2, ft), "vec3": wp.types.vector(3, ft),
              "mat22": wp.types.matrix((2, 2), ft), "mat44": wp.types.matrix((4, 4), ft)}
    role_of = {name: role for role, names in _ROLES.items() for name in names}
    types = {}
    for arg in kernel.adj.args:
        is_array = wp.types.is_array(arg.type)
        if (arg.type.dtype if is_array else arg.type) is not Any:
            continue
        if arg.label not in role_of:
            raise TypeError(f"kernel {kernel.key}: generic argument {arg.label!r} has no entry "
                            "in kernels._ROLES (scalar, vec2, vec3, mat22 or mat44)")
        dtype = dtypes[role_of[arg.label]]
        types[arg.label] = wp.array(dtype=dtype) if is_array else dtype
    return types


def _kernel(function: Callable, module: str, ft: Any) -> wp.Kernel:
    """``function`` as a kernel of warp module ``module``, specialised to float type ``ft``."""
    kernel = wp.kernel(function, module=module, enable_backward=False)
    types = _concrete_types(kernel, ft)
    if types:
        wp.overload(kernel, types)
    return kernel


@cache
def kernels_for(dtype: str = "float64", replica: int = 0) -> KernelSet:
    """The kernels for ``dtype`` ("float64" or "float32") as warp module ``replica``, each
    specialised to the float type before the module is first built (so it builds once).

    On x86-64 a CPU module keeps a static pointer to the running launch's tile storage, so
    two threads must never run kernels of the same module at once: every CPU thread steps
    with its own replica.
    """
    ft = {"float64": wp.float64, "float32": wp.float32}[dtype]
    module = f"granular_material_dem_{dtype}_r{replica}"
    return KernelSet(**{f.__name__: _kernel(f, module, ft) for f in _KERNELS})


@dataclass(frozen=True)
class StepFeatures:
    """What ``contact_forces`` and ``integrate`` compute (compile-time flags).

    Attributes:
        tangential: the tangential force, its history and the torques (False: every RVE is
            frictionless, μ = 0; the history is kept at zero).
        damping: YADE's local damping (False: damping 0).
        stress: the stress sums for the servo where ``with_stress`` asks at run time (False:
            never, no servo runs).
    """

    tangential: bool = True
    damping: bool = True
    stress: bool = True

    @property
    def tag(self) -> str:
        """A name for the variant: "generic", or the terms it leaves out."""
        left_out = [name for name, kept in (("tangential", self.tangential),
                                            ("damping", self.damping),
                                            ("stress", self.stress)) if not kept]
        return "no_" + "_".join(left_out) if left_out else "generic"


GENERIC_STEP = StepFeatures()  #: every term, as in :func:`kernels_for`'s module
#: every combination of the flags, the generic one first
STEP_VARIANTS = tuple(StepFeatures(tangential, damping, stress)
                      for tangential in (True, False) for damping in (True, False)
                      for stress in (True, False))


@dataclass(frozen=True)
class StepKernels:
    """``contact_forces``, ``integrate`` and ``step_serial`` of one :class:`StepFeatures`
    (same arguments as the generic ones)."""

    contact_forces: wp.Kernel
    integrate: wp.Kernel
    step_serial: wp.Kernel


def _with_flags(function: Callable, flags: dict[str, bool]) -> Callable:
    """A copy of ``function`` (same code) whose globals hold ``flags`` in place of those of
    ``kernels_step``: what its ``wp.static`` tests read when warp builds it."""
    copy = FunctionType(function.__code__, {**function.__globals__, **flags},
                              function.__name__, function.__defaults__, function.__closure__)
    copy.__qualname__ = function.__qualname__
    copy.__module__ = function.__module__
    copy.__doc__ = function.__doc__
    copy.__annotations__ = dict(function.__annotations__)
    return copy


@cache
def step_kernels_for(dtype: str = "float64", replica: int = 0,
                     features: StepFeatures = GENERIC_STEP) -> StepKernels:
    """The step kernels of ``features`` for ``dtype`` and ``replica``: the generic ones are
    those of :func:`kernels_for`; any other variant is a warp module of its own (three
    kernels), built when first launched."""
    if features == GENERIC_STEP:
        ks = kernels_for(dtype, replica)
        return StepKernels(ks.contact_forces, ks.integrate, ks.step_serial)
    ft = {"float64": wp.float64, "float32": wp.float32}[dtype]
    module = f"granular_material_dem_{dtype}_r{replica}_{features.tag}"
    flags = {"TANGENTIAL": features.tangential, "DAMPING": features.damping,
             "STRESS": features.stress}
    assert set(flags) <= set(vars(kernels_step))  # the names the kernels test
    return StepKernels(
        contact_forces=_kernel(_with_flags(contact_forces, flags), module, ft),
        integrate=_kernel(_with_flags(integrate, flags), module, ft),
        step_serial=_kernel(_with_flags(step_serial, flags), module, ft),
    )


@dataclass(frozen=True)
class BlockKernels:
    """The block path's kernels (:mod:`~.kernels_block`): ``step_block``, launched tiled
    with ``BLOCK_THREADS`` threads an RVE, and ``block_pending``."""

    step_block: wp.Kernel
    block_pending: wp.Kernel


@cache
def block_kernels_for(dtype: str = "float64", replica: int = 0) -> BlockKernels:
    """The block path's kernels for ``dtype`` as a warp module of their own per replica
    (as :func:`kernels_for`), generic in the step's terms (:data:`GENERIC_STEP`), compiled
    for blocks of ``BLOCK_THREADS`` threads (on the CPU for the width a launch resolves
    to)."""
    ft = {"float64": wp.float64, "float32": wp.float32}[dtype]
    module = f"granular_material_dem_block_{dtype}_r{replica}"
    kernels = BlockKernels(step_block=_kernel(step_block, module, ft),
                           block_pending=_kernel(block_pending, module, ft))
    kernels.step_block.module.options["block_dim"] = BLOCK_THREADS
    return kernels


def kernel_modules(replica: int = 0) -> dict[str, wp.Module]:
    """Every warp module the engine can launch, for ``replica``, by name: per float type
    the generic module of :func:`kernels_for`, the module of each other variant of
    :data:`STEP_VARIANTS` and the block path's module (:func:`block_kernels_for`); created,
    not built (e.g. for an ahead-of-time compile)."""
    modules = {}
    for dtype in DTYPES:
        for features in STEP_VARIANTS:
            module = step_kernels_for(dtype, replica, features).contact_forces.module
            modules[module.name] = module
        module = block_kernels_for(dtype, replica).step_block.module
        modules[module.name] = module
    return modules


def launch(kernel: wp.Kernel, dim: int, device: str, record: bool = False,
           block_dim: int | None = None, **arguments: Any) -> wp.Launch | None:
    """Launch ``kernel`` with its arguments by name (all of them, no others); with
    ``record`` return the recorded launch instead, to be replayed by ``.launch()``; with
    ``block_dim`` launch it tiled, ``dim`` blocks of ``block_dim`` threads (on the CPU one
    thread a block unless ``warp.config.enable_cpu_blocks``)."""
    names = [arg.label for arg in kernel.adj.args]
    if set(names) != set(arguments):
        missing = sorted(set(names) - set(arguments))
        unknown = sorted(set(arguments) - set(names))
        raise TypeError(f"{kernel.key}: missing arguments {missing}, unknown {unknown}")
    inputs = [arguments[n] for n in names]
    if block_dim is not None:
        return wp.launch_tiled(kernel, dim=[dim], inputs=inputs, device=device,
                               block_dim=block_dim, record_cmd=record)
    return wp.launch(kernel, dim=dim, inputs=inputs, device=device, record_cmd=record)
