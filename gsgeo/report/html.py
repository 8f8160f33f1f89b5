"""The survey report as one self-contained HTML document (jinja2, autoescaped).

Every figure is embedded as a data URI and the style sheet is inline, so the file stands
alone: it can be mailed, archived or opened offline. Text from the project (names, ids,
descriptions, codes) is escaped by jinja2's autoescape; no user text reaches the CSS.
"""

from __future__ import annotations

from functools import cache

import jinja2

from gsgeo.report.content import LISTING_FONT_PT, LISTING_LINE_HEIGHT, Report

TEMPLATE = "report.html"


@cache
def _environment() -> jinja2.Environment:
    return jinja2.Environment(loader=jinja2.PackageLoader("gsgeo.report", "templates"),
                              autoescape=True, undefined=jinja2.StrictUndefined,
                              trim_blocks=True, lstrip_blocks=True)


def render_html(report: Report) -> str:
    """The report as an HTML document (UTF-8 text)."""
    return _environment().get_template(TEMPLATE).render(
        report=report, listing_font_pt=LISTING_FONT_PT, listing_line_height=LISTING_LINE_HEIGHT)
