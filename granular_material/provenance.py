"""Which code produced a result: the git commit of the checkout this package runs from,
for the reports, studies and benchmarks that record it."""

from __future__ import annotations

import subprocess
from pathlib import Path

__all__ = ["code_commit"]

#: the folder git is asked in: the package's own
_HERE = Path(__file__).resolve().parent
#: a file every checkout of this project tracks (this module), relative to its top
_OWN_FILE = "granular_material/provenance.py"


def _git(*args: str) -> str | None:
    """Standard output of ``git args`` run in the package's folder; None where it fails
    (no git, not inside a repository)."""
    try:
        done = subprocess.run(["git", *args], capture_output=True, text=True, cwd=_HERE,
                              timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip()


def code_commit(rev: str = "HEAD") -> str:
    """The short commit of ``rev`` in the checkout of this project that the package runs
    from (an editable install, or a copy installed inside the checkout, as tox does); for
    ``HEAD`` with ``+dirty`` when the checkout's tracked files differ from it (the result
    then came from uncommitted code). ``unknown`` where the repository around the package is
    none or another project's (a virtual environment inside a user's own repository)."""
    top = _git("rev-parse", "--show-toplevel")
    if not top or _git("-C", top, "ls-files", "--error-unmatch", _OWN_FILE) is None:
        return "unknown"
    commit = _git("rev-parse", "--short", rev)
    if not commit:
        return "unknown"
    if rev == "HEAD" and _git("status", "--porcelain", "--untracked-files=no"):
        commit += "+dirty"
    return commit
