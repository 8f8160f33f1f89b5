"""The survey report as PDF: the HTML document laid out by WeasyPrint.

WeasyPrint turns the same HTML (and its print CSS: A4 pages, repeated table headers, page
numbers) into a PDF, so the PDF and the HTML cannot say different things. It needs Pango
(Debian's libpango-1.0-0 and libpangoft2-1.0-0), which scripts/install.sh installs; it is
imported on first use, so the rest of gsgeo starts without it.
"""

from __future__ import annotations

from gsgeo.errors import GsgeoError


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
    # No base_url: the document embeds everything, and nothing may be fetched.
    return bytes(weasyprint.HTML(string=html).write_pdf())
