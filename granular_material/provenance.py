"""Which code produced a result: the git commit of the checkout this package runs from,
for the reports, studies and benchmarks that record it."""

from __future__ import annotations

import subprocess
from pathlib import Path

__all__ = ["code_commit"]

#: the folder git is asked in: the package's own, inside its checkout
_HERE = Path(__file__).resolve().parent


def _git(*args: str) -> str | None:
    """Standard output of ``git args`` run in the package's folder; None where it fails
    (no git, not a checkout: an installed wheel)."""
    try:
        done = subprocess.run(["git", *args], capture_output=True, text=True, cwd=_HERE,
                              timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip()


def code_commit(rev: str = "HEAD") -> str:
    """The short commit of ``rev`` in this package's checkout; for ``HEAD`` with ``+dirty``
    when tracked files differ from it (the result then came from uncommitted code), and
    ``unknown`` where the package is not a checkout's own files (an installed wheel)."""
    # the package's own files tracked: not a copy installed inside some other checkout
    if _git("ls-files", "--error-unmatch", "__init__.py") is None:
        return "unknown"
    commit = _git("rev-parse", "--short", rev)
    if not commit:
        return "unknown"
    if rev == "HEAD" and _git("status", "--porcelain", "--untracked-files=no"):
        commit += "+dirty"
    return commit
