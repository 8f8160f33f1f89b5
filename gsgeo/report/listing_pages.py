"""A report's long listings drawn onto its PDF pages: reportlab draws the text, pypdf lays it
over the pages WeasyPrint made.

WeasyPrint shapes and paints text through Pango, one Python call per line and per glyph: the
5 000-point listing of a large project was 6-8 s of a 10 s report. A listing is plain
fixed-width text in one font, so it needs no shaping: WeasyPrint lays out an empty space of
the listing's height (its pages, footers and page numbers stay WeasyPrint's), and this module
writes the lines into those spaces with reportlab (DejaVu Sans Mono, matplotlib's copy,
embedded as a subset with its Unicode map, so the text stays selectable and searchable),
then pypdf merges each drawn page over its page of the report.

Only text that needs no shaping is drawn here (:func:`drawable`): every character in the
font, none combining or right-to-left. Any other listing stays WeasyPrint's text.

Units: WeasyPrint's positions are CSS pixels (1/96 in) from a page's top-left corner; PDF
points (1/72 in) run from the bottom-left.
"""

from __future__ import annotations

import io
import unicodedata
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

#: PDF points per CSS pixel.
PT_PER_PX = 72 / 96
#: The listing font (matplotlib ships it, so it is where gsgeo is).
FONT_FAMILY = "DejaVu Sans Mono"
FONT_NAME = "GsgeoListingMono"
#: Bidirectional classes of text that runs right to left (drawn only with shaping).
RIGHT_TO_LEFT = {"R", "AL", "AN", "RLE", "RLO", "RLI", "FSI", "PDF", "PDI", "LRE", "LRO",
                 "LRI", "NSM"}


@dataclass(frozen=True)
class Placement:
    """Listing text to draw: its lines, the 0-based page, and the top-left corner of its
    space on that page in CSS pixels."""

    page: int
    x_px: float
    y_px: float
    text: str


@cache
def _font() -> object:
    """The registered reportlab TTFont (once per process)."""
    import matplotlib.font_manager as fm
    from reportlab.pdfbase import pdfmetrics
    from reportlab.pdfbase.ttfonts import TTFont

    path = fm.findfont(fm.FontProperties(family=FONT_FAMILY), fallback_to_default=False)
    font = TTFont(FONT_NAME, path)
    pdfmetrics.registerFont(font)
    return font


@cache
def _covered() -> frozenset[int]:
    """Code points the listing font has a glyph for."""
    return frozenset(_font().face.charToGlyph)  # type: ignore[attr-defined]


def drawable(text: str) -> bool:
    """True when every line of ``text`` can be drawn glyph by glyph in the listing font: each
    character (but the line breaks) has a glyph there, none combines with its neighbour or
    runs right to left."""
    try:
        covered = _covered()
    except (ImportError, ValueError, OSError):  # no reportlab, no font: WeasyPrint draws it
        return False
    for ch in set(text) - {"\n"}:
        if (ord(ch) not in covered or unicodedata.combining(ch)
                or unicodedata.category(ch) in ("Mn", "Me", "Mc", "Cc", "Cf")
                or unicodedata.bidirectional(ch) in RIGHT_TO_LEFT):
            return False
    return True


def baseline_offset_pt(size_pt: float, leading_pt: float) -> float:
    """From the top of a line box of height ``leading_pt`` down to its text's baseline (CSS
    puts half the leading above the font's ascent, as WeasyPrint does)."""
    face = _font().face  # type: ignore[attr-defined]
    ascent, descent = face.ascent / 1000 * size_pt, -face.descent / 1000 * size_pt
    return (leading_pt - (ascent + descent)) / 2 + ascent


def draw(pdf: bytes, placements: Sequence[Placement], size_pt: float,
         leading_pt: float) -> bytes:
    """``pdf`` with each placement's lines written in the listing font (``size_pt``, one
    line every ``leading_pt``) from the top-left of its space down."""
    if not placements:
        return pdf
    import pypdf
    from reportlab.pdfgen import canvas

    _font()
    base = pypdf.PdfWriter(clone_from=pypdf.PdfReader(io.BytesIO(pdf)))
    pages = sorted({p.page for p in placements})
    drawn = io.BytesIO()
    sheet = canvas.Canvas(drawn, pageCompression=1, invariant=1)
    drop = baseline_offset_pt(size_pt, leading_pt)
    for page in pages:
        box = base.pages[page].mediabox
        height = float(box.height)
        sheet.setPageSize((float(box.width), height))
        for p in (p for p in placements if p.page == page):
            text = sheet.beginText(p.x_px * PT_PER_PX, height - p.y_px * PT_PER_PX - drop)
            text.setFont(FONT_NAME, size_pt, leading=leading_pt)
            text.textLines(p.text.split("\n"))  # a list: a str's edges are stripped
            sheet.drawText(text)
        sheet.showPage()
    sheet.save()
    overlays = pypdf.PdfReader(io.BytesIO(drawn.getvalue())).pages
    for page, overlay in zip(pages, overlays, strict=True):
        _lay_over(base, base.pages[page], overlay, f"/GsgeoListing{page}")
    out = io.BytesIO()
    base.write(out)
    return out.getvalue()


def _lay_over(writer: Any, page: Any, overlay: Any, name: str) -> None:
    """Draw pypdf page ``overlay`` over ``page`` of ``writer`` as a form XObject ``name``.

    pypdf's ``merge_page`` parses both pages' content streams to rename their resources
    (2-4 s for a 70-page listing); a form XObject keeps the drawn page's resources apart
    and leaves the report's stream as it is, but for the one operator that paints it."""
    from pypdf.generic import ArrayObject, DictionaryObject, FloatObject, NameObject

    contents = overlay.raw_get("/Contents")  # reportlab writes one stream per page
    form = contents.get_object()
    form[NameObject("/Type")] = NameObject("/XObject")
    form[NameObject("/Subtype")] = NameObject("/Form")
    form[NameObject("/BBox")] = ArrayObject(FloatObject(v) for v in overlay.mediabox)
    form[NameObject("/Resources")] = overlay["/Resources"]
    ref = contents.clone(writer)
    resources = page["/Resources"].get_object()
    if "/XObject" not in resources:
        resources[NameObject("/XObject")] = DictionaryObject()
    resources["/XObject"].get_object()[NameObject(name)] = ref
    streams = page["/Contents"].get_object()
    streams = list(streams) if isinstance(streams, ArrayObject) else [page.raw_get("/Contents")]
    first, last = streams[0].get_object(), streams[-1].get_object()
    # the report's drawing in its own graphics state, so the form is drawn in the page's space
    first.set_data(b"q\n" + first.get_data())
    last.set_data(last.get_data() + f"\nQ\nq {name} Do Q\n".encode("ascii"))
