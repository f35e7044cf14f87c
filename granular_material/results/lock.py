"""One writer per output folder: an advisory lock (``fcntl.flock``) on a file in it.

The lock is taken before anything is written in the folder and is released when the run
ends, or by the operating system when the process dies (``kill -9`` included), so a stale
lock file never blocks a later run. The file holds the holder's process id, which a refused
run names.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

__all__ = ["LOCK_NAME", "FolderLock", "FolderLockedError"]

#: the lock file in the folder
LOCK_NAME = ".granular-material.lock"

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no lock
    fcntl = None  # type: ignore[assignment]


class FolderLockedError(ValueError):
    """The folder is being written by another run (its process id in the message)."""


class FolderLock:
    """The lock of ``folder``: :meth:`acquire` (making the folder, and remembering which
    folders it made) and :meth:`release` (removing the lock file, and the folders it made
    when nothing else is in them)."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self._fd: int | None = None
        self._made: list[Path] = []

    @property
    def held(self) -> bool:
        """Whether this object holds the lock."""
        return self._fd is not None

    def _holder(self) -> str:
        try:
            pid = self.path.read_text().strip()
        except OSError:
            pid = ""
        return f"pid {pid}" if pid.isdigit() else "a process that has not written its pid yet"

    def acquire(self) -> None:
        """Take the lock now, or raise :class:`FolderLockedError` naming the folder and the
        holder's pid (the folder is then left as it was)."""
        if self._fd is not None or fcntl is None:
            return
        path = self.folder
        while not path.exists() and path.parent != path:
            self._made.append(path)
            path = path.parent
        self.folder.mkdir(parents=True, exist_ok=True)
        for _ in range(100):  # the file may be replaced while we wait: take the one there
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                raise FolderLockedError(f"{self.folder} is being written by another run "
                                   f"({self._holder()}); wait for it to end or stop it "
                                   "(one run at a time may write a folder)") from None
            except OSError:
                os.close(fd)
                raise
            try:
                same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)  # its holder removed it as we opened it: lock the new one
        else:  # pragma: no cover - a file replaced a hundred times over
            raise FolderLockedError(f"{self.folder}: its lock file keeps changing")
        self._fd = fd
        try:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
        except OSError as exc:
            self.release()
            raise OSError(exc.errno, f"cannot write {self.path}: {exc.strerror}") from exc

    def release(self) -> None:
        """Remove the lock file and let the lock go; remove the folders :meth:`acquire`
        made, where nothing else is in them (a run refused before it wrote anything)."""
        if self._fd is None:
            return
        with contextlib.suppress(OSError):
            if os.stat(self.path).st_ino == os.fstat(self._fd).st_ino:
                self.path.unlink()
        os.close(self._fd)
        self._fd = None
        for path in self._made:  # deepest first
            with contextlib.suppress(OSError):
                path.rmdir()
        self._made = []

    def __enter__(self) -> FolderLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
