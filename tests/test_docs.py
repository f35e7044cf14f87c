"""The documentation site builds with no warning (Sphinx, ``-W --keep-going``), as ``tox -e docs``,
and reads offline.

It reads every page under docs/ and imports every module of the API reference, so a broken
link between pages, a page left out of the navigation or a docstring Sphinx cannot read fails
here. The built HTML must show its equations without a script or the network (MathML written
at build time by docs/_ext/mathml.py) and load nothing from another host. Skipped, saying what
is missing, where the docs toolchain (the ``docs`` extra) is not installed; CI installs it
(tox's ``py`` environment).
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"
MISSING = [m for m in ("sphinx", "myst_parser", "furo", "latex2mathml")
           if importlib.util.find_spec(m) is None]
pytestmark = pytest.mark.skipif(bool(MISSING), reason="the docs toolchain is not installed ("
                                + ", ".join(MISSING) + "): pip install '.[docs]'")

#: an element or a style rule that makes the browser fetch something: a script, a style sheet,
#: an image, a frame, a font (an ``<a href>`` to another site is a link, not a fetch)
FETCHES = re.compile(r"<(?:script|link|img|iframe|source|embed)\b[^>]*?\b(?:src|href)\s*=\s*"
                     r"[\"']?([^\"'\s>]+)|url\(\s*[\"']?([^\"')\s]+)|@import\s+[\"']([^\"']+)",
                     re.IGNORECASE)
#: TeX left for a script to typeset: MathJax's delimiters as Sphinx writes them
RAW_TEX = re.compile(r"\\\(|\\\)|\\\[|\\\]|\$\$")


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site built once, as ``tox -e docs`` builds it; its HTML folder."""
    out = tmp_path_factory.mktemp("docs")
    env = dict(os.environ, MPLBACKEND="Agg")
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
           "-d", str(out / "doctrees"), str(DOCS), str(out / "html")]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=900)
    assert proc.returncode == 0, f"sphinx-build failed:\n{proc.stderr[-8000:]}"
    return out / "html"


def test_docs_build_without_warnings(site):
    for page in ("index", "getting-started", "cli", "python-api", "physics", "performance",
                 "validation", "api/runs", "reproduction/report"):
        assert (site / f"{page}.html").is_file(), page


def _external(url: str) -> bool:
    return bool(re.match(r"(?:[a-z][a-z0-9+.-]*:)?//", url, re.IGNORECASE))


def test_pages_show_math_and_fetch_nothing_from_the_network(site):
    pages = sorted(site.rglob("*.html"))
    assert len(pages) > 20
    raw, fetched, math = [], [], 0
    for page in pages:
        text = page.read_text(encoding="utf-8")
        body = re.sub(r"<pre\b.*?</pre>", "", text, flags=re.DOTALL)  # code may show TeX
        raw += [f"{page.relative_to(site)}: {m.group(0)}" for m in RAW_TEX.finditer(body)]
        fetched += [f"{page.relative_to(site)}: {url}" for m in FETCHES.finditer(text)
                    for url in m.groups() if url and _external(url)]
        math += text.count("<math ")
    for sheet in site.rglob("*.css"):
        text = sheet.read_text(encoding="utf-8", errors="replace")
        fetched += [f"{sheet.relative_to(site)}: {url}" for m in FETCHES.finditer(text)
                    for url in m.groups() if url and _external(url)]
    assert not raw, "TeX left for a script to typeset:\n" + "\n".join(raw[:20])
    assert not fetched, "resources from another host:\n" + "\n".join(fetched[:20])
    assert math > 30  # physics' equations, as MathML


def test_the_offline_check_finds_what_it_looks_for():
    """The patterns catch a CDN script, a web font and MathJax's delimiters (so that the test
    above cannot pass by matching nothing)."""
    page = ('<script src="https://cdn.jsdelivr.net/npm/mathjax@4/tex-mml-chtml.js"></script>'
            '<link rel="stylesheet" href="//fonts.example.org/a.css"><a href="https://x.org">'
            '<span class="math">\\(a^2\\)</span>')
    urls = [u for m in FETCHES.finditer(page) for u in m.groups() if u and _external(u)]
    assert len(urls) == 2 and "https://x.org" not in urls
    assert len(RAW_TEX.findall(page)) == 2
    assert not [u for m in FETCHES.finditer('<script src="_static/furo.js">') for u in m.groups()
                if u and _external(u)]
