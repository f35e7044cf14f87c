"""Every name the documentation tells a user to import imports (README, docs/, the API
reference's modules), and every module that moved keeps its old name for one release, as the
very module that moved, with a DeprecationWarning."""

from __future__ import annotations

import importlib
import re
import sys
import warnings
from pathlib import Path

import pytest

from granular_material.moved_modules import MOVED

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*.md")
                                     if "_build" not in p.parts)]
FROM_IMPORT = re.compile(r"^\s*from\s+(granular_material[\w.]*)\s+import\s+"
                         r"(\([^)]*\)|[^\n#]+)", re.M)
AUTOMODULE = re.compile(r"\.\. automodule:: (granular_material[\w.]*)")


def _documented() -> list[tuple[str, str]]:
    """(module, name) of every ``from granular_material... import name`` on the pages, and
    (module, "") of every module the API reference documents."""
    found = set()
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for module, names in FROM_IMPORT.findall(text):
            for name in re.split(r"[,\s()]+", names):
                if name and name != "as" and re.fullmatch(r"[A-Za-z_]\w*", name):
                    found.add((module, name))
        found.update((module, "") for module in AUTOMODULE.findall(text))
    return sorted(found)


DOCUMENTED = _documented()


def test_the_pages_document_names() -> None:
    # the reader must find what it checks
    assert ("granular_material.runs", "run") in DOCUMENTED
    assert ("granular_material.fem.materials.mohr_coulomb", "") in DOCUMENTED
    assert len(DOCUMENTED) > 100


@pytest.mark.parametrize(("module", "name"), DOCUMENTED)
def test_a_documented_name_imports(module: str, name: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)  # no page names an old path
        imported = importlib.import_module(module)
    if name:
        assert hasattr(imported, name) or importlib.util.find_spec(f"{module}.{name}"), \
            f"{module} has no {name}"


@pytest.mark.parametrize("old", sorted(MOVED))
def test_a_moved_module_keeps_its_old_name(old: str) -> None:
    new = importlib.import_module(f"granular_material.{MOVED[old]}")
    sys.modules.pop(f"granular_material.{old}", None)  # an earlier import of the old name
    with pytest.warns(DeprecationWarning, match=f"granular_material.{MOVED[old]}"):
        aliased = importlib.import_module(f"granular_material.{old}")
    assert aliased is new
