"""GeoJSON writers: RFC 7946 (WGS 84 longitude, latitude, ellipsoidal height) and legacy grid.

RFC 7946 (the default): positions are [longitude, latitude, h] on WGS 84, h the WGS 84
ellipsoidal height that gsgeo.crs computed from the georeferenced ECEF point; every grid value
(easting, northing, height, sigmas, covariances, ellipse, CRS, height type) is in the
properties; no ``crs`` member; polygon rings counterclockwise (right-hand rule). Longitude and
latitude are rounded to 1e-9 degrees (0.1 mm), h to 0.1 mm; properties keep full precision.

One FeatureCollection holds the points, lines and polygons; each feature's ``layer`` property
says which. Check points, known only in the grid CRS, are features with ``"geometry": null``
and their grid coordinates in the properties (a datum transformation to WGS 84 would move
them by metres relative to the measured points). Rays and error ellipses are GeoPackage-only.

Legacy grid (``geojson-grid``): positions [easting, northing, height] in the grid CRS with a
``crs`` member (the 2008 GeoJSON draft); marked ``"rfc7946": false``. Many tools still read
it; RFC 7946 readers must not be given it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from gsgeo.crs.resolve import parse_crs
from gsgeo.export.tables import ExportData, Table

LONLAT_DECIMALS = 9
HEIGHT_DECIMALS = 4
FEATURE_CHUNK = 5000


def crs_urn(text: str) -> str:
    """OGC URN of a CRS: urn:ogc:def:crs:EPSG::27700, compound urn:ogc:def:crs,crs:EPSG::..,crs:..."""
    crs = parse_crs(text)
    auth = crs.to_authority(min_confidence=100)
    if auth:
        return f"urn:ogc:def:crs:{auth[0]}::{auth[1]}"
    if crs.is_compound:
        parts = [c.to_authority(min_confidence=100) for c in crs.sub_crs_list]
        if all(parts):
            return "urn:ogc:def:crs," + ",".join(f"crs:{a}::{c}" for a, c in parts)
    return crs.to_wkt()  # no code: the WKT itself is the best name there is


def _rows(table: Table) -> list[dict]:
    """Properties dictionaries (NaN -> null) from a table's columns."""
    keys, cols = [], []
    for name, col in table.columns.items():
        kind = table.types[name]
        if kind == "float":
            arr = np.asarray(col, dtype=np.float64)
            vals = arr.tolist()
            if not np.all(np.isfinite(arr)):
                vals = [v if math.isfinite(v) else None for v in vals]
        elif kind in ("int", "bool"):
            vals = np.asarray(col).tolist()
        else:
            vals = list(col)
        keys.append(name)
        cols.append(vals)
    return [dict(zip(keys, row, strict=True)) for row in zip(*cols, strict=True)]


def _ccw(ring: np.ndarray) -> bool:
    x, y = ring[:, 0] - ring[:, 0].mean(), ring[:, 1] - ring[:, 1].mean()
    return float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)) > 0


def _positions(xyz: np.ndarray, grid: bool) -> list:
    if grid:
        return np.round(xyz, HEIGHT_DECIMALS).tolist()
    out = np.empty_like(xyz)
    out[:, :2] = np.round(xyz[:, :2], LONLAT_DECIMALS)
    out[:, 2] = np.round(xyz[:, 2], HEIGHT_DECIMALS)
    return out.tolist()


def feature_collection(data: ExportData, *, grid: bool = False) -> dict:
    """The GeoJSON document (a dict) for `data`; grid=True gives the legacy grid variant."""
    xyz = data.point_xyz if grid else data.point_llh
    pos = _positions(xyz, grid)
    features: list[dict] = []
    for p, props in zip(pos, _rows(data.points), strict=True):
        features.append({"type": "Feature", "id": props["point_id"],
                         "geometry": {"type": "Point", "coordinates": p},
                         "properties": {"layer": "points", **props}})
    meta = {"crs": data.crs, "height_type": data.height_type}
    if data.lines is not None:
        for idx, props in zip(data.line_index, _rows(data.lines), strict=True):
            props["point_ids"] = json.loads(props["point_ids"])
            features.append({"type": "Feature", "id": props["line_id"],
                             "geometry": {"type": "LineString", "coordinates": [pos[i] for i in idx]},
                             "properties": {"layer": "lines", **props, **meta}})
    if data.polygons is not None:
        for idx, props in zip(data.polygon_index, _rows(data.polygons), strict=True):
            ring = list(idx)
            if not _ccw(xyz[ring, :2]):  # right-hand rule in the coordinates written
                ring = ring[::-1]
            props["point_ids"] = json.loads(props["point_ids"])
            features.append({"type": "Feature", "id": props["polygon_id"],
                             "geometry": {"type": "Polygon",
                                          "coordinates": [[pos[i] for i in ring + ring[:1]]]},
                             "properties": {"layer": "polygons", **props, **meta}})
    if data.check_points is not None:
        for k, props in enumerate(_rows(data.check_points)):
            geom = None
            if grid:
                c = data.check_xyz[k]
                coords = c.tolist() if math.isfinite(c[2]) else c[:2].tolist()
                geom = {"type": "Point", "coordinates": [round(v, HEIGHT_DECIMALS) for v in coords]}
            features.append({"type": "Feature", "id": props["point_id"], "geometry": geom,
                             "properties": {"layer": "check_points", **props, **meta}})
    doc: dict = {"type": "FeatureCollection"}
    if grid:
        doc["crs"] = {"type": "name", "properties": {"name": crs_urn(data.crs)}}
        doc["rfc7946"] = False
        doc["description"] = (
            f"Legacy GeoJSON with grid coordinates (easting, northing, height) in {data.crs} and "
            "a crs member; NOT RFC 7946. Use the default GeoJSON export for RFC 7946 readers.")
    else:
        doc["description"] = (
            "RFC 7946: longitude, latitude (degrees) and ellipsoidal height (m) on WGS 84; grid "
            f"coordinates in {data.crs} in the properties.")
    doc["features"] = features
    return doc


def write_geojson(path: Path, data: ExportData, *, grid: bool = False) -> None:
    """Write `data` as GeoJSON to a new file at `path` (UTF-8).

    Features are encoded in chunks with json.dumps (the C encoder; json.dump's incremental
    encoder is pure Python and several times slower) to bound memory for large exports.
    """
    doc = feature_collection(data, grid=grid)
    features = doc.pop("features")
    opts = {"ensure_ascii": False, "allow_nan": False, "separators": (",", ":")}
    head = json.dumps(doc, **opts)
    with open(path, "x", encoding="utf-8") as fh:
        fh.write(head[:-1] + ',"features":[')
        for k in range(0, len(features), FEATURE_CHUNK):
            if k:
                fh.write(",")
            fh.write(json.dumps(features[k:k + FEATURE_CHUNK], **opts)[1:-1])
        fh.write("]}\n")
