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
The kernels are plain functions in ``kernels_lists``, ``kernels_step`` and
``kernels_measures``; :func:`kernels_for` makes one warp module of them per float type and
replica (see there), each specialised to the float type before the module is built.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

import warp as wp

from granular_material.dem.kernels_lists import (
    any_rebuild,
    begin_build,
    build_lists,
    check_lists,
    commit_lists,
    fill_bins,
    link_lists,
)
from granular_material.dem.kernels_measures import contact_measures, reduce_measures
from granular_material.dem.kernels_step import (
    advance_cell_and_check,
    contact_forces,
    integrate,
    servo,
)

__all__ = [
    "KernelSet",
    "kernels_for",
    "launch",
]

_KERNELS = (
    check_lists, any_rebuild, begin_build, fill_bins, build_lists, commit_lists, link_lists,
    contact_forces, integrate, servo, advance_cell_and_check, contact_measures,
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
    "vec3": ("pair",),
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
    kernels = {}
    for function in _KERNELS:
        kernel = wp.kernel(function, module=module, enable_backward=False)
        types = _concrete_types(kernel, ft)
        if types:
            wp.overload(kernel, types)
        kernels[function.__name__] = kernel
    return KernelSet(**kernels)


def launch(kernel: wp.Kernel, dim: int, device: str, record: bool = False,
           **arguments: Any) -> wp.Launch | None:
    """Launch ``kernel`` with its arguments by name (all of them, no others); with
    ``record`` return the recorded launch instead, to be replayed by ``.launch()``."""
    names = [arg.label for arg in kernel.adj.args]
    if set(names) != set(arguments):
        missing = sorted(set(names) - set(arguments))
        unknown = sorted(set(arguments) - set(names))
        raise TypeError(f"{kernel.key}: missing arguments {missing}, unknown {unknown}")
    return wp.launch(kernel, dim=dim, inputs=[arguments[n] for n in names], device=device,
                     record_cmd=record)
