"""The documentation site builds with no warning (Sphinx, ``-W --keep-going``), as ``tox -e docs``.

It reads every page under docs/ and imports every module of the API reference, so a broken
link between pages, a page left out of the navigation or a docstring Sphinx cannot read fails
here. Skipped, saying what is missing, where the docs toolchain (the ``docs`` extra) is not
installed; CI installs it (tox's ``py`` environment).
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"
MISSING = [m for m in ("sphinx", "myst_parser", "furo") if importlib.util.find_spec(m) is None]


@pytest.mark.skipif(bool(MISSING), reason="the docs toolchain is not installed ("
                    + ", ".join(MISSING) + "): pip install '.[docs]'")
def test_docs_build_without_warnings(tmp_path):
    env = dict(os.environ, MPLBACKEND="Agg")
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
           "-d", str(tmp_path / "doctrees"), str(DOCS), str(tmp_path / "html")]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=900)
    assert proc.returncode == 0, f"sphinx-build failed:\n{proc.stderr[-8000:]}"
    for page in ("index", "getting-started", "cli", "python-api", "physics", "performance",
                 "validation", "api/runs", "reproduction/report"):
        assert (tmp_path / "html" / f"{page}.html").is_file(), page
