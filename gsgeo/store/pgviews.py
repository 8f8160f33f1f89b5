"""PostGIS views of one project, for GIS clients (QGIS) reading the database directly.

Per project four views, registered in PostGIS's ``geometry_columns`` through their typed
geometry column: ``gsgeo_<id>_points`` (the point-schema record columns and the point's
provenance, gsgeo.pointschema.EXPORT_KEYS, geometry ``PointZ`` from easting, northing,
height), ``gsgeo_<id>_lines`` (``LineStringZ`` through the line's solved points in order),
``gsgeo_<id>_polygons`` (``PolygonZ``, the ring closed) and ``gsgeo_<id>_buildings`` (one
``PolygonZ`` per surface of each built building, the columns of
gsgeo.pointschema.BUILDING_TYPES, from the surfaces the service keeps in
``building_surfaces``). The SRID is the EPSG code of the project's grid CRS (the horizontal
part of a compound ``EPSG:h+v``; 0 when the CRS has no EPSG code). They read the stored
tables, so they are always current; they are recreated when the project's CRS changes, and
for every project when this gsgeo's views (VIEWS_VERSION) are newer than the database's.
"""

from __future__ import annotations

import hashlib
import re

from psycopg import sql

from gsgeo.pointschema import BUILDING_TYPES, RECORD_KEYS
from gsgeo.store.base import INSTANT

#: Record columns that are text (measured_at becomes a timestamptz) and integers; the rest
#: are double precision.
TEXT_KEYS = frozenset({"point_id", "code", "description", "height_type", "vertical_datum",
                       "crs", "operation"})
INT_KEYS = frozenset({"n_rays"})
KINDS = ("points", "lines", "polygons", "buildings")
#: The version of the views this module makes: 2 added the points' provenance columns and
#: the buildings view, 3 reads measured_at as every backend's time filters do.
VIEWS_VERSION = 3

# An ISO 8601 instant with a zone offset (gsgeo.store.base.INSTANT), which alone is cast (a
# bad text gives NULL, not an error that would make the whole view unreadable)
INSTANT_RE = f"^{INSTANT}$"


def view_name(pid: str, kind: str) -> str:
    """``gsgeo_<id>_<kind>``: the id lower-cased with other characters than [a-z0-9] as _.
    An id of other characters than [a-z0-9-] (an underscore, a capital) or a long one gets a
    short hash of itself appended, which keeps names apart (PostgreSQL names are at most 63
    bytes)."""
    clean = re.sub(r"[^a-z0-9]", "_", pid.lower())
    if not re.fullmatch(r"[a-z0-9-]{1,40}", pid):
        clean = clean[:32] + "_" + hashlib.sha1(pid.encode()).hexdigest()[:8]
    return f"gsgeo_{clean}_{kind}"


def srid_of(crs: str | None) -> int:
    """The EPSG code of a grid CRS given as ``EPSG:n`` or ``EPSG:h+v`` (0: none)."""
    m = re.fullmatch(r"\s*EPSG:(\d+)(\+\d+)?\s*", crs or "", re.IGNORECASE)
    return int(m.group(1)) if m else 0


def _column(key: str, kind: str | None = None) -> sql.Composable:
    """The typed column ``key`` of the JSON record ``r``: ``kind`` 'str', 'int' or 'float'
    (None: a point-schema key, typed by TEXT_KEYS / INT_KEYS)."""
    if kind is None:
        kind = "str" if key in TEXT_KEYS else "int" if key in INT_KEYS else \
            "instant" if key == "measured_at" else "float"
    text = sql.SQL("(r->>{})").format(sql.Literal(key))
    if kind == "str":
        expr: sql.Composable = text
    elif kind == "int":
        expr = sql.SQL("CASE WHEN jsonb_typeof(r->{k}) = 'number' THEN {t}::float8::integer END"
                       ).format(k=sql.Literal(key), t=text)
    elif kind == "instant":
        expr = sql.SQL("CASE WHEN {t} ~ {re} THEN gsgeo_timestamptz({t}) END").format(
            t=text, re=sql.Literal(INSTANT_RE))
    else:
        expr = sql.SQL("CASE WHEN jsonb_typeof(r->{k}) = 'number' THEN {t}::float8 END").format(
            k=sql.Literal(key), t=text)
    return sql.SQL("{} AS {}").format(expr, sql.Identifier(key))


def drop_views(pid: str) -> list[sql.Composed]:
    """Statements dropping the project's views (those that exist)."""
    return [sql.SQL("DROP VIEW IF EXISTS {}").format(sql.Identifier(view_name(pid, k)))
            for k in reversed(KINDS)]


def create_views(pid: str, crs: str | None) -> list[sql.Composed]:
    """Statements (re)creating the project's views with the SRID of ``crs``."""
    srid = sql.Literal(srid_of(crs))
    points, lines, polygons, buildings = (sql.Identifier(view_name(pid, k)) for k in KINDS)
    p = sql.Literal(pid)
    cols = sql.SQL(", ").join(_column(k) for k in RECORD_KEYS)
    num = "CASE WHEN jsonb_typeof(r->'{k}') = 'number' THEN (r->>'{k}')::float8 END"
    xyz = sql.SQL(", ").join(sql.SQL(num.format(k=k)) for k in ("easting", "northing", "height"))
    out = drop_views(pid)
    out.append(sql.SQL(
        "CREATE VIEW {points} AS SELECT pt.seq AS fid, pt.id AS id, {cols},"
        " pt.measured_by AS measured_by,"
        " (json_array_length(pt.rays) - a.n)::integer AS n_rays_clicked,"
        " a.n::integer AS n_rays_auto, pt.version AS version, pt.updated_at AS updated_at,"
        " ST_SetSRID(ST_MakePoint({xyz}), {srid})::geometry(PointZ, {srid}) AS geom"
        " FROM points pt CROSS JOIN LATERAL (SELECT pt.result::jsonb AS r) j"
        " CROSS JOIN LATERAL (SELECT count(*) AS n FROM json_array_elements(pt.rays) e"
        " WHERE e->>'auto' = 'true') a"
        " WHERE pt.project_id = {p} AND pt.result IS NOT NULL"
    ).format(points=points, cols=cols, xyz=xyz, srid=srid, p=p))
    line_of = ("SELECT f.seq AS fid, f.id AS id, f.code AS code, f.description AS description,"
               " f.version AS version, f.updated_at AS updated_at,"
               " ST_MakeLine(v.geom ORDER BY e.ord) AS line, count(v.geom) AS n"
               " FROM features f CROSS JOIN LATERAL json_array_elements_text(f.point_ids)"
               " WITH ORDINALITY e(point_id, ord)"
               " JOIN {points} v ON v.id = e.point_id AND v.geom IS NOT NULL"
               " WHERE f.project_id = {p} AND f.kind = {kind}"
               " GROUP BY f.project_id, f.kind, f.id")
    out.append(sql.SQL(
        "CREATE VIEW {lines} AS SELECT fid, id, code, description, version, updated_at,"
        " CASE WHEN n >= 2 THEN line END::geometry(LineStringZ, {srid}) AS geom"
        " FROM (" + line_of + ") s"
    ).format(lines=lines, points=points, p=p, kind=sql.Literal("line"), srid=srid))
    out.append(sql.SQL(
        "CREATE VIEW {polygons} AS SELECT fid, id, code, description, version, updated_at,"
        " CASE WHEN n >= 3 THEN ST_MakePolygon(ST_AddPoint(line, ST_StartPoint(line))) END"
        "::geometry(PolygonZ, {srid}) AS geom FROM (" + line_of + ") s"
    ).format(polygons=polygons, points=points, p=p, kind=sql.Literal("polygon"), srid=srid))
    surface_cols = sql.SQL(", ").join(_column(k, t) for k, t in BUILDING_TYPES.items()
                                      if k not in ("building_id", "surface_index"))
    out.append(sql.SQL(
        "CREATE VIEW {buildings} AS SELECT s.fid AS fid, s.building_id AS building_id,"
        " s.surface_index AS surface_index, {cols},"
        " ST_SetSRID(ST_GeomFromWKB(s.wkb), {srid})::geometry(PolygonZ, {srid}) AS geom"
        " FROM building_surfaces s CROSS JOIN LATERAL (SELECT s.attrs::jsonb AS r) j"
        " WHERE s.project_id = {p}"
    ).format(buildings=buildings, cols=surface_cols, srid=srid, p=p))
    return out
