"""Sphinx configuration of the granular-material documentation.

Built by ``tox -e docs`` (``sphinx-build -W --keep-going -b html docs docs/_build/html``) and by
``tests/test_docs.py`` in CI; see ``docs/contributing.md`` for why Sphinx and what is suppressed.
"""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")
# docs/_ext: the site's own extensions (mathml: equations rendered when the site is built)
sys.path.insert(0, str(Path(__file__).resolve().parent / "_ext"))

project = "granular-material"
author = "granular-material contributors"
copyright = "granular-material contributors, MIT licence"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "mathml",
]
# equations as MathML in the HTML, converted at build time: no script, no network
html_math_renderer = "mathml"

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = [
    "_build",
    "_ext",
    "**/.ipynb_checkpoints",
    # the validation reports' READMEs are linked from their report pages, not pages of their own
]

myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 4

html_theme = "furo"
html_title = "granular-material"

# Each object is documented once, in the module that defines it (a package's __init__ and
# a module's __all__ re-export names that are documented at their home).
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_class_signature = "mixed"
napoleon_google_docstring = True
napoleon_numpy_docstring = True
# "Attributes:" sections as :ivar: fields, so that an attribute that also has a ``#:`` comment
# is not described twice
napoleon_use_ivar = True

nitpicky = False


# -- Docstrings that files being rewritten elsewhere still hold ---------------------------------
#
# reStructuredText reads ``|text|`` as a substitution reference, so an absolute value written
# |d| in a docstring is an "Undefined substitution" error. The docstrings below are in files
# that other branches are rewriting now (granular_material/dem/*, granular_material/procedures/*),
# so they are not edited here: their bars are escaped as the docstring is read, for these
# objects and these strings only. Fix them at the source (``|d|`` in double back-quotes) and
# delete their entries; an entry whose text is no longer found fails the build.
ESCAPED_BARS = {
    "granular_material.dem.condensed.tangent": ["|d|", "|fs|"],
    "granular_material.dem.condensed.tangent.ContactNetwork": ["|fs|"],
    "granular_material.dem.condensed.tangent.SLIDING_TOLERANCE": ["|fs|"],
    "granular_material.dem.condensed.tangent.contact_network": ["|fs|"],
    "granular_material.dem.homogenization.Homogenized": ["|net disc force|", "|contact force|"],
    "granular_material.procedures.strain_path.drive_grad_u": ["|H01/H11|"],
}


def _escape_bars(app, what, name, obj, options, lines):
    # what was escaped, per document, kept in the environment so that an incremental build
    # (which reads only the changed documents) still knows what the others escaped
    if not hasattr(app.env, "gm_escaped_bars"):
        app.env.gm_escaped_bars = {}
    seen = app.env.gm_escaped_bars.setdefault(app.env.docname, set())
    for text in ESCAPED_BARS.get(name, ()):
        for i, line in enumerate(lines):
            if text in line:
                lines[i] = line.replace(text, "``" + text + "``")
                seen.add((name, text))


def _purge_escapes(app, env, docname):
    getattr(env, "gm_escaped_bars", {}).pop(docname, None)


def _check_escapes(app, env):
    seen = set().union(*getattr(env, "gm_escaped_bars", {}).values())
    stale = [(n, t) for n, ts in ESCAPED_BARS.items() for t in ts if (n, t) not in seen]
    if stale:
        from sphinx.util import logging

        logging.getLogger(__name__).warning(
            "ESCAPED_BARS in docs/conf.py lists text no docstring holds any more (remove it): %s",
            stale)


# -- The API reference: the public API by package, the rest for contributors -------------------
#
# The public API is what the packages export (their __all__). docs/api/<package>.md documents
# the modules those names live in, each showing only its exported names; every other module of
# the packages is on docs/api/internals.md (for contributors). A module on the wrong page, or on
# none, fails the build.
API_PACKAGES = ["granular_material.runs", "granular_material.fem", "granular_material.dem",
                "granular_material.procedures", "granular_material.results",
                "granular_material.multiscale", "granular_material_pore_fractal"]
INTERNALS_PAGE = "api/internals"


@functools.lru_cache(maxsize=1)
def _exported() -> dict[str, set[str]]:
    """Module -> the names of it that some package of :data:`API_PACKAGES` exports."""
    import importlib

    homes: dict[str, set[str]] = {}
    for name in API_PACKAGES:
        package = importlib.import_module(name)
        for export in getattr(package, "__all__", ()):
            home = getattr(getattr(package, export), "__module__", None)
            if home is not None:
                homes.setdefault(home, set()).add(export)
    return homes


def _skip_unexported(app, what, name, obj, skip, options):
    # a public module's page shows its exported names only; internal modules show everything
    if what != "module" or skip:
        return None
    module = getattr(app.env, "gm_documenting", None)
    exported = _exported().get(module)
    if exported is not None and name not in exported:
        return True
    return None


def _note_module(app, what, name, obj, options, lines):
    if what == "module":
        app.env.gm_documenting = name


def _check_api_pages(app, env):
    import importlib
    import pkgutil

    from sphinx.util import logging

    documented = {name: entry.docname for name, entry in env.get_domain("py").modules.items()}
    exported = _exported()
    wrong, missing = [], []
    for name in API_PACKAGES:
        package = importlib.import_module(name)
        # every module of the package and of its sub-packages (a sub-package's __init__ holds
        # only its docstring and is documented by none)
        modules = [info.name for info in pkgutil.walk_packages(package.__path__, f"{name}.")
                   if not info.ispkg and not info.name.rpartition(".")[2].startswith("_")]
        for module in modules:
            if module not in documented:
                missing.append(module)
                continue
            internal_page = documented[module] == INTERNALS_PAGE
            if internal_page == (module in exported):
                wrong.append(f"{module} ({'public' if module in exported else 'internal'}, "
                             f"on {documented[module]})")
    for module in exported:
        if module in documented and documented[module] == INTERNALS_PAGE:
            wrong.append(f"{module} (public, on {INTERNALS_PAGE})")
    log = logging.getLogger(__name__)
    if missing:
        log.warning("modules missing from the API reference (add an automodule block to their "
                    "package's page under docs/api/, or to %s.md if no package exports from "
                    "them): %s", INTERNALS_PAGE, ", ".join(missing))
    if wrong:
        log.warning("modules on the wrong API page (a module some package's __all__ exports "
                    "from goes on its package's page, any other on %s.md): %s",
                    INTERNALS_PAGE, ", ".join(sorted(set(wrong))))


def setup(app):
    app.connect("autodoc-process-docstring", _escape_bars)
    app.connect("env-purge-doc", _purge_escapes)
    app.connect("env-updated", _check_escapes)
    app.connect("autodoc-process-docstring", _note_module)
    app.connect("autodoc-skip-member", _skip_unexported)
    app.connect("env-updated", _check_api_pages)
