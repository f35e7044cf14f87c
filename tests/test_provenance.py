"""The commit a report records: the package's checkout's, marked when it is not clean, and
``unknown`` for a package that is no checkout's own files."""

from __future__ import annotations

import subprocess

import pytest

from granular_material import provenance


def _git(folder, *args):
    return subprocess.run(["git", "-c", "user.email=t@example.org", "-c", "user.name=t",
                           *args], cwd=folder, capture_output=True, text=True,
                          check=True).stdout.strip()


@pytest.fixture
def checkout(tmp_path, monkeypatch):
    """A git repository whose ``pkg/__init__.py`` is committed, as the package's folder."""
    package = tmp_path / "repo" / "pkg"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("x = 1\n")
    _git(package.parent, "init", "-q")
    _git(package.parent, "add", ".")
    _git(package.parent, "commit", "-q", "-m", "one")
    monkeypatch.setattr(provenance, "_HERE", package)
    return package


def test_a_clean_checkout_gives_its_commit(checkout):
    assert provenance.code_commit() == _git(checkout, "rev-parse", "--short", "HEAD")


def test_uncommitted_changes_are_marked(checkout):
    (checkout / "__init__.py").write_text("x = 2\n")
    commit = _git(checkout, "rev-parse", "--short", "HEAD")
    assert provenance.code_commit() == f"{commit}+dirty"
    assert provenance.code_commit("HEAD~0") == commit  # another revision: no mark


def test_untracked_package_or_no_repository_is_unknown(tmp_path, monkeypatch):
    loose = tmp_path / "site-packages" / "pkg"
    loose.mkdir(parents=True)
    (loose / "__init__.py").write_text("")
    monkeypatch.setattr(provenance, "_HERE", loose)
    assert provenance.code_commit() == "unknown"  # no repository at all
    _git(tmp_path, "init", "-q")  # a repository around it that does not track it
    assert provenance.code_commit() == "unknown"
