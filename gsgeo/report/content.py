"""The survey report's content: report data (gsgeo.service.reporting's JSON) -> sections.

A :class:`Report` is a title, a summary and sections of blocks (facts, tables, figures,
notes; a table of more than LISTING_ROWS rows as a fixed-width listing), every value already
formatted as text. HTML and PDF are both rendered from it, so they cannot differ.
Coordinates are shown in the grid CRS's units with 3 decimals;
sigmas, residuals and accuracy figures in millimetres with 1 decimal (``fmt_mm``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.report import plots

DASH = "—"


# formatting ---------------------------------------------------------------------------------
def _num(v: JSON) -> float | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    return float(v) if math.isfinite(v) else None


def fmt_mm(v: JSON, decimals: int = 1, signed: bool = False) -> str:
    """Metres as millimetres (``12.3``); a dash when unknown."""
    x = _num(v)
    if x is None:
        return DASH
    return f"{x * 1000:{'+' if signed else ''}.{decimals}f}"


def fmt_m(v: JSON, decimals: int = 3) -> str:
    """A coordinate or length with ``decimals`` decimals; a dash when unknown."""
    x = _num(v)
    return DASH if x is None else f"{x:.{decimals}f}"


def fmt_g(v: JSON, digits: int = 4) -> str:
    """A plain number with ``digits`` significant digits; a dash when unknown."""
    x = _num(v)
    return DASH if x is None else f"{x:.{digits}g}"


def fmt_text(v: JSON) -> str:
    return DASH if v is None or v == "" else str(v)


# blocks -------------------------------------------------------------------------------------
@dataclass
class Facts:
    """Label/value pairs."""

    rows: list[tuple[str, str]]
    kind: str = "facts"


@dataclass
class Table:
    """A table of text cells; ``numeric`` columns are right-aligned; ``row_classes`` mark
    rows ("outlier", "excluded", "failed" or ""); ``anywhere`` columns (long machine text:
    JSON) may break between any two characters to stay inside the page."""

    columns: list[str]
    rows: list[list[str]]
    numeric: list[bool]
    row_classes: list[str] = field(default_factory=list)
    caption: str = ""
    kind: str = "table"
    anywhere: list[bool] = field(default_factory=list)


@dataclass
class Figure:
    """A figure as a data URI (PNG), with its caption."""

    src: str
    caption: str
    kind: str = "figure"


@dataclass
class Notes:
    """A list of sentences: ``style`` "remark", "warning" or "formula"."""

    items: list[str]
    style: str = "remark"
    title: str = ""
    kind: str = "notes"


@dataclass
class Listing:
    """A long table set as fixed-width text (see :func:`listing`): its ``header`` lines and
    its rows in ``blocks`` of at most LISTING_BLOCK_ROWS lines, each printed under the header
    again and kept on one page."""

    header: str
    blocks: list[str]
    caption: str = ""
    kind: str = "listing"


@dataclass
class ListingSpace:
    """Where a Listing's blocks go in the PDF: empty spaces of their heights (points), one per
    block, with anchors ``{anchor}-{k}`` (gsgeo.report.pdf draws the text into them)."""

    anchor: str
    heights_pt: list[float]
    caption: str = ""
    kind: str = "listing_space"


Block = Facts | Table | Figure | Notes | Listing | ListingSpace

#: A table of more rows than this is set as a Listing. WeasyPrint lays out and paints every
#: cell of a table as its own box (5 000 points x 14 columns: about 50 s and gigabytes); a
#: listing line is one box, about 15 times cheaper, and holds the same text.
LISTING_ROWS = 200
#: Between a listing's columns: one space (every space is a glyph WeasyPrint shapes and
#: draws; two were an eighth of a points row).
LISTING_GAP = " "
#: Rows per block of a listing: with its header, one block fills most of an A4 page.
LISTING_BLOCK_ROWS = 80
#: A listing's font size (points) and line height (as a multiple of it).
LISTING_FONT_PT = 6.5
LISTING_LINE_HEIGHT = 1.25


@dataclass
class Section:
    title: str
    anchor: str
    blocks: list[Block]


@dataclass
class Report:
    """The whole document."""

    title: str
    subtitle: str
    generated: str
    summary: Facts
    sections: list[Section]


def _table(columns: Sequence[tuple[str, bool]], rows: list[list[str]],
           row_classes: list[str] | None = None, caption: str = "") -> Table:
    return Table([c for c, _ in columns], rows, [n for _, n in columns],
                 row_classes or [""] * len(rows), caption)


def _header_lines(title: str, width: int) -> list[str]:
    """A column title's words packed into lines of at most ``width`` characters (a longer
    word stands alone)."""
    lines: list[str] = []
    for word in title.split():
        if lines and len(lines[-1]) + 1 + len(word) <= width:
            lines[-1] += " " + word
        else:
            lines.append(word)
    return lines or [""]


def listing(table: Table) -> Listing:
    """``table`` as fixed-width text: each column as wide as its widest value or title word,
    numeric columns right-aligned, columns LISTING_GAP apart, titles wrapped at spaces and
    set at the foot of the header; no value is ever cut (a longer one shifts the rest of its
    line). Every row is kept, in order; the rows' marks (``row_classes``) are not drawn."""
    widths = [max([len(max(c.split() or [""], key=len))] + [len(r[j]) for r in table.rows])
              for j, c in enumerate(table.columns)]
    titles = [_header_lines(c, w) for c, w in zip(table.columns, widths, strict=True)]
    depth = max(len(t) for t in titles)
    titles = [[""] * (depth - len(t)) + t for t in titles]

    def line(cells: Sequence[str]) -> str:
        return LISTING_GAP.join(c.rjust(w) if num else c.ljust(w) for c, w, num
                                in zip(cells, widths, table.numeric, strict=True)).rstrip()

    header = [line([t[k] for t in titles]) for k in range(depth)]
    header.append("-" * max(len(h) for h in header))
    rows = [line(r) for r in table.rows]
    blocks = ["\n".join(rows[i:i + LISTING_BLOCK_ROWS])
              for i in range(0, len(rows), LISTING_BLOCK_ROWS)]
    return Listing("\n".join(header), blocks, table.caption)


def _set_long_tables(sections: list[Section]) -> list[Section]:
    """Every table of more than LISTING_ROWS rows as a Listing."""
    for s in sections:
        s.blocks = [listing(b) if isinstance(b, Table) and len(b.rows) > LISTING_ROWS else b
                    for b in s.blocks]
    return sections


# sections -----------------------------------------------------------------------------------
def _unit(data: JSONObject) -> str:
    grid = (data.get("frames") or {}).get("grid_crs") or {}
    return str(grid.get("unit") or "metre")


def _project_section(data: JSONObject) -> Section:
    p = data["project"]
    rows = [("Project", f"{p['name']} ({p['id']})"),
            ("Description", fmt_text(p.get("description"))),
            ("Scene", fmt_text(p.get("scene"))),
            ("Aiming precision σpx", f"{fmt_g(p.get('sigma_px'))} px"),
            ("Settings revision", fmt_text(p.get("settings_rev"))),
            ("Created", fmt_text(p.get("created_at"))),
            ("Last changed", fmt_text(p.get("updated_at")))]
    return Section("Project", "project", [Facts(rows)])


def _crs_line(facts: JSON) -> str:
    if not facts:
        return DASH
    if facts.get("error"):
        return f"{facts['code']} ({facts['error']})"
    extra = ", ".join(str(facts[k]) for k in ("datum", "projection") if facts.get(k))
    return f"{facts['code']} {facts.get('name') or ''}" + (f" ({extra})" if extra else "")


def _frames_section(data: JSONObject) -> Section:
    p, f = data["project"], data.get("frames") or {}
    rows = [("Scene frame (source CRS)", _crs_line(f.get("source_crs"))),
            ("Grid CRS", _crs_line(f.get("grid_crs")) if p.get("crs") else
             "none: points stay in the scene's frame; no grid coordinates, no accuracy test"),
            ("Area of use", fmt_text((f.get("grid_crs") or {}).get("area_of_use"))),
            ("Vertical datum", _crs_line(f.get("vertical_crs")) if p.get("vertical") else
             (f"geoid grid {p['geoid']}" if p.get("geoid") else
              "ellipsoidal heights (no geoid applied)"))]
    blocks: list[Block] = [Facts(rows)]
    ops = f.get("operations") or []
    if ops:
        blocks.append(_table(
            [("Datum operation used (PROJ)", False), ("Stated accuracy [m]", True),
             ("Points", True)],
            [[str(o["operation"]), "unknown (ballpark)" if o.get("accuracy_m") is None
              else fmt_g(o["accuracy_m"]), str(o["points"])] for o in ops],
            caption="The operation's accuracy is a systematic offset shared by the whole "
                    "scene; it is not part of the points' sigmas."))
    heights = f.get("heights") or []
    if heights:
        blocks.append(_table(
            [("Height type", False), ("Vertical datum / geoid", False), ("Points", True)],
            [[fmt_text(h.get("height_type")), fmt_text(h.get("vertical_datum")),
              str(h["points"])] for h in heights]))
    return Section("Reference frames", "frames", blocks)


def _control_style(c: JSONObject) -> str:
    if c.get("outlier"):
        return "outlier"
    if c.get("excluded") or not c.get("used", True):
        return "excluded"
    return "control"


def _rmse_rows(label: str, r: JSONObject) -> list[str]:
    return [label, fmt_text(r.get("count")), fmt_mm(r.get("e")), fmt_mm(r.get("n")),
            fmt_mm(r.get("horizontal")), fmt_mm(r.get("h")), fmt_mm(r.get("3d"))]


def _rotation_angle(rot: JSON) -> str:
    try:
        tr = float(rot[0][0]) + float(rot[1][1]) + float(rot[2][2])
    except (TypeError, IndexError, ValueError):
        return DASH
    return f"{math.degrees(math.acos(max(-1.0, min(1.0, (tr - 1) / 2)))):.6f}°"


def _parameters(g: JSONObject) -> Table:
    """The similarity's parameters (translation and rotation as fitted, old ECEF -> new)."""
    t = g.get("translation") or [None] * 3
    scale, s_sigma = _num(g.get("scale")), _num(g.get("scale_sigma"))
    rel = DASH if scale is None or s_sigma is None or scale == 0 else \
        f"{s_sigma / abs(scale) * 1e6:.1f} ppm"
    rows = [["scale s", fmt_g(scale, 10), fmt_g(s_sigma, 3), rel]]
    if scale is not None and abs(scale - 1) < 0.01:
        rows.append(["scale change s − 1", f"{(scale - 1) * 1e6:+.1f} ppm", DASH, ""])
    if g.get("kind") == "scale":
        return _table([("Parameter", False), ("Value", True), ("σ", True),
                       ("σ relative", True)], rows,
                      caption="Scale only: the scene keeps its local frame (no rotation, "
                              "no grid), its lengths become metres.")
    rows += [[f"translation {a} (ECEF) [m]", fmt_m(t[i], 4), DASH, ""] for i, a in enumerate("XYZ")]
    rows.append(["rotation angle", _rotation_angle(g.get("rotation")), DASH, ""])
    rot = g.get("rotation") or []
    for i, r in enumerate(rot):
        rows.append([f"rotation matrix row {i + 1}", " ".join(f"{float(x):+.9f}" for x in r),
                     DASH, ""])
    return _table([("Parameter", False), ("Value", True), ("σ", True), ("σ relative", True)],
                  rows, caption="Similarity y = s·R·x + t from the scene's previous frame to "
                                "the new one (ECEF).")


def _precision(p: JSONObject, g: JSONObject) -> Table:
    """The fit's precision at the control centroid (the frame covariance)."""
    sh = p.get("shift_enu_m") or [None] * 3
    rot = p.get("rotation_enu_arcsec") or [None] * 3
    c = p.get("centre") or {}
    rows: list[list[str]] = []
    if g.get("kind") != "scale":  # a scale-only fit has no shift or rotation
        rows += [[f"shift {a}", fmt_mm(sh[i]) + " mm"]
                 for i, a in enumerate(("east", "north", "up"))]
        rows += [[f"rotation about {a}",
                  DASH if _num(rot[i]) is None else f"{float(rot[i]):.2f}″"]
                 for i, a in enumerate(("east", "north", "up"))]
    rows.append(["scale", f"{fmt_g(p.get('scale_ppm'), 3)} ppm"])
    return _table([("1σ of the georeference", False), ("at the control centroid", True)], rows,
                  caption=f"The fit's uncertainty about the control centroid (lat "
                          f"{fmt_g(c.get('lat'), 9)}°, lon {fmt_g(c.get('lon'), 9)}°), which "
                          "adds to every measured point's total sigma.")


def _georef_blocks(status: JSONObject, precision: JSONObject | None) -> list[Block]:
    blocks: list[Block] = []
    rows = [("Scene", fmt_text(status.get("scene"))),
            ("Georeference version", fmt_text(status.get("version"))),
            ("Georeferenced", "yes" if status.get("georeferenced") else
             "NO: the scene sits at the default origin (lat 0, lon 0)")]
    g = status.get("current")
    if not g:
        blocks.append(Facts(rows))
        blocks.append(Notes(["No fit by control points has been applied to this scene."]))
        return blocks
    rows += [("Fit", "scale only" if g.get("kind") == "scale" else
              "7-parameter similarity (3-D Helmert), weighted least squares"),
             ("Applied to the scene", "yes" if status.get("current_applied", True) else
              "no (a proposed fit)"),
             ("Control in", fmt_text(g.get("grid_crs") or "local ENU")),
             ("σ0 (a-posteriori)", fmt_g(g.get("sigma0"))),
             ("Degrees of freedom", fmt_text(g.get("dof"))),
             ("Global test p-value", fmt_g(g.get("global_test_p"), 3))]
    blocks.append(Facts(rows))
    blocks.append(_parameters(g))
    if precision:
        blocks.append(_precision(precision, g))
    distances = g.get("distances") or []
    if distances:
        blocks.append(_table(
            [("From", False), ("To", False), ("Known [m]", True), ("σ [mm]", True),
             ("Scaled [m]", True), ("Residual [mm]", True)],
            [[str(d.get("from")), str(d.get("to")), fmt_m(d.get("distance"), 4),
              fmt_mm(d.get("sigma")), fmt_m(d.get("scaled"), 4),
              fmt_mm(d.get("residual"), signed=True)] for d in distances],
            caption="Known distances: measured in the scene, scaled, and the residual "
                    "(scaled minus known)."))
    control = g.get("control") or []
    if control:
        cols = [("Control", False), ("Status", False), ("dE [mm]", True), ("dN [mm]", True),
                ("dH [mm]", True), ("w", True), ("p", True), ("σh [mm]", True),
                ("σv [mm]", True)]
        rws, classes = [], []
        for c in control:
            style = _control_style(c)
            rws.append([str(c.get("id")), {"control": "used", "excluded": "excluded",
                                           "outlier": "OUTLIER"}[style],
                        fmt_mm(c.get("dE"), signed=True), fmt_mm(c.get("dN"), signed=True),
                        fmt_mm(c.get("dH"), signed=True), fmt_g(c.get("w"), 3),
                        fmt_g(c.get("p"), 3), fmt_mm(c.get("sigma_h")),
                        fmt_mm(c.get("sigma_v"))])
            classes.append("" if style == "control" else style)
        blocks.append(_table(cols, rws, classes, "Control residuals: control minus fitted, "
                             "in the grid; w is the data-snooping test statistic, p its "
                             "p-value."))
    check = g.get("check") or []
    if check:
        blocks.append(_table(
            [("Check", False), ("dE [mm]", True), ("dN [mm]", True), ("dH [mm]", True)],
            [[str(c.get("id")), fmt_mm(c.get("dE"), signed=True),
              fmt_mm(c.get("dN"), signed=True), fmt_mm(c.get("dH"), signed=True)]
             for c in check], caption="Check points of the fit (never in the fit)."))
    vectors = [plots.Vector(str(c.get("id")), _f(c.get("easting")), _f(c.get("northing")),
                            _f(c.get("dE")), _f(c.get("dN")), _f(c.get("dH")),
                            _control_style(c)) for c in control]
    vectors += [plots.Vector(str(c.get("id")), _f(c.get("easting")), _f(c.get("northing")),
                             _f(c.get("dE")), _f(c.get("dN")), _f(c.get("dH")), "check")
                for c in check]
    src = plots.residual_plan(vectors, "Georeference residuals (control minus fitted)")
    if src:
        blocks.append(Figure(src, "Horizontal residual vectors on a plan (exaggerated; "
                                  "labels give dH in mm). Outliers in red, excluded control "
                                  "in grey, check points as triangles."))
    blocks.append(_table(
        [("RMSE", False), ("n", True), ("E [mm]", True), ("N [mm]", True),
         ("horizontal [mm]", True), ("H [mm]", True), ("3-D [mm]", True)],
        [_rmse_rows(label, g.get(key)) for label, key in
         (("control", "rmse_control"), ("check", "rmse_check")) if g.get(key)]))
    if g.get("outliers"):
        blocks.append(Notes([f"Outlier{'s' if len(g['outliers']) > 1 else ''} flagged by "
                             f"data snooping: {', '.join(map(str, g['outliers']))}."],
                            "warning"))
    wo = g.get("without_outliers")
    if wo:
        blocks.append(_table(
            [("Without", False), ("scale", True), ("RMSE control H [mm]", True),
             ("RMSE control 3-D [mm]", True), ("RMSE check 3-D [mm]", True)],
            [[", ".join(map(str, wo.get("excluded") or [])) or DASH,
              fmt_g(wo.get("scale"), 10),
              fmt_mm((wo.get("rmse_control") or {}).get("horizontal")),
              fmt_mm((wo.get("rmse_control") or {}).get("3d")),
              fmt_mm((wo.get("rmse_check") or {}).get("3d"))]],
            caption="The same fit without the flagged points (the user decides)."))
    if g.get("warnings"):
        blocks.append(Notes([str(w) for w in g["warnings"]], "warning", "Warnings of the fit"))
    history = status.get("history") or []
    if history:
        blocks.append(_table([("Version", True), ("Kind", False), ("At", False),
                              ("Parent", True)],
                             [[fmt_text(h.get("version")), fmt_text(h.get("kind")),
                               fmt_text(h.get("at")), fmt_text(h.get("parent"))]
                              for h in history], caption="Georeference history of the scene"))
    return blocks


def _f(v: JSON) -> float:
    x = _num(v)
    return math.nan if x is None else x


def _georef_section(data: JSONObject) -> Section:
    geo = data.get("georeference") or {}
    status = geo.get("status")
    if not status:
        return Section("Georeference", "georeference",
                       [Notes([str(geo.get("note") or "no georeference information")])])
    return Section("Georeference", "georeference",
                   _georef_blocks(status, geo.get("frame_precision")))


def _accuracy_section(data: JSONObject) -> Section:
    acc = data.get("accuracy") or {}
    asprs = acc.get("asprs")
    if not asprs:
        return Section("Accuracy against check points", "accuracy",
                       [Notes([str(acc.get("note") or "no check points")])])
    s = asprs["statistics"]
    blocks: list[Block] = [Notes([f"Per the {asprs['standard']}. Differences are measured "
                                  "minus check point, in the grid; check points never enter "
                                  "the georeference."])]
    stats = [
        ["E", str(s["n_horizontal"]), fmt_mm(s["ME_E"], signed=True), fmt_mm(s["SD_E"]),
         fmt_mm(s["RMSE_E"])],
        ["N", str(s["n_horizontal"]), fmt_mm(s["ME_N"], signed=True), fmt_mm(s["SD_N"]),
         fmt_mm(s["RMSE_N"])],
        ["V (height)", str(s["n_vertical"]), fmt_mm(s["ME_V"], signed=True),
         fmt_mm(s["SD_V"]), fmt_mm(s["RMSE_V1"])],
    ]
    blocks.append(_table([("Component", False), ("n", True), ("ME [mm]", True),
                          ("SD [mm]", True), ("RMSE [mm]", True)], stats,
                         caption="Product against check points, per component."))
    summary = [
        ["RMSE_H1 (radial, product vs check points)", fmt_mm(s["RMSE_H1"])],
        ["RMSE_H2 (check point survey, horizontal)",
         fmt_mm(s["RMSE_H2"]) + (f" (n = {s['n_survey_horizontal']})"
                                 if s["n_survey_horizontal"] else " (not stated)")],
        ["RMSE_H (horizontal accuracy)", fmt_mm(s["RMSE_H"])],
        ["RMSE_V1 (product vs check points)", fmt_mm(s["RMSE_V1"])],
        ["RMSE_V2 (check point survey, vertical)",
         fmt_mm(s["RMSE_V2"]) + (f" (n = {s['n_survey_vertical']})"
                                 if s["n_survey_vertical"] else " (not stated)")],
        ["RMSE_V (vertical accuracy)", fmt_mm(s["RMSE_V"])],
        ["RMSE_3D (three-dimensional accuracy)", fmt_mm(s["RMSE_3D"])],
        ["Horizontal accuracy at 95 % (NSSDA, 1.7308 × RMSE_H)", fmt_mm(s["ACC_H95"])],
        ["Vertical accuracy at 95 % (NSSDA, 1.96 × RMSE_V)", fmt_mm(s["ACC_V95"])],
    ]
    blocks.append(_table([("Statistic", False), ("Value [mm]", True)], summary,
                         caption="ASPRS Edition 2 accuracy statistics."))
    blocks.append(Notes(list(asprs["formulas"]), "formula", "Formulas"))
    blocks.append(Notes(list(asprs["remarks"]), "remark", "Remarks"))
    pts = acc.get("points") or []
    blocks.append(_table(
        [("Check point", False), ("E", True), ("N", True), ("dE [mm]", True),
         ("dN [mm]", True), ("dH [mm]", True), ("2-D [mm]", True), ("3-D [mm]", True),
         ("survey σh [mm]", True), ("survey σv [mm]", True)],
        [[str(r["id"]), fmt_m(r.get("easting")), fmt_m(r.get("northing")),
          fmt_mm(r.get("dE"), signed=True), fmt_mm(r.get("dN"), signed=True),
          fmt_mm(r.get("dH"), signed=True), fmt_mm(r.get("d2D")), fmt_mm(r.get("d3D")),
          fmt_mm(r.get("survey_sigma_h")), fmt_mm(r.get("survey_sigma_v"))] for r in pts],
        caption="Check points: measured minus check."))
    vectors = [plots.Vector(str(r["id"]), _f(r.get("easting")), _f(r.get("northing")),
                            _f(r.get("dE")), _f(r.get("dN")), _f(r.get("dH")), "check")
               for r in pts]
    src = plots.residual_plan(vectors, "Check point residuals (measured minus check)")
    if src:
        blocks.append(Figure(src, "Horizontal differences at the check points "
                                  "(exaggerated; labels give dH in mm)."))
    src = plots.height_residuals([str(r["id"]) for r in pts], [r.get("dH") for r in pts],
                                 ["check"] * len(pts), "Height differences at check points")
    if src:
        blocks.append(Figure(src, "dH per check point, measured minus check."))
    counts = acc.get("counts") or {}
    missing = counts.get("check_points_not_measured") or []
    if missing:
        blocks.append(Notes([f"Check points not measured ({len(missing)}): "
                             + ", ".join(map(str, missing[:50]))
                             + (" …" if len(missing) > 50 else "")]))
    if acc.get("heights"):
        blocks.append(Notes([str(acc["heights"])]))
    return Section("Accuracy against check points", "accuracy", blocks)


def _aimed(row: JSONObject) -> str:
    """'clicked / auto' ray counts of a point row ('' when the row does not say)."""
    clicked, auto = row.get("n_rays_clicked"), row.get("n_rays_auto")
    if clicked is None and auto is None:
        return ""
    return f"{fmt_text(clicked)} / {fmt_text(auto)}"


def _points_section(data: JSONObject) -> Section:
    pts = data.get("points") or []
    failed = data.get("failed_points") or []
    unit = _unit(data)
    blocks: list[Block] = []
    if pts:
        src = plots.points_plan([str(r["point_id"]) for r in pts],
                                [_f(r.get("easting")) for r in pts],
                                [_f(r.get("northing")) for r in pts],
                                [_num(r.get("sigma_e")) for r in pts],
                                [_num(r.get("sigma_n")) for r in pts], "Measured points")
        if src:
            blocks.append(Figure(src, "Measured points on a plan, coloured by their total "
                                      "horizontal 1σ."))
        blocks.append(_table(
            [("Point", False), ("Code", False), (f"E [{unit}]", True), (f"N [{unit}]", True),
             (f"H [{unit}]", True), ("σE [mm]", True), ("σN [mm]", True), ("σH [mm]", True),
             ("σE meas [mm]", True), ("σN meas [mm]", True), ("σH meas [mm]", True),
             ("rays", True), ("clicked / auto", True),
             ("σ0", True)],
            [[str(r["point_id"]), fmt_text(r.get("code")) if r.get("code") else "",
              fmt_m(r.get("easting")), fmt_m(r.get("northing")), fmt_m(r.get("height")),
              fmt_mm(r.get("sigma_e")), fmt_mm(r.get("sigma_n")), fmt_mm(r.get("sigma_h")),
              fmt_mm(r.get("sigma_e_meas")), fmt_mm(r.get("sigma_n_meas")),
              fmt_mm(r.get("sigma_h_meas")), fmt_text(r.get("n_rays")), _aimed(r),
              fmt_g(r.get("sigma0"), 3)] for r in pts],
            caption="1σ in millimetres: total (aiming and georeference) and measurement-only "
                    "(aiming alone). rays: used in the solution; clicked / auto: how all of "
                    "the point's rays were aimed (by a click, or matched automatically)."))
    ecef = data.get("ecef_points") or []
    if ecef:
        blocks.append(_table(
            [("Point", False), ("Code", False), ("X [m]", True), ("Y [m]", True),
             ("Z [m]", True), ("σX [mm]", True), ("σY [mm]", True), ("σZ [mm]", True),
             ("rays", True), ("clicked / auto", True), ("σ0", True)],
            [[str(r["point_id"]), fmt_text(r.get("code")) if r.get("code") else "",
              fmt_m(r.get("x")), fmt_m(r.get("y")), fmt_m(r.get("z")),
              fmt_mm(r.get("sigma_x")), fmt_mm(r.get("sigma_y")), fmt_mm(r.get("sigma_z")),
              fmt_text(r.get("n_rays")), _aimed(r), fmt_g(r.get("sigma0"), 3)] for r in ecef],
            caption="Without a grid CRS: the points in the scene's geocentric frame (ECEF, as "
                    "rendered), with their total 1σ along its axes."))
    if not pts and not ecef:
        blocks.append(Notes(["No point has been measured."]))
    if failed:
        blocks.append(_table([("Point", False), ("Not solved because", False)],
                             [[str(r["point_id"]), str(r["error"])] for r in failed],
                             ["failed"] * len(failed)))
    return Section(f"Measured points ({len(pts) + len(ecef)})", "points", blocks)


def _feature_table(items: list[JSONObject], columns: list[tuple[str, bool]],
                   measures: Callable[[JSONObject], list[str]], caption: str) -> Table:
    """Lines or polygons: id, code, point ids, then ``measures(f)`` (or why there are none)."""
    def row(f: JSONObject) -> list[str]:
        head = [str(f["id"]), fmt_text(f.get("code")) if f.get("code") else "",
                ", ".join(map(str, f.get("points") or []))]
        tail = measures(f) if "error" not in f else \
            [str(f["error"])] + [""] * (len(columns) - len(head) - 1)
        return head + tail
    return _table(columns, [row(f) for f in items],
                  ["failed" if "error" in f else "" for f in items], caption=caption)


def _features_section(data: JSONObject) -> Section:
    """Lines (2-D and 3-D length) and polygons (area, perimeter) with their 1σ, in the grid."""
    lines = data.get("lines") or []
    polys = data.get("polygons") or []
    unit = _unit(data)
    blocks: list[Block] = []
    grid = "grid (the projected CRS's plane)"
    ground = ("Ground values are the grid values divided by the combined scale factor (CSF: "
              "the projection's point scale factor times the elevation factor R / (R + h), at "
              "the mean position and ellipsoidal height of the feature's points), areas by its "
              "square.")

    def csf(f: JSONObject) -> str:
        v = f.get("combined_scale_factor")
        return f"{v:.8f}" if isinstance(v, (int, float)) else DASH

    if lines:
        blocks.append(_feature_table(
            lines, [("Line", False), ("Code", False), ("Points", False),
                    (f"length 2-D, grid [{unit}]", True), ("σ [mm]", True),
                    ("length 2-D, ground [m]", True), (f"length 3-D [{unit}]", True),
                    ("σ [mm]", True), ("CSF", True)],
            lambda f: [fmt_m(f.get("length_2d")), fmt_mm(f.get("sigma_length_2d")),
                       fmt_m(f.get("length_2d_ground")),
                       fmt_m(f.get("length_3d")), fmt_mm(f.get("sigma_length_3d")), csf(f)],
            f"Lengths from the points' grid coordinates: the 2-D length in the {grid} and "
            "on the ground; the 3-D length with the heights. 1σ from the points' "
            f"covariances. {ground}"))
    if polys:
        blocks.append(_feature_table(
            polys, [("Polygon", False), ("Code", False), ("Points", False),
                    (f"area, grid [{unit}²]", True), ("σ [m²]", True),
                    ("area, ground [m²]", True), (f"perimeter, grid [{unit}]", True),
                    ("σ [mm]", True), ("perimeter, ground [m]", True), ("CSF", True)],
            lambda f: [fmt_g(f.get("area_2d"), 6), fmt_g(f.get("sigma_area_2d"), 3),
                       fmt_g(f.get("area_2d_ground"), 6),
                       fmt_m(f.get("perimeter_2d")), fmt_mm(f.get("sigma_perimeter_2d")),
                       fmt_m(f.get("perimeter_2d_ground")), csf(f)],
            f"Areas and perimeters in the {grid} and on the ground, from the points' E and "
            f"N; 1σ from their covariances. {ground}"))
    if not blocks:
        blocks.append(Notes(["No line or polygon has been measured."]))
    return Section(f"Lines and polygons ({len(lines)} / {len(polys)})", "features", blocks)


def _with_sigma(ms: JSONObject, key: str, fmt: Callable[[JSON], str], sigma_fmt: Callable[[JSON], str]
                ) -> str:
    """``ms[key]`` with its ``sigma_<key>`` beside it: "12.345 ± 4.2"."""
    v = fmt(ms.get(key))
    sig = ms.get(f"sigma_{key}")
    return v if sig is None or v == DASH else f"{v} ± {sigma_fmt(sig)}"


def _buildings_section(data: JSONObject) -> Section:
    """LoD2 buildings with their measures and 1σ (gsgeo.buildings.measures)."""
    rows = data.get("buildings") or []
    if not rows:
        return Section("Buildings (0)", "buildings", [Notes(["No building has been captured."])])
    unit = _unit(data)
    unit = {"metre": "m", "foot": "ft", "US survey foot": "ftUS"}.get(unit, unit)

    def row(b: JSONObject) -> list[str]:
        if b.get("error"):
            return [str(b["id"]), DASH, str(b["error"]), "", "", "", "", ""]
        got = b.get("measures")
        ms: JSONObject = got if isinstance(got, dict) else {}
        warn = "; ".join(map(str, b.get("warnings") or []))
        return [str(b["id"]), fmt_text(ms.get("roof_type")),
                _with_sigma(ms, "volume", lambda v: fmt_g(v, 6), lambda v: fmt_g(v, 3)),
                _with_sigma(ms, "footprint_area", lambda v: fmt_g(v, 6), lambda v: fmt_g(v, 3)),
                _with_sigma(ms, "eaves_height", fmt_m, fmt_mm),
                _with_sigma(ms, "ridge_height", fmt_m, fmt_mm),
                _with_sigma(ms, "measured_height", fmt_m, fmt_mm), warn]
    table = _table(
        [("Building", False), ("Roof", False), (f"volume [{unit}³] ± σ", True),
         (f"footprint, grid [{unit}²] ± σ", True), (f"eaves H [{unit}] ± σ [mm]", True),
         (f"ridge H [{unit}] ± σ [mm]", True), (f"height [{unit}] ± σ [mm]", True),
         ("Warnings", False)],
        [row(b) for b in rows], ["failed" if b.get("error") else "" for b in rows],
        caption="LoD2 models adjusted from measured roof corners: volume down to the ground "
                "given, footprint in the grid plane, eaves and ridge heights in the project's "
                "height system, height of the ridge above the ground; 1σ propagated from the "
                "points' covariances through the adjustment.")
    return Section(f"Buildings ({len(rows)})", "buildings", [table])


def _values(v: JSON, limit: int = 160) -> str:
    """Before/after values of an audit entry as JSON text, cut at ``limit``; a space after
    each comma and colon, where a long value may wrap."""
    if v is None:
        return DASH
    text = json.dumps(v, separators=(", ", ": "), ensure_ascii=False, default=str)
    return text if len(text) <= limit else text[:limit - 1] + "…"


def _audit_section(data: JSONObject) -> Section:
    audit = data.get("audit") or {}
    entries = audit.get("entries") or []
    counts = audit.get("counts") or {}
    total = int(audit.get("total") or 0)
    if not entries:
        return Section("Audit trail", "audit", [Notes(["No change has been recorded."])])
    blocks: list[Block] = [_table(
        [("Action", False), ("Entries", True)],
        [[str(a), str(n)] for a, n in sorted(counts.items())],
        caption=f"{total} changes recorded in all, by action.")]
    shown = f"The latest {len(entries)} of {total}" if total > len(entries) else "All"
    trail = _table(
        [("When (UTC)", False), ("Who", False), ("Action", False), ("What", False),
         ("Before", False), ("After", False)],
        [[str(e.get("at")), str(e.get("user")), str(e.get("action")),
          f"{e.get('kind')} {e.get('item')}" if e.get("item") else str(e.get("kind")),
          _values(e.get("before")), _values(e.get("after"))] for e in entries],
        caption=f"{shown} changes, newest first; the whole trail is at "
                "GET /api/projects/{id}/audit.")
    trail.anywhere = [False, False, False, False, True, True]
    blocks.append(trail)
    return Section(f"Audit trail ({total})", "audit", blocks)


def _summary(data: JSONObject) -> Facts:
    p = data["project"]
    acc = (data.get("accuracy") or {}).get("asprs")
    geo = ((data.get("georeference") or {}).get("status") or {})
    rows: list[tuple[str, str]] = [
        ("Project", str(p["name"])), ("Scene", fmt_text(p.get("scene"))),
        ("Grid CRS", fmt_text(p.get("crs"))),
        ("Points measured", str(len(data.get("points") or [])
                                 + len(data.get("ecef_points") or []))),
        ("Scene georeferenced", DASH if not geo else ("yes" if geo.get("georeferenced")
                                                       else "NO (default origin)")),
    ]
    if acc:
        s = acc["statistics"]
        rows += [("Check points (H / V)", f"{s['n_horizontal']} / {s['n_vertical']}"),
                 ("RMSE_H / RMSE_V / RMSE_3D",
                  f"{fmt_mm(s['RMSE_H'])} / {fmt_mm(s['RMSE_V'])} / {fmt_mm(s['RMSE_3D'])} mm")]
    else:
        rows.append(("Accuracy", "not tested against check points"))
    return Facts(rows)


def build_report(data: JSONObject) -> Report:
    """The report's content from gsgeo.service.reporting's data."""
    p = data["project"]
    gen: dict[str, Any] = data.get("generated") or {}
    return Report(
        title=f"Survey report: {p['name']}",
        subtitle="Point measurement in a 3D Gaussian Splatting scene by multi-ray intersection",
        generated=f"{gen.get('at', '')} by {gen.get('by', 'gsgeo')}",
        summary=_summary(data),
        sections=_set_long_tables([
            _project_section(data), _frames_section(data), _georef_section(data),
            _accuracy_section(data), _points_section(data), _features_section(data),
            _buildings_section(data), _audit_section(data)]),
    )
