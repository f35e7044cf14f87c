"""The commit a report records: the project's checkout's, marked when it is not clean, and
``unknown`` for a package that no checkout of this project holds."""

from __future__ import annotations

import subprocess

import pytest

from granular_material import provenance


def _git(folder, *args):
    return subprocess.run(["git", "-c", "user.email=t@example.org", "-c", "user.name=t",
                           *args], cwd=folder, capture_output=True, text=True,
                          check=True).stdout.strip()


@pytest.fixture
def checkout(tmp_path):
    """A repository that tracks this project's ``granular_material/provenance.py``."""
    package = tmp_path / "repo" / "granular_material"
    package.mkdir(parents=True)
    (package / "provenance.py").write_text("x = 1\n")
    _git(package.parent, "init", "-q")
    _git(package.parent, "add", ".")
    _git(package.parent, "commit", "-q", "-m", "one")
    return package


def test_a_clean_checkout_gives_its_commit(checkout, monkeypatch):
    monkeypatch.setattr(provenance, "_HERE", checkout)
    assert provenance.code_commit() == _git(checkout, "rev-parse", "--short", "HEAD")


def test_uncommitted_changes_are_marked(checkout, monkeypatch):
    monkeypatch.setattr(provenance, "_HERE", checkout)
    (checkout / "provenance.py").write_text("x = 2\n")
    commit = _git(checkout, "rev-parse", "--short", "HEAD")
    assert provenance.code_commit() == f"{commit}+dirty"
    assert provenance.code_commit("HEAD~0") == commit  # another revision: no mark


def test_a_copy_installed_inside_the_checkout_gives_the_checkout(checkout, monkeypatch):
    """As tox installs the package: built from the checkout, into a folder inside it."""
    installed = checkout.parent / ".tox" / "site-packages" / "granular_material"
    installed.mkdir(parents=True)
    monkeypatch.setattr(provenance, "_HERE", installed)
    assert provenance.code_commit() == _git(checkout, "rev-parse", "--short", "HEAD")


def test_no_repository_or_another_projects_is_unknown(tmp_path, monkeypatch):
    installed = tmp_path / "venv" / "site-packages" / "granular_material"
    installed.mkdir(parents=True)
    monkeypatch.setattr(provenance, "_HERE", installed)
    assert provenance.code_commit() == "unknown"  # no repository at all
    (tmp_path / "own.py").write_text("")
    _git(tmp_path, "init", "-q")  # a user's repository with the environment inside it
    _git(tmp_path, "add", "own.py")
    _git(tmp_path, "commit", "-q", "-m", "theirs")
    assert provenance.code_commit() == "unknown"
