"""Math written into the HTML as MathML when the site is built, so that the pages show their
equations with no script and no network (browsers render MathML themselves).

The TeX of each ``$...$``, ``$$...$$`` and ``{math}`` block is converted by ``latex2mathml``
(pure Python, the ``docs`` extra). TeX it cannot convert stops the build with the page and
the TeX, instead of leaving raw TeX on the page.
"""

from __future__ import annotations

from typing import Any

from docutils import nodes
from sphinx.errors import ExtensionError
from sphinx.util.math import get_node_equation_number


def _convert(tex: str, display: str, node: nodes.Node) -> str:
    from latex2mathml.converter import convert

    try:
        return convert(tex.strip(), display=display)
    except Exception as error:  # latex2mathml raises many kinds for TeX it does not know
        where = f"{node.source}:{node.line}" if getattr(node, "source", None) else "a page"
        raise ExtensionError(f"{where}: MathML conversion failed for {tex!r}: {error}") from error


def visit_math(self: Any, node: nodes.math) -> None:
    """Inline math as a ``<math>`` element inside a ``span.math``."""
    self.body.append(self.starttag(node, "span", "", CLASS="math"))
    self.body.append(_convert(node.astext(), "inline", node) + "</span>")
    raise nodes.SkipNode


def visit_displaymath(self: Any, node: nodes.math_block) -> None:
    """Displayed math, one ``<math display="block">`` per equation (blank-line separated),
    with the equation number where the block has one."""
    self.body.append(self.starttag(node, "div", CLASS="math"))
    if node["number"]:
        number = get_node_equation_number(self, node)
        self.body.append(f'<span class="eqno">({number})')
        self.add_permalink_ref(node, "Link to this equation")
        self.body.append("</span>")
    for part in (p for p in node.astext().split("\n\n") if p.strip()):
        tex = rf"\begin{{aligned}}{part}\end{{aligned}}" if r"\\" in part else part
        self.body.append(_convert(tex, "block", node))
    self.body.append("</div>\n")
    raise nodes.SkipNode


def setup(app: Any) -> dict[str, Any]:
    app.add_html_math_renderer("mathml", (visit_math, None), (visit_displaymath, None))
    return {"parallel_read_safe": True, "parallel_write_safe": True}
