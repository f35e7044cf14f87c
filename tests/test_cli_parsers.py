"""The command parsers record their arguments: exactly what argparse holds, in its order."""

from __future__ import annotations

import argparse

import pytest

from granular_material.cli import build_parser
from granular_material.cli.parsers import CommandParser


def _walk(parser: CommandParser, name: str) -> list[tuple[str, CommandParser]]:
    found = [(name, parser)]
    for command, sub in parser.commands.items():
        found += _walk(sub, f"{name} {command}".strip())
    return found


@pytest.mark.parametrize("command", [None, "biaxial", "run"])
def test_every_command_parser_records_what_argparse_holds(command: str | None) -> None:
    """Every parser of the tree (plugins' and nested sub-commands included) is a
    CommandParser whose ``arguments`` are argparse's own actions, in the same order."""
    parsers = _walk(build_parser(command), "")
    assert len(parsers) > 1
    for name, parser in parsers:
        assert isinstance(parser, CommandParser), name
        assert parser.arguments == parser._actions, name


def test_groups_and_nested_sub_commands_are_recorded() -> None:
    parser = CommandParser(prog="p")
    group = parser.add_argument_group("g")
    a = group.add_argument("--a", type=int)
    exclusive = group.add_mutually_exclusive_group()
    b = exclusive.add_argument("--b", action="store_true")
    c = parser.add_mutually_exclusive_group().add_argument("--c")
    sub = parser.add_subparsers(dest="command")
    child = sub.add_parser("child")
    d = child.add_argument("d")
    assert parser.arguments == parser._actions
    assert [x for x in parser.arguments if x.dest in "abc"] == [a, b, c]
    assert parser.commands == {"child": child} and isinstance(child, CommandParser)
    assert child.arguments[-1] is d
    assert parser.parse_args(["--a", "2", "--b", "child", "x"]).d == "x"


def test_sub_commands_of_another_parser_class_are_refused() -> None:
    with pytest.raises(TypeError, match="CommandParsers"):
        CommandParser().add_subparsers(parser_class=argparse.ArgumentParser)
