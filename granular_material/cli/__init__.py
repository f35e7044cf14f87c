"""The ``granular-material`` command line: the core commands plus plugin commands.

The core commands are registered by :mod:`granular_material.cli.commands`: ``prepare``,
``biaxial-dem`` and ``dem-drive`` (:mod:`granular_material.cli.dem`), ``single-element`` and
``biaxial`` (:mod:`granular_material.cli.fem`), ``run`` (:mod:`granular_material.cli.scene`:
one of them described by a TOML scene file), ``trade-study``
(:mod:`granular_material.cli.study`) and ``calibrate``
(:mod:`granular_material.cli.calibrate`); their shared options are defined once in
:mod:`granular_material.cli.options`, the stop signals in
:mod:`granular_material.cli.signals`. Plugins add sub-commands through the
``granular_material.commands`` entry-point group; each entry point is a
``register(subparsers)`` callable that adds its parsers and sets ``func`` (a callable taking
the parsed arguments and returning the exit code). warp prints nothing on stdout (which
``--json`` keeps for the report): the package keeps it quiet
(:func:`granular_material.verbose`).
"""

from __future__ import annotations

import contextlib
import signal
import sys
import warnings
from collections.abc import Iterator
from typing import Any

from granular_material.cli.commands import (
    COMMAND_GROUP,
    COMMAND_HELP,
    build_parser,
    command_parser,
    names_a_command,
)
from granular_material.cli.signals import interrupt_exit_code, stop_signals_as_interrupt

__all__ = ["COMMAND_GROUP", "COMMAND_HELP", "UsageError", "build_parser", "command_parser",
           "entry", "main"]


def __getattr__(name: str) -> Any:  # UsageError, imported only when asked for (it is heavy)
    if name == "UsageError":
        from granular_material.cli.options import UsageError

        return UsageError
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: exit codes of a command stopped by a signal (SIGHUP, Ctrl-C, SIGTERM)
_STOPPED_CODES = frozenset({128 + 1, 128 + 2, 128 + 15})


def _named(exc: BaseException) -> str:
    """The message of ``exc``; a library's ParameterError with its fields named as options
    (:func:`~granular_material.cli.options.message_of`)."""
    from granular_material.cli.options import message_of

    return message_of(exc)


def _usage_error() -> type[Exception]:
    from granular_material.cli.options import UsageError

    return UsageError


@contextlib.contextmanager
def _renamed_as_warnings(command: str) -> Iterator[None]:
    """While the command runs, an old name it reads (a
    :class:`~granular_material.vocabulary.RenamedWarning`: an option, scene key or spec field
    renamed) is said once on stderr as ``granular-material COMMAND: warning: ...``, naming
    options (``run``: the keys of its file); other warnings are shown as Python shows
    them."""
    from granular_material.vocabulary import RenamedWarning

    with warnings.catch_warnings():
        shown = warnings.showwarning

        def show(message: Any, category: type[Warning], *rest: Any, **kw: Any) -> None:
            if issubclass(category, RenamedWarning):
                from granular_material.cli.options import as_flags

                # its fields named as options, or, read from a file (a scene or a spec,
                # whose keys are the fields' names), as keys
                text = (str(message).replace("`", "'") if command == "run"
                        else as_flags(str(message)))
                print(f"granular-material {command}: warning: {text}", file=sys.stderr)
            else:
                shown(message, category, *rest, **kw)

        warnings.simplefilter("default", RenamedWarning)
        warnings.showwarning = show
        yield


def entry() -> None:
    """The process's entry point (console script, ``python -m``): :func:`main`, then exit
    with its code. A command stopped by a signal ignores the stop signals of a storm that
    arrive after its reports, until the process has exited (they would kill it by the
    signal, without its exit code)."""
    code = main()
    if code in _STOPPED_CODES:
        for name in ("SIGTERM", "SIGHUP"):
            if hasattr(signal, name):
                signal.signal(getattr(signal, name), signal.SIG_IGN)
    sys.exit(code)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (2 for bad input, 1 for a failed run,
    130/143 for a run stopped by Ctrl-C/SIGTERM)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not names_a_command(argv):  # --help, --version or nothing: no command to import
        command_parser().parse_args(argv)
    from granular_material.cli.stored_help import asks_for_help, print_stored

    option = asks_for_help(argv)  # a command's help: stored, the command not imported
    if option is not None and print_stored(argv[0], option):
        raise SystemExit(0)
    parser = build_parser(argv[0])
    if option == "--help-all" and not getattr(parser.commands.get(argv[0]), "_advanced", 1):
        argv = ["--help" if a == option else a for a in argv]  # all its options are shown
    args = parser.parse_args(argv)
    with stop_signals_as_interrupt(), _renamed_as_warnings(args.command):
        try:  # the reports below too: a later signal is ignored
            return int(args.func(args) or 0)
        except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM that the command did not catch
            code = interrupt_exit_code(exc)
            what = ("interrupted" if code == 130 else
                    f"terminated ({signal.Signals(code - 128).name})")
            print(f"granular-material {args.command}: {what} before its outputs "
                  "were complete", file=sys.stderr)
            return code
        except (_usage_error(), ValueError, OSError) as exc:
            print(f"granular-material {args.command}: error: {_named(exc)}", file=sys.stderr)
            return 2
        except RuntimeError as exc:  # e.g. DEMInstabilityError naming the RVEs
            print(f"granular-material {args.command}: failed: {exc}", file=sys.stderr)
            return 1
