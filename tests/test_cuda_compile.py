"""Every kernel module the engine can launch compiles for CUDA (sm_90), without a GPU.

warp's ahead-of-time compiler generates the CUDA source of a module and compiles it to PTX
with the NVRTC bundled in warp's library, so a CUDA compile error fails this test on any
machine, GPU or not. Each module is compiled into a fresh folder (never from a cache).
"""

from __future__ import annotations

import importlib
import pkgutil
import re
from pathlib import Path

import pytest
import warp as wp

from granular_material.dem.condensed import cg_kernels as condensed_cg_kernels
from granular_material.dem.condensed import device_kernels as condensed_device_kernels
from granular_material.dem.kernels.block import BLOCK_THREADS
from granular_material.dem.kernels.sets import DTYPES, STEP_VARIANTS, kernel_modules

ARCH = 90  #: Hopper (H100, H200)

wp.init()
_RUNTIME = wp._src.context.runtime
pytestmark = pytest.mark.skipif(
    not _RUNTIME.is_cuda_enabled or ARCH not in (_RUNTIME.nvrtc_supported_archs or ()),
    reason=f"this warp build cannot compile CUDA for sm_{ARCH} (no NVRTC)",
)

#: the packages whose warp kernels must all be covered by ``kernel_modules``
PACKAGES = ("granular_material", "granular_material_pore_fractal",
            "granular_material_reproduction", "granular_material_validation")


def _all_modules() -> dict[str, wp.Module]:
    """The engine's modules (every float type and step variant) and the condensed tangent's
    CG and device assembly (float64 only: the CG's relative residual of 1e-10 is below
    float32's resolution)."""
    return {**kernel_modules(), **condensed_cg_kernels.kernel_modules(),
            **condensed_device_kernels.kernel_modules()}


def _base_name(name: str) -> str:
    """A module's name with the replica number left out (replicas hold the same code)."""
    return re.sub(r"_r\d+(?=_|$)", "_r*", name)


def test_kernel_modules_cover_every_variant_and_kernel():
    modules = kernel_modules()
    # per float type the step's variants and the block path's module
    assert len(modules) == len(DTYPES) * (len(STEP_VARIANTS) + 1) == 18
    assert {name for name in modules if "_block_" in name} == {
        f"granular_material_dem_block_{dtype}_r0" for dtype in DTYPES}
    for name, module in modules.items():
        kernels = [k for k in module.kernels.values()
                   if not k.is_generic or k.overloads]
        assert kernels, f"{name} holds no compilable kernel"
        assert all(len(k.overloads) == 1 for k in module.kernels.values() if k.is_generic), \
            f"{name}: a generic kernel with no or several overloads"


def test_every_warp_module_of_the_project_is_compiled():
    """A kernel module added anywhere in the project (an ``@wp.kernel`` in a new file) must
    join :func:`_all_modules`, or this test names it."""
    for package in PACKAGES:
        root = importlib.import_module(package)
        for info in pkgutil.walk_packages(root.__path__, prefix=package + "."):
            if info.name.endswith("__main__"):
                continue
            importlib.import_module(info.name)
    covered = {_base_name(name) for name in _all_modules()}
    ours = {
        _base_name(name) for name, module in wp._src.context.user_modules.items()
        if name.startswith("granular_material") and module.kernels
    }
    assert ours <= covered, f"kernel modules not compiled by this test: {sorted(ours - covered)}"


@pytest.mark.parametrize("name", sorted(_all_modules()))
def test_module_compiles_to_ptx_for_sm90(name: str, tmp_path: Path):
    module = _all_modules()[name]
    paths = wp.compile_aot_module(module, arch=ARCH, use_ptx=True, module_dir=tmp_path)
    assert len(paths) == 1 and paths[0].suffix == ".ptx" and f"sm{ARCH}" in paths[0].name
    ptx = paths[0].read_text()
    assert f".target sm_{ARCH}" in ptx
    entries = set(re.findall(r"\.entry\s+(\w+)\(", ptx))
    for kernel in module.kernels.values():
        # every kernel of the module (its one overload where generic), forward only
        assert any(entry.startswith(kernel.key) and entry.endswith("_cuda_kernel_forward")
                   for entry in entries), f"{kernel.key} missing from the PTX of {name}"
    if "_block_" in name:
        # the block path: compiled for its blocks, its tiles in shared memory, and the
        # block's barriers in the code
        assert module.options["block_dim"] == BLOCK_THREADS
        assert "dynamic_smem_base" in ptx and "bar.sync" in ptx
