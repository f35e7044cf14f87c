"""Sphinx configuration of the granular-material documentation.

Built by ``tox -e docs`` (``sphinx-build -W --keep-going -b html docs docs/_build/html``) and by
``tests/test_docs.py`` in CI; see ``docs/contributing.md`` for why Sphinx and what is suppressed.
"""

from __future__ import annotations

import os

os.environ.setdefault("MPLBACKEND", "Agg")

project = "granular-material"
author = "granular-material contributors"
copyright = "granular-material contributors, MIT licence"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = [
    "_build",
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
    "granular_material.dem.condensed": ["|d|", "|fs|"],
    "granular_material.dem.condensed.ContactNetwork": ["|fs|"],
    "granular_material.dem.condensed.SLIDING_TOLERANCE": ["|fs|"],
    "granular_material.dem.condensed.contact_network": ["|fs|"],
    "granular_material.dem.homogenization.Homogenized": ["|net disc force|", "|contact force|"],
    "granular_material.procedures.element_tests.lateral_stress_error": ["|σxx/(−confining) − 1|"],
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


# -- Every module of the public packages is in the API reference ---------------------------------
#
# docs/api/<package>.md lists its modules one by one; a module added to a package but not to its
# page fails the build.
API_PACKAGES = ["granular_material.runs", "granular_material.fem", "granular_material.dem",
                "granular_material.procedures", "granular_material.results",
                "granular_material.multiscale", "granular_material_pore_fractal"]


def _check_api_complete(app, env):
    import importlib
    import pkgutil

    from sphinx.util import logging

    documented = set(env.get_domain("py").modules)
    missing = []
    for name in API_PACKAGES:
        package = importlib.import_module(name)
        for info in pkgutil.iter_modules(package.__path__):
            if not info.name.startswith("_") and f"{name}.{info.name}" not in documented:
                missing.append(f"{name}.{info.name}")
    if missing:
        logging.getLogger(__name__).warning(
            "modules missing from the API reference (add an automodule block to their "
            "package's page under docs/api/): %s", ", ".join(missing))


def setup(app):
    app.connect("autodoc-process-docstring", _escape_bars)
    app.connect("env-purge-doc", _purge_escapes)
    app.connect("env-updated", _check_escapes)
    app.connect("env-updated", _check_api_complete)
