"""The survey report as PDF: the HTML document laid out by WeasyPrint.

WeasyPrint turns the same HTML (and its print CSS: A4 pages, repeated table headers, page
numbers) into a PDF, so the PDF and the HTML cannot say different things. It needs Pango
(Debian's libpango-1.0-0 and libpangoft2-1.0-0), which scripts/install.sh installs; it is
imported on first use, so the rest of gsgeo starts without it.

WeasyPrint fetches what a document references (images, style sheets, fonts) through its URL
fetcher, by default any URL: http(s), ftp, file. The report embeds everything as ``data:``
URIs, so its fetcher allows that scheme alone (WeasyPrint's own ``URLFetcher`` with
``allowed_protocols``): whatever project text might slip past the HTML escaping, it can
neither read a local file nor make the server send a request.

A report's long listings (thousands of fixed-width lines) are not WeasyPrint's text: it lays
out an empty space of each block's height, and gsgeo.report.listing_pages writes the lines
into those spaces (about 3 times cheaper for a 5 000-point report; see that module). The
HTML report keeps them as ``<pre>`` text.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from gsgeo.errors import GsgeoError
from gsgeo.report.content import LISTING_FONT_PT, LISTING_LINE_HEIGHT, Listing, ListingSpace, Report

#: The only URL scheme WeasyPrint may fetch: resources embedded in the document itself.
ALLOWED_SCHEMES = ("data",)


class ReportError(GsgeoError):
    """The PDF cannot be made here (WeasyPrint or its system libraries are missing)."""


#: Anchors of the spaces listings are drawn into: ``{LISTING_ANCHOR}{n}-{block}``.
LISTING_ANCHOR = "gsgeo-listing-"


def _document(html: str) -> Any:
    """WeasyPrint's laid-out document of ``html`` (resources from data: URIs only)."""
    try:
        import weasyprint
    except (ImportError, OSError) as exc:  # OSError: Pango's shared libraries are missing
        raise ReportError("PDF needs WeasyPrint and Debian's libpango-1.0-0 and "
                          f"libpangoft2-1.0-0 (bash scripts/install.sh installs them): {exc}"
                          ) from None
    # No base_url (no relative URL resolves) and a fetcher of data: URIs only.
    fetcher = weasyprint.urls.URLFetcher(allowed_protocols=ALLOWED_SCHEMES,
                                         allow_redirects=False)
    return weasyprint.HTML(string=html, url_fetcher=fetcher).render()


def html_to_pdf(html: str) -> bytes:
    """PDF bytes of an HTML document whose resources are all embedded (data URIs)."""
    return bytes(_document(html).write_pdf())


def _spaced(report: Report) -> tuple[Report, dict[str, str]]:
    """``report`` with each listing the listing font can draw as a ListingSpace, and the text
    of each space by its anchor."""
    from gsgeo.report.listing_pages import drawable

    line_pt = LISTING_FONT_PT * LISTING_LINE_HEIGHT
    texts: dict[str, str] = {}
    sections = []
    for section in report.sections:
        blocks = []
        for block in section.blocks:
            if isinstance(block, Listing) and drawable(block.header + "".join(block.blocks)):
                anchor = f"{LISTING_ANCHOR}{len(texts)}"
                lines = [f"{block.header}\n{text}" for text in block.blocks]
                texts |= {f"{anchor}-{k}": t for k, t in enumerate(lines)}
                block = ListingSpace(anchor, [(t.count("\n") + 1) * line_pt for t in lines],
                                     block.caption)
            blocks.append(block)
        sections.append(dataclasses.replace(section, blocks=blocks))
    return dataclasses.replace(report, sections=sections), texts


def report_to_pdf(report: Report) -> bytes:
    """The report as PDF bytes: WeasyPrint's layout of its HTML, the long listings drawn into
    the spaces it left for them."""
    from gsgeo.report.html import render_html
    from gsgeo.report.listing_pages import Placement, draw

    spaced, texts = _spaced(report)
    document = _document(render_html(spaced))
    placements = [Placement(i, x, y, texts[name])
                  for i, page in enumerate(document.pages)
                  for name, (x, y, *_) in page.anchors.items() if name in texts]
    if len(placements) != len(texts):  # a space WeasyPrint did not lay out: never lose rows
        raise ReportError(f"the PDF laid out {len(placements)} of {len(texts)} listing blocks")
    return draw(bytes(document.write_pdf()), placements, LISTING_FONT_PT,
                LISTING_FONT_PT * LISTING_LINE_HEIGHT)
