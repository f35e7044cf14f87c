"""The parser class of every command: an ``argparse.ArgumentParser`` that keeps the arguments
added to it, in order, so that the scenes read a command's options (their type, choices,
default, help) from the parser, not from argparse's private attributes.

Nothing but argparse's public methods is used: ``add_argument`` returns the action it made,
and ``add_argument_group``, ``add_mutually_exclusive_group`` and ``add_subparsers`` return
what the arguments are then added to. The sub-command parsers of a :class:`CommandParser`
(``subparsers.add_parser``, the plugins' commands included) are CommandParsers too.
Arguments a parser takes over from ``parents=`` are not recorded (no command uses it).

A command's ``--help`` shows the options a first run needs; the groups added with
``advanced=True`` (the solver's knobs, the RVEs' material, ...) are listed by title and
count, their options shown by ``--help-all``."""

from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = ["CommandParser", "HelpAll"]


class HelpAll(argparse.Action):
    """``--help-all``: the full help, every group's options, then exit."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS,
                 default: str = argparse.SUPPRESS, help: str | None = None) -> None:
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0,
                         help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        parser.print_help_all()  # type: ignore[attr-defined]
        parser.exit()


class _KeepEpilogLines:
    """Mixed into a parser's formatter: the epilog's list of advanced groups keeps its lines."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if text.startswith("more options, shown by --help-all:"):
            listed, _, rest = text.partition("\n\n")
            return "\n".join(indent + line for line in listed.splitlines()) + (
                "\n\n" + super()._fill_text(rest, width, indent)  # type: ignore[misc]
                if rest else "")
        return super()._fill_text(text, width, indent)  # type: ignore[misc]


class CommandParser(argparse.ArgumentParser):
    """An argument parser that records its arguments: :attr:`arguments` holds the action of
    every argument (option, positional, ``--help``, sub-commands) added to it or to one of
    its argument groups, in the order they were added; :attr:`commands` its sub-command
    parsers by name."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        #: every argument's action, in order (set first: ``__init__`` adds ``--help``)
        self.arguments: list[argparse.Action] = []
        self._subcommands: argparse._SubParsersAction | None = None
        #: the argument groups whose options only ``--help-all`` shows
        self._advanced: list[Any] = []
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

    def add_argument_group(self, *args: Any, advanced: bool = False, **kwargs: Any) -> Any:
        """``ArgumentParser.add_argument_group``; what is added to the group is recorded.
        ``advanced``: its options are left out of ``--help`` (which names the group) and
        shown by ``--help-all``, added with the first such group."""
        group = super().add_argument_group(*args, **kwargs)
        if advanced:
            if not self._advanced:
                self._record(super().add_argument(
                    "--help-all", action=HelpAll,
                    help="show every option, the advanced groups' too"))
            self._advanced.append(group)
        return self._recording(group)

    def format_help(self) -> str:
        """The help without the advanced groups' options: their titles and how many options
        each holds, after the others (:meth:`format_help_all`: everything)."""
        if not self._advanced:
            return super().format_help()
        hidden = [(group, group.description, [(a, a.help) for a in group._group_actions])
                  for group in self._advanced]
        epilog, usage = self.epilog, self.usage
        if usage is None:  # every option would be listed: the short form instead
            self.usage = "%(prog)s [-h] [--help-all] [options]"
        lines = [f"  {group.title} ({len(actions)})" for group, _, actions in hidden]
        self.epilog = ("more options, shown by --help-all:\n" + "\n".join(lines)
                       + (f"\n\n{epilog}" if epilog else ""))
        formatter_class = self.formatter_class
        self.formatter_class = type("KeepEpilogLines", (_KeepEpilogLines, formatter_class), {})
        try:
            for group, _, actions in hidden:
                group.description = None
                for action, _ in actions:
                    action.help = argparse.SUPPRESS
            return super().format_help()
        finally:
            self.epilog, self.usage, self.formatter_class = epilog, usage, formatter_class
            for group, description, actions in hidden:
                group.description = description
                for action, text in actions:
                    action.help = text

    def format_help_all(self) -> str:
        """The full help: every option of every group."""
        return super().format_help()

    def print_help_all(self, file: Any = None) -> None:
        """Print :meth:`format_help_all` (on stdout by default)."""
        self._print_message(self.format_help_all(), file or sys.stdout)

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
