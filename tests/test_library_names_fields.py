"""The library names fields, the command line names flags (issue 43): no module of the
package outside ``granular_material/cli/`` spells a command-line flag (``--rve``) in a string
it builds (an error message, a default naming what set a value, a list of given options);
it raises :class:`~granular_material.errors.ParameterError` naming the field, and the command
line shows the field as its flag in one place (``cli.options.flag_of`` / ``shown``)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from granular_material.cli.options import UsageError, check_output_dir, shown
from granular_material.errors import ParameterError

PACKAGE = Path(__file__).resolve().parents[1] / "granular_material"
#: a flag as a user types it: two dashes and a lowercase word, not inside a longer word
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
#: calls whose string arguments are another program's options (git's), not ours
FOREIGN_CALLS = frozenset({"_git"})
#: modules not yet converted, each with why (the lead's): an entry here is a known debt
PENDING: dict[str, str] = {}


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the string constants that stand alone as statements (docstrings, attribute
    docstrings): prose, which may show a command line."""
    return {id(node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)}


def _foreign(tree: ast.AST) -> set[int]:
    """ids of the constants passed to another program's command line."""
    return {id(arg) for node in ast.walk(tree)
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id in FOREIGN_CALLS for arg in node.args}


def flags_spelled(source: str) -> list[tuple[int, str]]:
    """(line, flag) of every command-line flag the module's code spells in a string: a
    constant, or an f-string that puts ``--`` before a formatted name."""
    tree = ast.parse(source)
    skip = _docstrings(tree) | _foreign(tree)
    found = []
    for node in ast.walk(tree):
        if (isinstance(node, ast.Constant) and isinstance(node.value, str)
                and id(node) not in skip):
            found += [(node.lineno, flag) for flag in FLAG.findall(node.value)]
        if isinstance(node, ast.JoinedStr):
            for part, after in zip(node.values, node.values[1:], strict=False):
                if (isinstance(part, ast.Constant) and str(part.value).endswith("--")
                        and isinstance(after, ast.FormattedValue)):
                    found.append((node.lineno, "--{...}"))
    return found


def _library_modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py")
                  if p.relative_to(PACKAGE).parts[0] != "cli")


def test_no_library_module_spells_a_flag() -> None:
    spelled = {}
    for path in _library_modules():
        name = path.relative_to(PACKAGE).as_posix()
        found = flags_spelled(path.read_text())
        if found and name not in PENDING:
            spelled[name] = found
    assert spelled == {}, ("library modules name command-line flags; raise "
                           f"ParameterError(field, message) instead: {spelled}")


@pytest.mark.parametrize("name", sorted(PENDING))
def test_a_pending_module_is_still_pending(name) -> None:
    """An entry of PENDING goes once its module names no flag (the list only shrinks)."""
    assert flags_spelled((PACKAGE / name).read_text()), f"{name} is clean: drop it from PENDING"


def test_the_scan_finds_flags_in_messages_and_built_names() -> None:
    source = ('def f(x):\n    """--shown in prose is fine."""\n'
              '    raise ValueError(f"--rve {x} does not exist")\n'
              'def g(name):\n    return f"--{name}"\n'
              '_git("rev-parse", "--short")\n')
    assert sorted(flags_spelled(source)) == [(3, "--rve"), (5, "--{...}")]


def test_a_field_is_shown_as_its_flag_on_the_command_line(tmp_path) -> None:
    error = ParameterError("reuse_tol", "0.01 needs `convergence` force, `radius_min` = 0.2")
    assert str(error) == "reuse_tol 0.01 needs `convergence` force, `radius_min` = 0.2"
    assert shown(error) == "--reuse-tol 0.01 needs --convergence force, --radius-min 0.2"
    (tmp_path / "file").write_text("")
    with pytest.raises(UsageError, match=r"^--out .*file exists and is not a folder$"):
        check_output_dir(tmp_path / "file")
    with pytest.raises(UsageError, match=r"^--plots .*file exists and is not a folder$"):
        check_output_dir(tmp_path / "file", "--plots")
