"""Memory a piece of work will need, told before it is allocated: how much the system can
give now, a size in words, and the refusal of a request that cannot be met (a base module:
the commands' checks, :mod:`granular_material.checks`, and the materials' ``allocate`` use
it alike)."""

from __future__ import annotations

import contextlib
import os

__all__ = ["MEMORY_LIMIT", "available_memory", "memory_refusal", "size_in_words"]

#: a request for more memory than this is refused whatever the machine [bytes]: 1 TiB
MEMORY_LIMIT = 2**40


def size_in_words(n_bytes: float) -> str:
    """``n_bytes`` in words: 12.3 GB, 4.1 TB, 2e+25 B."""
    if not n_bytes < 1e21:  # NaN and inf too
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


def memory_refusal(needed: float, what: str, available: int | None) -> str | None:
    """Why ``what`` (in words), which needs about ``needed`` bytes, cannot be allocated with
    ``available`` bytes free (None: unknown): beyond :data:`MEMORY_LIMIT`, which no machine
    this runs on has, or beyond what is available; None where it fits."""
    if not needed <= MEMORY_LIMIT:  # NaN and inf too
        return (f"{what} needs about {size_in_words(needed)} of memory, more than the "
                f"{size_in_words(MEMORY_LIMIT)} any run may take; ask for less")
    if available is not None and needed > available:
        return (f"{what} needs about {size_in_words(needed)} of memory; this machine has "
                f"{size_in_words(available)} available now; ask for less")
    return None
