"""Every file the library writes goes through its one whole-file writer (issue 47): no module
of the core package or of the pore-fractal plugin writes a file in place (``write_text``,
``to_csv`` to a path, ``savefig``, ``open(..., "w")`` ...) outside a writer callback of
:func:`granular_material.filesafe.write_whole` (a ``lambda tmp: ...``, or a function whose
parameter is ``tmp``). An in-place write cut by a full disk or a kill leaves a partial or
empty file where a whole one was."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = [ROOT / "granular_material", ROOT / "plugins" / "pore_fractal"]
#: methods that write a file named by their first argument
WRITING_METHODS = {"write_text", "write_bytes", "to_csv", "savefig", "savez",
                   "savez_compressed", "to_json", "to_parquet", "dump"}
#: (module, call) that write into memory or a terminal, not a file, and why
NOT_FILES = {
    ("granular_material/runs/checkpoint_files.py", "savez"): "into an io.BytesIO, then "
                                                             "written whole",
    ("granular_material/cli/options.py", "dump"): "the JSON report to sys.stdout",
}


def _in_writer_callback(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> bool:
    while node in parents:
        node = parents[node]
        if isinstance(node, ast.Lambda):
            return True
        if isinstance(node, ast.FunctionDef):
            return any(a.arg == "tmp" for a in node.args.args)
    return False


def _writes(path: Path) -> list[tuple[int, str]]:
    """The in-place file writes of the module at ``path``: (line, call)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        if isinstance(func, ast.Attribute) and func.attr in WRITING_METHODS:
            name = func.attr
            if name in ("to_csv", "to_json") and not node.args and not any(
                    k.arg == "path_or_buf" for k in node.keywords):
                continue  # returns the text: no file
            if name == "dump" and len(node.args) < 2:
                continue
        elif isinstance(func, ast.Name) and func.id == "open":
            name = "open"
            mode = node.args[1] if len(node.args) > 1 else next(
                (k.value for k in node.keywords if k.arg == "mode"), None)
            if not (isinstance(mode, ast.Constant) and set(str(mode.value)) & set("wax+")):
                continue
        else:
            continue
        if not _in_writer_callback(node, parents):
            found.append((node.lineno, name))
    return found


def _modules() -> list[Path]:
    return sorted(p for package in PACKAGES for p in package.rglob("*.py"))


@pytest.mark.parametrize("module", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_writes_a_file_in_place(module):
    relative = str(module.relative_to(ROOT))
    writes = [(line, call) for line, call in _writes(module)
              if (relative, call) not in NOT_FILES]
    assert not writes, (f"{relative} writes in place at "
                        + ", ".join(f"line {line} ({call})" for line, call in writes)
                        + ": write through granular_material.filesafe.write_whole")


def test_the_scan_finds_an_in_place_write(tmp_path):
    module = tmp_path / "bad.py"
    module.write_text("def f(path, text, frame):\n"
                      "    path.write_text(text)\n"
                      "    frame.to_csv(path)\n"
                      "    write_whole(path, lambda tmp: tmp.write_text(text))\n"
                      "    with open(path, 'a') as fh:\n"
                      "        fh.write(text)\n")
    assert _writes(module) == [(2, "write_text"), (3, "to_csv"), (5, "open")]
