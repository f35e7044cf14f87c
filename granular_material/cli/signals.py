"""Stop signals as Ctrl-C: SIGTERM and SIGHUP raise :class:`Terminated` (a
``KeyboardInterrupt``) while a command runs, and the shell's exit code of a stopped command."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

__all__ = ["Terminated", "interrupt_exit_code", "stop_signals_as_interrupt"]


class Terminated(KeyboardInterrupt):
    """SIGTERM (a batch scheduler's or ``timeout``'s stop) or SIGHUP (a closed terminal or
    ssh session), raised where Ctrl-C raises ``KeyboardInterrupt``, so that every command
    stops on it as on Ctrl-C; ``signum`` is the signal's number."""

    signum: int = int(signal.SIGTERM)


#: the signals other than Ctrl-C that stop a command as Ctrl-C does
_STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP")
                      if hasattr(signal, name))


#: set once a stop signal has been raised in the block of :func:`stop_signals_as_interrupt`
_STOPPING = {"now": False}


def _raise_terminated(signum: int, frame: object) -> None:
    if _STOPPING["now"]:  # the command is stopping already: let it write what it keeps
        return
    _STOPPING["now"] = True
    exc = Terminated(f"signal {signal.Signals(signum).name}")
    exc.signum = int(signum)
    raise exc


def _raise_interrupt(signum: int, frame: object) -> None:
    if _STOPPING["now"]:
        return
    _STOPPING["now"] = True
    raise KeyboardInterrupt


#: how long after a stop lost in a finaliser it is sent again [s]
_RESEND_S = 0.05


def _resend_lost_stop(previous: Callable[[Any], object]) -> Callable[[Any], object]:
    """A ``sys.unraisablehook`` that sends a stop signal again when its exception was raised
    where Python cannot raise one (a ``__del__`` or a weakref callback run by the garbage
    collector, which print "Exception ignored in" and go on): without it the run would go on
    and, the stop being marked as under way, ignore every later signal. The signal comes
    back from a thread a moment later, once the finaliser has returned."""

    def hook(unraisable: Any) -> object:
        lost = unraisable.exc_value
        if isinstance(lost, KeyboardInterrupt) and _STOPPING["now"]:
            _STOPPING["now"] = False
            signum = int(getattr(lost, "signum", signal.SIGINT))
            threading.Timer(_RESEND_S, os.kill, (os.getpid(), signum)).start()
            return None
        return previous(unraisable)

    return hook


@contextlib.contextmanager
def stop_signals_as_interrupt() -> Iterator[None]:
    """While the block runs, SIGTERM and SIGHUP raise :class:`Terminated` (a
    ``KeyboardInterrupt``) in the main thread, as Ctrl-C does; the previous handlers come
    back afterwards. Only the first stop signal is raised: the ones after it (a storm of
    SIGTERMs, Ctrl-C pressed again) are ignored while the command writes what it keeps and
    ends; a stop whose exception a finaliser swallowed is sent again
    (:func:`_resend_lost_stop`). A no-op outside the main thread, where Python cannot
    install signal handlers.
    (A signal ignored when the process started, as ``nohup`` does with SIGHUP and a shell
    with a background job's SIGINT, stays ignored.)"""
    handlers = {signum: _raise_terminated for signum in _STOP_SIGNALS}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        handlers[signal.SIGINT] = _raise_interrupt
    previous = {}
    try:
        for signum, handler in handlers.items():
            if signum == signal.SIGTERM or signal.getsignal(signum) is not signal.SIG_IGN:
                previous[signum] = signal.signal(signum, handler)
    except ValueError:  # not the main thread
        yield
        return
    _STOPPING["now"] = False
    unraisable = sys.unraisablehook
    sys.unraisablehook = _resend_lost_stop(unraisable)
    try:
        yield
    finally:
        sys.unraisablehook = unraisable
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        _STOPPING["now"] = False


def interrupt_exit_code(exc: KeyboardInterrupt) -> int:
    """The shell's exit code of a command stopped by ``exc``: 128 + the signal number (130 for
    Ctrl-C, 143 for SIGTERM, 129 for SIGHUP), looked up through interrupts raised ``from``
    another."""
    cause: BaseException | None = exc
    while cause is not None and not isinstance(cause, Terminated):
        cause = cause.__cause__
    return 128 + (cause.signum if isinstance(cause, Terminated) else int(signal.SIGINT))
