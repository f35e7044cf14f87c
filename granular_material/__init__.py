"""granular-material: multiscale FEM x DEM simulation of granular geomaterials.

Layers, bottom up, each importing only from those below it (docs/design.md#layout):
:mod:`granular_material.dem` (batched periodic DEM on warp, homogenisation) beside
:mod:`granular_material.fem` (materials, boundary-value problems, the Newton solver),
:mod:`granular_material.procedures` (strain paths, servo, packings, element tests),
:mod:`granular_material.multiscale` (the DEM material),
:mod:`granular_material.results` (tables, writers, plots, localisation, summaries),
:mod:`granular_material.runs` (run specifications and ``run``),
:mod:`granular_material.studies` (the trade study) and
:mod:`granular_material.cli` (the ``granular-material`` command line).

warp is silent in the library: its start-up banner ("Warp 1.x initialized ...") and its
module-load lines ("Module ... load on device 'cpu' took ...") go to stdout, so importing
this package keeps warp at log level WARNING, whenever warp is imported (before or after this
package). Its native library also writes "Warp CUDA warning: Could not find or load the
NVIDIA CUDA driver" to stderr as the runtime starts on a machine without a GPU; that line is
dropped too (a run that asks for CUDA there is refused by the library with its own message).
Opt in with :func:`verbose` (``granular_material.verbose(True)``) or the environment variable
``GRANULAR_MATERIAL_VERBOSE=1``; warp's other warnings and errors are always shown.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import os
import sys
import tempfile
from types import ModuleType
from typing import Any

__version__ = "0.1.0"
__all__ = ["__version__", "verbose"]

#: environment variable that, set to 1 (true, yes), lets warp print its banner and loads
VERBOSE_VARIABLE = "GRANULAR_MATERIAL_VERBOSE"

_verbose = os.environ.get(VERBOSE_VARIABLE, "").strip().lower() in ("1", "true", "yes", "on")


def verbose(on: bool = True) -> bool:
    """Let warp print its banner and module-load lines (``on=True``) or silence them again
    (``False``, the default state of the library); returns the previous setting. Takes effect
    at once if warp is loaded, else when it is."""
    global _verbose
    previous, _verbose = _verbose, bool(on)
    if "warp" in sys.modules:
        _configure_warp(sys.modules["warp"])
    return previous


#: the native library's line on a machine without a CUDA driver, dropped unless verbose
_NO_DRIVER_LINE = "Could not find or load the NVIDIA CUDA driver"


def _without_driver_warning(start: Any) -> Any:
    """warp's ``Runtime.__init__`` with the file descriptor 2 captured while it runs: the
    no-driver line (:data:`_NO_DRIVER_LINE`) is dropped unless verbose, every other line is
    written back to stderr."""

    def start_quietly(runtime: Any, *args: Any, **kwargs: Any) -> None:
        if _verbose:
            start(runtime, *args, **kwargs)
            return
        try:
            if sys.stderr is not None:
                sys.stderr.flush()
            saved = os.dup(2)
        except (OSError, ValueError):  # no stderr to capture (closed): nothing to drop either
            start(runtime, *args, **kwargs)
            return
        with tempfile.TemporaryFile() as captured:
            os.dup2(captured.fileno(), 2)
            try:
                start(runtime, *args, **kwargs)
            finally:
                os.dup2(saved, 2)
                os.close(saved)
                captured.seek(0)
                lines = captured.read().decode(errors="replace").splitlines(keepends=True)
                kept = "".join(line for line in lines if _NO_DRIVER_LINE not in line)
                if kept and sys.stderr is not None:
                    sys.stderr.write(kept)
                    sys.stderr.flush()

    start_quietly.__wrapped__ = start  # type: ignore[attr-defined]
    return start_quietly


def _configure_warp(wp: ModuleType) -> None:
    """warp's log level as :func:`verbose` says (INFO when verbose, else WARNING), and its
    runtime's start without the no-driver line (:func:`_without_driver_warning`)."""
    config = getattr(wp, "config", None)
    if config is None:
        return
    context = sys.modules.get("warp._src.context") or sys.modules.get("warp.context")
    runtime = getattr(context, "Runtime", None)
    if runtime is not None and not hasattr(runtime.__init__, "__wrapped__"):
        runtime.__init__ = _without_driver_warning(runtime.__init__)
    if hasattr(wp, "LOG_WARNING"):  # warp >= 1.10
        config.log_level = getattr(wp, "LOG_INFO", 20) if _verbose else wp.LOG_WARNING
    else:  # older warp
        config.quiet = not _verbose


def _configuring(exec_module: Any) -> Any:
    """``exec_module`` followed by :func:`_configure_warp` of the module it executed."""

    def exec_and_configure(module: ModuleType) -> None:
        exec_module(module)
        _configure_warp(module)

    return exec_and_configure


class _WarpImportHook(importlib.abc.MetaPathFinder):
    """Configures warp (:func:`_configure_warp`) as soon as its module has been executed,
    before any kernel is loaded or the runtime initialised (which is when warp prints)."""

    def find_spec(self, fullname: str, path: Any, target: Any = None
                  ) -> importlib.machinery.ModuleSpec | None:
        if fullname != "warp":
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(fullname, path, target)
            if spec is not None and spec.loader is not None:
                spec.loader.exec_module = _configuring(  # type: ignore[method-assign]
                    spec.loader.exec_module)
                return spec
        return None


if "warp" in sys.modules:
    _configure_warp(sys.modules["warp"])
elif not any(isinstance(f, _WarpImportHook) for f in sys.meta_path):
    sys.meta_path.insert(0, _WarpImportHook())

from granular_material.moved_modules import install as _install_moved_modules  # noqa: E402

_install_moved_modules()
