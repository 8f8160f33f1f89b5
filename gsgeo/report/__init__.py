"""The survey report: a project's frames, georeference, accuracy and points as HTML or PDF.

gsgeo.service.reporting gathers the data (plain JSON); this package renders it:
``content`` (data -> sections of facts, tables, figures and notes), ``plots`` (matplotlib
figures as PNG data URIs), ``html`` (jinja2) and ``pdf`` (WeasyPrint from that HTML). It
sits beside gsgeo.export, below the service: it never opens a store.
"""

from __future__ import annotations

from pathlib import Path

from gsgeo.errors import InputError
from gsgeo.jsontypes import JSONObject

#: Report formats and their file suffixes.
FORMATS = {"html": (".html", ".htm"), "pdf": (".pdf",)}
MEDIA_TYPES = {"html": "text/html; charset=utf-8", "pdf": "application/pdf"}


def format_from_suffix(path: str | Path) -> str | None:
    """"html" or "pdf" from a file name's suffix (case-insensitive), None otherwise."""
    suffix = Path(path).suffix.lower()
    return next((f for f, sfx in FORMATS.items() if suffix in sfx), None)


def render(data: JSONObject, fmt: str) -> bytes:
    """The report of gsgeo.service.reporting's ``data`` as HTML (UTF-8) or PDF bytes."""
    from gsgeo.report.content import build_report
    from gsgeo.report.html import render_html

    if fmt not in FORMATS:
        raise InputError(f"unknown report format '{fmt}'; use html or pdf", field="format")
    report = build_report(data)
    if fmt == "html":
        return render_html(report).encode("utf-8")
    from gsgeo.report.pdf import report_to_pdf

    return report_to_pdf(report)


__all__ = ["FORMATS", "MEDIA_TYPES", "format_from_suffix", "render"]
