"""Names of a module imported on first use (PEP 562), so that importing a package or module
does not load what only some of its names need (warp, the DEM) until one of them is used."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_names"]


def lazy_names(module: str, homes: Mapping[str, str], namespace: dict[str, Any], *,
               submodules: bool = False) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The ``__getattr__`` and ``__dir__`` of ``module`` (its ``__name__``), whose names
    ``homes`` (name -> the module that defines it) are imported on first use and kept in
    ``namespace`` (the module's ``globals()``); with ``submodules``, any other name is tried
    as a submodule of the package ``module``."""

    def module_getattr(name: str) -> Any:
        home = homes.get(name)
        if home is None:
            if not submodules or name.startswith("__"):
                raise AttributeError(f"module {module!r} has no attribute {name!r}")
            try:
                return importlib.import_module(f"{module}.{name}")
            except ModuleNotFoundError as exc:
                if exc.name != f"{module}.{name}":
                    raise
                raise AttributeError(f"module {module!r} has no attribute {name!r}") from None
        value = getattr(importlib.import_module(home), name)
        namespace[name] = value
        return value

    def module_dir() -> list[str]:
        return sorted({*namespace, *homes})

    return module_getattr, module_dir
