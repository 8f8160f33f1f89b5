"""A project's layers as OGC API – Features collections: metadata, pages of features, one feature.

Collections are ``{pid}.points``, ``{pid}.lines``, ``{pid}.polygons``, ``{pid}.check_points``
and ``{pid}.rays``, and ``{pid}.buildings`` (one feature per surface of an LoD2 building, id
``{building}~{surface index}``) while the project has buildings. Their properties are the
export's (gsgeo.export.tables: EXPORT_KEYS / POINT_TYPES for points, the GeoPackage layers'
column types for the others), and their values
come from the same code the export uses (``collect``), so a feature says what the export says.

Coordinates: CRS84 (longitude, latitude in degrees, WGS 84 ellipsoidal height in metres: a
point's ``lon``, ``lat``, ``h_wgs84``) by default; in the project's grid CRS (EPSG URI) the
stored E, N, H (the CRS's units), in the CRS's own axis order. Points are paged in the store
(only the page's records are read); the other layers are small and built whole.

Nothing here knows HTTP: errors are InputError (a bad parameter), NotFoundError (no such
collection or feature) and CRSError (a CRS that is not offered).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, date, datetime, time, timedelta
from typing import Any

import numpy as np

from gsgeo.crs.ellipsoid import ecef_to_geodetic_closed_form
from gsgeo.crs.resolve import grid_crs
from gsgeo.errors import CRSError, GsgeoError, InputError
from gsgeo.export.gpkg import gpkg_crs
from gsgeo.export.tables import (
    BUILDING_TYPES,
    CHECK_POINT_TYPES,
    LINE_TYPES,
    POINT_TYPES,
    POLYGON_TYPES,
    RAY_TYPES,
    ExportData,
    building_table,
    collect,
)
from gsgeo.georef.control import grid_to_ecef
from gsgeo.jsontypes import JSONObject
from gsgeo.limits import number_text
from gsgeo.pointschema import EXPORT_KEYS, provenance
from gsgeo.service.buildings import spec_point_ids
from gsgeo.service.measuring import solve_settings
from gsgeo.service.projects import Projects, check_points_in_grid, feature_measures
from gsgeo.store.base import PointFilter, Transaction
from gsgeo.store.records import NotFoundError, Project

#: The layers every project offers, in order, with their properties' types.
LAYERS: dict[str, dict[str, str]] = {
    "points": {k: POINT_TYPES[k] for k in EXPORT_KEYS},
    "lines": LINE_TYPES,
    "polygons": POLYGON_TYPES,
    "check_points": CHECK_POINT_TYPES,
    "rays": RAY_TYPES,
    "buildings": BUILDING_TYPES,
}
#: Layers a project offers only while it holds something of them.
OPTIONAL_LAYERS = ("buildings",)
GEOMETRY = {"points": "PointZ", "lines": "LineStringZ", "polygons": "PolygonZ",
            "check_points": "PointZ", "rays": "LineStringZ", "buildings": "PolygonZ"}
TITLES = {"points": "measured points", "lines": "lines", "polygons": "polygons",
          "check_points": "check and control points", "rays": "rays (camera centre to point)",
          "buildings": "LoD2 buildings (one surface per feature)"}

CRS84 = "http://www.opengis.net/def/crs/OGC/1.3/CRS84"
CRS84H = "http://www.opengis.net/def/crs/OGC/0/CRS84h"
EPSG_PREFIX = "http://www.opengis.net/def/crs/EPSG/0/"

DEFAULT_LIMIT = 100
MAX_LIMIT = 10_000
#: The largest offset taken (a 64-bit SQLite integer holds it; no project comes near it).
MAX_OFFSET = 2**53

#: Properties a client may filter on (besides bbox and datetime), by layer.
FILTERS = {"points": ("code",), "lines": (), "polygons": (), "check_points": (), "rays": (),
           "buildings": ()}
#: Layers whose features have a time (``measured_at``; a ray its point's).
TEMPORAL = ("points", "rays")


def epsg_uri(code: str) -> str:
    """The OGC URI of 'EPSG:NNNN'."""
    return EPSG_PREFIX + code.split(":", 1)[1]


@dataclass(frozen=True)
class OutputCRS:
    """A CRS a collection offers: its URI, whether it is the grid (E, N, H) or CRS84, and
    whether its first axis is northing (the grid's coordinates are then written N, E, H)."""

    uri: str
    grid: bool
    northing_first: bool = False


def offered_crs(project: Project) -> list[OutputCRS]:
    """The CRSs of a project's collections: the storage CRS first (the grid's EPSG code as the
    GeoPackage stores it, a compound one with a vertical datum included), its horizontal part,
    then CRS84. CRS84 only without a grid."""
    out: list[OutputCRS] = []
    if project.crs:
        g = grid_crs(project.crs, project.vertical)
        north = g.horizontal.axis_info[0].direction.lower() == "north"
        texts = [f"{g.id}+{g.vertical_id.split(':', 1)[1]}"] if g.vertical_id else []
        texts.append(g.id)
        for text in texts:
            code, _ = gpkg_crs(text)
            if code.startswith("EPSG:") and all(c.uri != epsg_uri(code) for c in out):
                out.append(OutputCRS(epsg_uri(code), True, north))
    out.append(OutputCRS(CRS84, False))
    return out


def storage_crs(project: Project) -> str:
    """The URI of the CRS the project's coordinates are stored in (CRS84 without a grid)."""
    return offered_crs(project)[0].uri


def pick_crs(project: Project, uri: str | None, what: str = "crs") -> OutputCRS:
    """The offered CRS named by ``uri`` (None: CRS84); CRSError naming the offered ones."""
    offered = offered_crs(project)
    if uri is not None and not uri.strip():
        raise CRSError(f"is empty: leave it out for CRS84, or use one of "
                       f"{', '.join(c.uri for c in offered)}", field=what)
    if uri is None or uri.strip() in (CRS84, CRS84H):
        return OutputCRS(CRS84H if uri is not None and uri.strip() == CRS84H else CRS84, False)
    text = uri.strip().removeprefix("[").removesuffix("]")
    if text.upper().startswith("EPSG:"):
        text = epsg_uri(text)
    text = text.replace("https://", "http://", 1)
    for c in offered:
        if c.uri == text:
            return c
    raise CRSError(f"{uri!r} is not offered for project '{project.id}'; use one of "
                   f"{', '.join(c.uri for c in offered)}", field=what)


@dataclass(frozen=True)
class ItemQuery:
    """What a page of items asks for. ``bbox`` is (min x, min y, max x, max y) in
    ``bbox_crs``'s axis order; ``start``/``end`` an inclusive time interval (UTC-aware)."""

    limit: int = DEFAULT_LIMIT
    offset: int = 0
    crs: str | None = None
    bbox: tuple[float, float, float, float] | None = None
    bbox_crs: str | None = None
    start: datetime | None = None
    end: datetime | None = None
    code: str | None = None


@dataclass
class ItemPage:
    """A page of GeoJSON features, how many match in all, the CRS of their coordinates and the
    latest change among them (ISO 8601 UTC)."""

    features: list[JSONObject]
    number_matched: int
    crs: OutputCRS
    last_modified: str


# -- parameters --------------------------------------------------------------------------

def parse_bbox(text: str) -> tuple[float, float, float, float]:
    """'minx,miny,maxx,maxy' (or six numbers with heights, whose heights are not used)."""
    parts = text.split(",")
    if len(parts) not in (4, 6):
        raise InputError(f"expected 4 or 6 comma-separated numbers, got {len(parts)}", field="bbox")
    try:
        v = [number_text(p, "bbox") for p in parts]
    except InputError as exc:
        raise InputError(f"{text[:80]!r} is not a list of numbers: {exc.problem}",
                         field="bbox") from None
    x0, y0, x1, y1 = (v[0], v[1], v[2], v[3]) if len(v) == 4 else (v[0], v[1], v[3], v[4])
    if y0 > y1:
        raise InputError(f"the lower corner's second coordinate ({y0}) is above the upper "
                         f"one's ({y1})", field="bbox")
    return x0, y0, x1, y1


def _instant(text: str, end: bool, field: str) -> datetime:
    """An RFC 3339 date-time (with its offset) or a full date (the whole UTC day: its start,
    or with ``end`` its last microsecond)."""
    try:
        if len(text) == 10:
            d = date.fromisoformat(text)
            t = datetime.combine(d, time(0), UTC)
            return t + timedelta(days=1, microseconds=-1) if end else t
        t = datetime.fromisoformat(text.replace("z", "Z").replace("t", "T"))
        if t.tzinfo is not None:
            return t.astimezone(UTC)
    except ValueError:
        raise InputError(f"{text[:80]!r} is not an RFC 3339 date-time such as "
                         "2026-11-24T15:00:00Z", field=field) from None
    except OverflowError:  # e.g. year 9999 plus a day, year 1 minus an hour
        raise InputError(f"{text[:80]!r} is out of the range of dates", field=field) from None
    raise InputError(f"{text[:80]!r} has no time zone (RFC 3339 needs one, e.g. Z)",
                     field=field)


def parse_datetime(text: str, field: str = "datetime"
                   ) -> tuple[datetime | None, datetime | None]:
    """An RFC 3339 instant or interval ('a/b', '../b', 'a/..', open ends also empty) as an
    inclusive (start, end); an instant is both."""
    if "/" not in text:
        return _instant(text, False, field), _instant(text, True, field)
    parts = text.split("/")
    if len(parts) != 2:
        raise InputError("an interval has exactly one '/'", field=field)
    a, b = (p.strip() for p in parts)
    start = None if a in ("", "..") else _instant(a, False, field)
    end = None if b in ("", "..") else _instant(b, True, field)
    if start is None and end is None:
        raise InputError("an interval needs at least one end", field=field)
    if start is not None and end is not None and start > end:
        raise InputError("the interval ends before it starts", field=field)
    return start, end


# -- the service ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Collection:
    """A collection: its project and layer."""

    project: Project
    layer: str

    @property
    def id(self) -> str:
        return f"{self.project.id}.{self.layer}"


class FeatureService:
    """Collections and features over the project service's store (one read transaction each)."""

    def __init__(self, projects: Projects) -> None:
        self.projects = projects

    def collections(self) -> list[Collection]:
        """Every project's layers, projects in creation order (an optional layer only where
        the project holds something of it)."""
        out = []
        with self.projects.store.transaction(write=False) as tx:
            for p in tx.list_projects():
                out += [Collection(p, layer) for layer in LAYERS
                        if layer not in OPTIONAL_LAYERS or _holds(tx, p.id, layer)]
        return out

    def collection(self, cid: str) -> Collection:
        """The collection ``{pid}.{layer}``; NotFoundError when there is none."""
        pid, _, layer = cid.rpartition(".")
        if not pid or layer not in LAYERS:
            raise NotFoundError(f"no collection '{cid}': collections are named "
                                f"PROJECT.{'|'.join(LAYERS)}")
        with self.projects.store.transaction(write=False) as tx:
            p = tx.get_project(pid)
            holds = layer not in OPTIONAL_LAYERS or p is None or _holds(tx, pid, layer)
        if p is None:
            raise NotFoundError(f"no collection '{cid}': project '{pid}' does not exist")
        if not holds:
            raise NotFoundError(f"no collection '{cid}': project '{pid}' has no {layer}")
        return Collection(p, layer)

    def items(self, cid: str, q: ItemQuery) -> ItemPage:
        """One page of a collection's features matching ``q``."""
        c = self.collection(cid)
        if self.projects.follow_scene(c.project.id):  # the scene moved without the store
            c = self.collection(cid)
        out = pick_crs(c.project, q.crs, "crs")
        if q.code is not None and "code" not in FILTERS[c.layer]:
            raise InputError(f"collection '{cid}' cannot be filtered by code", field="code")
        if (q.start or q.end) and c.layer not in TEMPORAL:
            raise InputError(f"the features of '{cid}' have no time to filter by",
                             field="datetime")
        box = None
        if q.bbox is not None:
            bcrs = pick_crs(c.project, q.bbox_crs, "bbox-crs")
            x0, y0, x1, y1 = q.bbox
            if bcrs.northing_first:
                x0, y0, x1, y1 = y0, x0, y1, x1
            if not bcrs.grid and (y0 < -90 or y1 > 90):
                raise InputError("latitudes must be within -90 and 90", field="bbox")
            if not bcrs.grid and not (-180 <= x0 <= 180 and -180 <= x1 <= 180):
                raise InputError("longitudes must be within -180 and 180 (a box across the "
                                 "antimeridian has its west edge east of its east edge)",
                                 field="bbox")
            if bcrs.grid and x0 > x1:
                raise InputError("the lower corner's easting is beyond the upper one's",
                                 field="bbox")
            box = (bcrs, x0, y0, x1, y1)
        with self.projects.store.transaction(write=False) as tx:
            if c.layer == "points":
                where = PointFilter(code=q.code, measured_from=q.start, measured_to=q.end,
                                    box=None if box is None else (
                                        ("easting", "northing") if box[0].grid
                                        else ("lon", "lat")) + box[1:])
                n = tx.count_point_records(c.project.id, where)
                rows = tx.page_point_records(c.project.id, where, q.offset, q.limit)
                feats = [point_feature(r.id, r.record | r.provenance, out) for r in rows]
                stamps = [r.updated_at for r in rows]
            else:
                every, stamps = self._layer(tx, c, out, q.start, q.end, box)
                n = len(every)
                feats = every[q.offset:q.offset + q.limit]
        return ItemPage(feats, n, out, max([c.project.updated_at, *stamps]))

    def item(self, cid: str, fid: str, crs: str | None = None) -> ItemPage:
        """One feature (a page of one); NotFoundError when the collection has no ``fid``."""
        c = self.collection(cid)
        if self.projects.follow_scene(c.project.id):
            c = self.collection(cid)
        out = pick_crs(c.project, crs, "crs")
        with self.projects.store.transaction(write=False) as tx:
            if c.layer == "points":
                pt = tx.get_point(c.project.id, fid)
                if pt is not None and pt.record is not None:
                    return ItemPage([point_feature(pt.id, pt.record | provenance(
                        pt.rays, pt.measured_by), out)], 1, out,
                                    max(pt.updated_at, c.project.updated_at))
            else:
                every, stamps = self._layer(tx, c, out)
                for f in every:
                    if f["id"] == fid:
                        return ItemPage([f], 1, out, max([c.project.updated_at, *stamps]))
        raise NotFoundError(f"collection '{cid}' has no feature '{fid}'")

    # the small layers, built whole through the export's collect -------------------------
    def _layer(self, tx: Transaction, c: Collection, out: OutputCRS,
               start: datetime | None = None, end: datetime | None = None,
               box: tuple[OutputCRS, float, float, float, float] | None = None,
               ) -> tuple[list[JSONObject], list[str]]:
        """Every feature of a small layer in ``out`` (within ``start``-``end`` and meeting
        ``box``, given in its own CRS), and the change times of what they are made of."""
        p = c.project
        if not p.crs:  # these layers are grid layers, as in the export
            return [], []

        def build(crs: OutputCRS) -> tuple[list[JSONObject], list[str]]:
            if c.layer == "rays":
                return self._rays(tx, p, crs, start, end)
            if c.layer == "check_points":
                return self._check_points(tx, p, crs)
            if c.layer == "buildings":
                return self._buildings(tx, p, crs)
            return self._features(tx, p, crs, c.layer[:-1])

        feats, stamps = build(out)
        if box is not None:
            probe = feats if box[0].grid == out.grid else build(box[0])[0]
            keep = [_in_box(f, box) for f in probe]
            feats = [f for f, k in zip(feats, keep, strict=True) if k]
        return feats, stamps

    def _features(self, tx: Transaction, p: Project, out: OutputCRS,
                  kind: str) -> tuple[list[JSONObject], list[str]]:
        feats = tx.list_features(p.id, kind)
        if not feats:
            return [], []
        records: dict[str, JSONObject | None] = {}
        stamps = [f.updated_at for f in feats]
        for q in {q for f in feats for q in f.point_ids}:
            pt = tx.get_point(p.id, q)
            if pt is not None:
                records[q] = pt.record
                stamps.append(pt.updated_at)
        # as the export does: a line or polygon whose measures cannot be computed is left out
        kept = [f for f in feats if "error" not in feature_measures(f, records, p)]
        used = {q for f in kept for q in f.point_ids}
        recs = [r for q, r in records.items() if q in used and r is not None]
        if not kept:
            return [], stamps
        shapes = [{"id": f.id, "points": f.point_ids} for f in kept]
        data = collect(recs, lines=shapes if kind == "line" else (),
                       polygons=shapes if kind == "polygon" else (), map_layers=False)
        table = data.lines if kind == "line" else data.polygons
        index = data.line_index if kind == "line" else data.polygon_index
        if table is None:
            return [], stamps
        xyz = _coords(data.point_xyz, data.point_llh, out)
        props = _rows(table.columns)
        result = []
        for f, prop, idx in zip(kept, props, index, strict=True):
            if kind == "line":
                geom = {"type": "LineString", "coordinates": xyz[idx].tolist()}
            else:
                ring = np.append(idx, idx[0])
                geom = {"type": "Polygon", "coordinates": [xyz[ring].tolist()]}
            result.append({"type": "Feature", "id": f.id, "geometry": geom, "properties": prop})
        return result, stamps

    def _buildings(self, tx: Transaction, p: Project,
                   out: OutputCRS) -> tuple[list[JSONObject], list[str]]:
        """One feature per surface of each building that builds now (as the export: one that
        cannot is left out); properties the GeoPackage buildings layer's."""
        stored = tx.list_buildings(p.id)
        stamps = [b.updated_at for b in stored]
        for q in {q for b in stored for q in spec_point_ids(b.spec)}:
            pt = tx.get_point(p.id, q)
            if pt is not None:
                stamps.append(pt.updated_at)
        models = [r.model for r in (self.projects.built_in(tx, p, b) for b in stored)
                  if r.model is not None]
        got = building_table(models)
        if got is None:
            return [], stamps
        table, rings = got
        xyz = np.vstack(rings)
        if not out.grid:
            settings = solve_settings(p.settings(), self.projects.data_dir)
            try:
                lon, lat, h = ecef_to_geodetic_closed_form(grid_to_ecef(xyz, settings))
            except GsgeoError:
                return [], stamps
            xyz = np.column_stack([lon, lat, h])
        xyz = _axis_order(xyz, out)
        ends = np.cumsum([len(r) for r in rings])
        result = []
        for prop, ring in zip(_rows(table.columns), np.split(xyz, ends[:-1]), strict=True):
            closed = np.vstack([ring, ring[:1]])
            result.append({"type": "Feature",
                           "id": f"{prop['building_id']}~{prop['surface_index']}",
                           "geometry": {"type": "Polygon", "coordinates": [closed.tolist()]},
                           "properties": prop})
        return result, stamps

    def _check_points(self, tx: Transaction, p: Project,
                      out: OutputCRS) -> tuple[list[JSONObject], list[str]]:
        cps = tx.list_check_points(p.id)
        if not cps:
            return [], []
        stamps = [c.created_at for c in cps]
        enh = check_points_in_grid(cps, p, data_dir=self.projects.data_dir)
        recs = []
        for c in cps:
            pt = tx.get_point(p.id, c.id)
            if pt is not None and pt.record is not None:
                recs.append(pt.record)
                stamps.append(pt.updated_at)
        check = [{"id": c.id, "role": c.role, "description": c.description,
                  "easting": float(x[0]), "northing": float(x[1]),
                  "height": None if not math.isfinite(x[2]) else float(x[2])}
                 for c, x in zip(cps, enh, strict=True)]
        if recs:
            data = collect(recs, check_points=check, map_layers=False)
            props = _rows(data.check_points.columns) if data.check_points is not None else []
        else:  # nothing measured yet: no differences
            props = [dict.fromkeys(CHECK_POINT_TYPES) | {
                "point_id": k["id"], "role": k["role"], "description": k["description"],
                "easting": k["easting"],
                "northing": k["northing"], "height": k["height"], "measured": False}
                for k in check]
        has_h = np.isfinite(enh[:, 2])
        if out.grid:
            xyz = enh.copy()
        else:
            settings = solve_settings(p.settings(), self.projects.data_dir)
            filled = np.where(has_h[:, None], enh, np.column_stack([enh[:, :2], np.zeros(len(enh))]))
            try:
                lon, lat, h = ecef_to_geodetic_closed_form(grid_to_ecef(filled, settings))
            except GsgeoError:
                return [], stamps
            xyz = np.column_stack([lon, lat, h])
        xyz = _axis_order(xyz, out)
        result = []
        for c, prop, pos, hh in zip(cps, props, xyz, has_h, strict=True):
            coords = pos.tolist() if hh else pos[:2].tolist()
            result.append({"type": "Feature", "id": c.id, "properties": prop | {"role": c.role},
                           "geometry": {"type": "Point", "coordinates": coords}})
        return result, stamps

    def _rays(self, tx: Transaction, p: Project, out: OutputCRS, start: datetime | None,
              end: datetime | None) -> tuple[list[JSONObject], list[str]]:
        when = PointFilter(measured_from=start, measured_to=end)
        pts = tx.list_points(p.id)
        stamps = [q.updated_at for q in pts]
        # the points with rays in the grid (every solved point of a project with a grid CRS)
        results: list[JSONObject] = [
            q.result for q in pts if q.result is not None and q.record is not None
            and when.matches(q.record) and q.result.get("rays")
            and all(r.get("origin_grid") is not None for r in q.result["rays"])]
        if not results:
            return [], stamps
        data: ExportData = collect(results)
        if data.rays is None or data.ray_xyz is None:
            return [], stamps
        seg = data.ray_xyz.copy()
        if not out.grid:
            org = np.array([r["origin_ecef"] for res in results for r in res["rays"]],
                           dtype=np.float64).reshape(-1, 3)
            lon, lat, h = ecef_to_geodetic_closed_form(org)
            owner = np.repeat(np.arange(len(results)),
                              [len(res["rays"]) for res in results])
            seg[:, 0] = np.column_stack([lon, lat, h])
            seg[:, 1] = data.point_llh[owner]
        seg = _axis_order(seg.reshape(-1, 3), out).reshape(-1, 2, 3)
        props = _rows(data.rays.columns)
        feats = [{"type": "Feature", "id": f"{prop['point_id']}~{prop['ray_index']}",
                  "geometry": {"type": "LineString", "coordinates": s.tolist()},
                  "properties": prop} for prop, s in zip(props, seg, strict=True)]
        return feats, stamps


def _holds(tx: Transaction, pid: str, layer: str) -> bool:
    """Whether project ``pid`` holds something of the optional ``layer``."""
    return layer == "buildings" and bool(tx.list_buildings(pid))


# -- GeoJSON building ---------------------------------------------------------------------

def point_feature(fid: str, record: JSONObject, out: OutputCRS) -> JSONObject:
    """A point's GeoJSON feature: its record as properties; [lon, lat, h_wgs84] in CRS84 or
    [E, N, H] in the grid (N, E, H where the CRS's first axis is northing)."""
    if out.grid:
        pos = [record.get("easting"), record.get("northing"), record.get("height")]
        if out.northing_first:
            pos[0], pos[1] = pos[1], pos[0]
    else:
        pos = [record.get("lon"), record.get("lat"), record.get("h_wgs84")]
    if pos[0] is None or pos[1] is None:
        geom = None
    else:
        geom = {"type": "Point", "coordinates": pos if pos[2] is not None else pos[:2]}
    return {"type": "Feature", "id": fid, "geometry": geom, "properties": record}


def _coords(xyz: np.ndarray, llh: np.ndarray, out: OutputCRS) -> np.ndarray:
    return _axis_order(xyz if out.grid else llh, out)


def _axis_order(xyz: np.ndarray, out: OutputCRS) -> np.ndarray:
    return xyz[:, [1, 0, 2]] if out.grid and out.northing_first else xyz


def _rows(columns: dict[str, np.ndarray]) -> list[JSONObject]:
    """Table columns as one dict per row, JSON values (NaN -> None)."""
    names = list(columns)
    cols = [_json_values(columns[k]) for k in names]
    return [dict(zip(names, vals, strict=True)) for vals in zip(*cols, strict=True)]


def _json_values(col: np.ndarray) -> list[Any]:
    if col.dtype.kind == "f":
        return [None if not math.isfinite(v) else v for v in col.tolist()]
    return col.tolist()


def _in_box(f: JSONObject, box: tuple[OutputCRS, float, float, float, float]) -> bool:
    """Whether a feature's envelope meets the box; the feature's coordinates are in the box's
    CRS (its axis order), the box's corners easting (longitude) first."""
    crs, x0, y0, x1, y1 = box
    pts = list(_positions(f["geometry"]["coordinates"]))
    if not pts:
        return False
    if crs.grid and crs.northing_first:
        pts = [(q[1], q[0]) for q in pts]
    xs, ys = [q[0] for q in pts], [q[1] for q in pts]
    if max(ys) < y0 or min(ys) > y1:
        return False
    if x0 <= x1:
        return not (max(xs) < x0 or min(xs) > x1)
    return max(xs) >= x0 or min(xs) <= x1


def _positions(coords: Any) -> Iterable[Sequence[float]]:
    if coords and isinstance(coords[0], (int, float)):
        yield coords
        return
    for c in coords:
        yield from _positions(c)
