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
"""

from __future__ import annotations

from gsgeo.errors import GsgeoError

#: The only URL scheme WeasyPrint may fetch: resources embedded in the document itself.
ALLOWED_SCHEMES = ("data",)


class ReportError(GsgeoError):
    """The PDF cannot be made here (WeasyPrint or its system libraries are missing)."""


def html_to_pdf(html: str) -> bytes:
    """PDF bytes of an HTML document whose resources are all embedded (data URIs)."""
    try:
        import weasyprint
    except (ImportError, OSError) as exc:  # OSError: Pango's shared libraries are missing
        raise ReportError("PDF needs WeasyPrint and Debian's libpango-1.0-0 and "
                          f"libpangoft2-1.0-0 (bash scripts/install.sh installs them): {exc}"
                          ) from None
    # No base_url (no relative URL resolves) and a fetcher of data: URIs only.
    fetcher = weasyprint.urls.URLFetcher(allowed_protocols=ALLOWED_SCHEMES,
                                         allow_redirects=False)
    return bytes(weasyprint.HTML(string=html, url_fetcher=fetcher).write_pdf())
