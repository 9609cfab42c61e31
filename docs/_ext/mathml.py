"""Math as MathML written at build time: no script, no CDN, nothing to load.

Sphinx's ``mathjax`` extension loads MathJax from a CDN, so offline every equation is
raw TeX. This renderer converts each ``:math:`` role, ``.. math::`` directive and MyST
``$...$`` / ``$$...$$`` to MathML with latex2mathml (pure Python) while the site is
built; every current browser renders MathML Core natively. An expression latex2mathml
cannot convert fails the build (with ``-W``), naming it, rather than showing raw TeX.
"""

from __future__ import annotations

from docutils import nodes
from latex2mathml.converter import convert
from sphinx.errors import ExtensionError
from sphinx.util import logging

logger = logging.getLogger(__name__)


def _mathml(latex: str, display: str, node) -> str:
    try:
        return convert(latex, display=display)
    except Exception as exc:  # noqa: BLE001 - reported as a warning with the source
        logger.warning("cannot convert math %r to MathML: %s", latex, exc, location=node)
        return f"<code>{latex}</code>"


def visit_math(self, node) -> None:
    self.body.append(f'<span class="math">{_mathml(node.astext(), "inline", node)}</span>')
    raise nodes.SkipNode


def visit_displaymath(self, node) -> None:
    latex = node.astext()
    if node.get("nowrap"):
        parts = [latex]
    else:
        parts = [p for p in latex.split("\n\n") if p.strip()]
    self.body.append(self.starttag(node, "div", CLASS="math"))
    if node.get("number"):
        number = self.builder.env.get_domain("math").get_equation_number_for(node["label"])
        self.body.append(f'<span class="eqno">({number})</span>')
    for part in parts:
        self.body.append(_mathml(part, "block", node))
    self.body.append("</div>\n")
    raise nodes.SkipNode


def setup(app):
    try:
        app.add_html_math_renderer("mathml", (visit_math, None), (visit_displaymath, None))
    except ExtensionError:  # already registered (a second build in one process)
        pass
    return {"parallel_read_safe": True, "parallel_write_safe": True}
