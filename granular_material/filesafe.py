"""Files written whole or not at all, by every layer (the DEM's RVE files, checkpoints,
tables, figures, XDMF).

:func:`write_whole` writes a file under a temporary name (``NAME.part``) and renames it into
place; a failed write removes the ``.part`` and raises an ``OSError`` that names the file
(a full disk says which file it cut). Ctrl-C, SIGTERM and SIGHUP that arrive while the file
is written and renamed are held back and delivered right after, so a storm of signals never
leaves a half-written or empty file, nor a ``.part``.
"""

from __future__ import annotations

import contextlib
import errno
import os
import signal
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

__all__ = ["deferred_signals", "write_whole"]

#: the signals that stop a command (Ctrl-C, SIGTERM, a closed terminal)
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                     if hasattr(signal, name))


@contextlib.contextmanager
def deferred_signals(deliver: bool = True) -> Iterator[None]:
    """Hold back the stop signals while the block runs: one that comes is recorded, and its
    handler (the one in place before the block) runs when the block ends, or it is dropped
    (``deliver`` False). Signals that are ignored stay ignored. A no-op outside the main
    thread, where Python runs no handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []

    def hold(signum: int, frame: object) -> None:
        pending.append(signum)

    previous = {}
    for signum in STOP_SIGNALS:
        handler = signal.getsignal(signum)
        if handler is not None and handler is not signal.SIG_IGN:
            previous[signum] = signal.signal(signum, hold)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if pending and deliver:
            handler = previous[pending[0]]
            if callable(handler):
                handler(pending[0], None)
            else:  # the default action (stop the process), as it would have been
                signal.raise_signal(pending[0])


def write_whole(path: str | Path, write: Callable[[Path], object]) -> Path:
    """Write ``path`` whole or not at all: ``write(tmp)`` writes the content to the
    temporary file ``tmp`` (``path.part``), which then replaces ``path``. A failed write
    leaves ``path`` as it was and no ``.part``; an ``OSError`` names ``path``."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    if tmp.is_dir() and not tmp.is_symlink():
        raise IsADirectoryError(errno.EISDIR, f"cannot write {path}: {tmp} is a folder in "
                                              "the way (remove it)")
    with deferred_signals():
        try:
            write(tmp)
            os.replace(tmp, path)
        except OSError as exc:
            if exc.filename == str(path) or (exc.filename is None and str(path) in str(exc)
                                             and str(tmp) not in str(exc)):
                raise
            if exc.errno is None:
                raise OSError(f"cannot write {path}: {exc}") from exc
            raise OSError(exc.errno, f"cannot write {path}: {exc.strerror or exc}") from exc
        finally:
            tmp.unlink(missing_ok=True)  # only there when writing or replacing failed
    return path
