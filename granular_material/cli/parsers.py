"""The parser class of every command: an ``argparse.ArgumentParser`` that keeps the arguments
added to it, in order, so that the scenes read a command's options (their type, choices,
default, help) from the parser, not from argparse's private attributes.

Nothing but argparse's public methods is used: ``add_argument`` returns the action it made,
and ``add_argument_group``, ``add_mutually_exclusive_group`` and ``add_subparsers`` return
what the arguments are then added to. The sub-command parsers of a :class:`CommandParser`
(``subparsers.add_parser``, the plugins' commands included) are CommandParsers too.
Arguments a parser takes over from ``parents=`` are not recorded (no command uses it)."""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["CommandParser"]


class CommandParser(argparse.ArgumentParser):
    """An argument parser that records its arguments: :attr:`arguments` holds the action of
    every argument (option, positional, ``--help``, sub-commands) added to it or to one of
    its argument groups, in the order they were added; :attr:`commands` its sub-command
    parsers by name."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        #: every argument's action, in order (set first: ``__init__`` adds ``--help``)
        self.arguments: list[argparse.Action] = []
        self._subcommands: argparse._SubParsersAction | None = None
        super().__init__(*args, **kwargs)

    def _record(self, action: argparse.Action) -> argparse.Action:
        self.arguments.append(action)
        return action

    def _recording(self, group: Any) -> Any:
        """``group`` (an argument group of this parser) with what is added to it, and to the
        groups made from it, recorded here."""
        add_argument = group.add_argument
        add_group = group.add_argument_group
        add_exclusive = group.add_mutually_exclusive_group

        def recorded_argument(*args: Any, **kwargs: Any) -> argparse.Action:
            return self._record(add_argument(*args, **kwargs))

        group.add_argument = recorded_argument
        group.add_argument_group = lambda *a, **k: self._recording(add_group(*a, **k))
        group.add_mutually_exclusive_group = \
            lambda **k: self._recording(add_exclusive(**k))
        return group

    def add_argument(self, *args: Any, **kwargs: Any) -> argparse.Action:
        """``ArgumentParser.add_argument``, its action recorded."""
        return self._record(super().add_argument(*args, **kwargs))

    def add_argument_group(self, *args: Any, **kwargs: Any) -> Any:
        """``ArgumentParser.add_argument_group``; what is added to the group is recorded."""
        return self._recording(super().add_argument_group(*args, **kwargs))

    def add_mutually_exclusive_group(self, **kwargs: Any) -> Any:
        """``ArgumentParser.add_mutually_exclusive_group``; its arguments are recorded."""
        return self._recording(super().add_mutually_exclusive_group(**kwargs))

    def add_subparsers(self, **kwargs: Any) -> Any:
        """``ArgumentParser.add_subparsers``, its action recorded; its parsers are of this
        class (a ``parser_class`` that is no CommandParser is refused)."""
        parser_class = kwargs.setdefault("parser_class", type(self))
        if not (isinstance(parser_class, type) and issubclass(parser_class, CommandParser)):
            raise TypeError(f"the sub-command parsers of a CommandParser are CommandParsers, "
                            f"not {parser_class!r}")
        action = super().add_subparsers(**kwargs)
        self._subcommands = action
        return self._record(action)

    @property
    def commands(self) -> dict[str, CommandParser]:
        """The sub-command parsers by name (empty: the parser has no sub-commands)."""
        return {} if self._subcommands is None else dict(self._subcommands.choices)
