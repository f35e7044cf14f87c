"""The one way library code shows progress: a tqdm bar on stderr, or nothing."""

from __future__ import annotations

from tqdm.auto import tqdm

__all__ = ["progress_bar"]


def progress_bar(total: int, desc: str, enabled: bool, unit: str = "step") -> tqdm:
    """A progress bar of ``total`` units on stderr; a silent one when not ``enabled``.

    Use it as a context manager (``with progress_bar(...) as bar: bar.update()``), so the
    bar is closed however the loop ends.
    """
    return tqdm(total=total, desc=desc, unit=unit, disable=not enabled)
