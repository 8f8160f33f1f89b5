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
from collections.abc import Iterator
from pathlib import Path
from typing import cast

import numpy as np
import orjson

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


def _json_values(col: np.ndarray, kind: str) -> list[bytes]:
    """One JSON text per value of a column (orjson: shortest round-trip floats, NaN -> null)."""
    if kind == "str":
        return list(map(orjson.dumps, col))
    if len(col) == 0:
        return []
    if kind == "float":
        text = orjson.dumps(np.ascontiguousarray(col, dtype=np.float64), option=orjson.OPT_SERIALIZE_NUMPY)
    else:  # int, bool
        text = orjson.dumps(np.asarray(col).tolist())
    return text[1:-1].split(b",")


def _template(layer: str, table: Table, id_key: str, meta: dict) -> bytes:
    """%-template of one feature: %b for the id, the geometry and each property, in order."""
    props = [orjson.dumps("layer") + b":" + orjson.dumps(layer)]
    props += [orjson.dumps(k).replace(b"%", b"%%") + b":%b" for k in table.columns]
    props += [orjson.dumps(k).replace(b"%", b"%%") + b":" + orjson.dumps(v).replace(b"%", b"%%")
              for k, v in meta.items()]
    return b'{"type":"Feature","id":%b,"geometry":%b,"properties":{' + b",".join(props) + b"}}"


def _features(layer: str, table: Table, id_key: str, geometry: list[bytes], meta: dict,
              start: int, stop: int) -> list[bytes]:
    """JSON texts of the features start..stop of one table (properties in column order)."""
    cols = []
    for name, col in table.columns.items():
        kind = table.types[name]
        if name == "point_ids":  # already a JSON array of the ids
            cols.append([v.encode() for v in col[start:stop]])
        else:
            cols.append(_json_values(col[start:stop], kind))
    ids = cols[list(table.columns).index(id_key)]
    tmpl = _template(layer, table, id_key, meta)
    return [tmpl % row for row in zip(ids, geometry[start:stop], *cols, strict=True)]


def _ccw(ring: np.ndarray) -> bool:
    x, y = ring[:, 0] - ring[:, 0].mean(), ring[:, 1] - ring[:, 1].mean()
    return float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)) > 0


def _positions(xyz: np.ndarray, grid: bool) -> np.ndarray:
    """Positions as written: grid E, N, H to 0.1 mm; or lon, lat to 1e-9 degrees and h to 0.1 mm."""
    if grid:
        return np.round(xyz, HEIGHT_DECIMALS)
    out = np.empty_like(xyz)
    out[:, :2] = np.round(xyz[:, :2], LONLAT_DECIMALS)
    out[:, 2] = np.round(xyz[:, 2], HEIGHT_DECIMALS)
    return out


def _point_geometries(pos: np.ndarray) -> list[bytes]:
    x, y, z = (_json_values(pos[:, k], "float") for k in range(3))
    return [b'{"type":"Point","coordinates":[%b,%b,%b]}' % c for c in zip(x, y, z, strict=True)]


def _layers(data: ExportData, grid: bool
            ) -> Iterator[tuple[str, Table, str, list[bytes], dict[str, str]]]:
    """(layer, table, id column, geometry JSON texts, constant properties) of each layer."""
    xyz = data.point_xyz if grid else data.point_llh
    pos = _positions(xyz, grid)
    yield "points", data.points, "point_id", _point_geometries(pos), {}
    meta = {"crs": data.crs, "height_type": data.height_type}
    plist = pos.tolist()
    if data.lines is not None:
        geoms = [orjson.dumps({"type": "LineString", "coordinates": [plist[i] for i in idx]})
                 for idx in data.line_index]
        yield "lines", data.lines, "line_id", geoms, meta
    if data.polygons is not None:
        geoms = []
        for idx in data.polygon_index:
            ring = list(idx)
            if not _ccw(xyz[ring, :2]):  # right-hand rule in the coordinates written
                ring = ring[::-1]
            geoms.append(orjson.dumps({"type": "Polygon",
                                       "coordinates": [[plist[i] for i in ring + ring[:1]]]}))
        yield "polygons", data.polygons, "polygon_id", geoms, meta
    if data.check_points is not None:
        geoms = []
        for c in cast(np.ndarray, data.check_xyz):  # set with check_points
            if not grid:
                geoms.append(b"null")
                continue
            coords = c.tolist() if math.isfinite(c[2]) else c[:2].tolist()
            geoms.append(orjson.dumps({"type": "Point",
                                       "coordinates": [round(v, HEIGHT_DECIMALS) for v in coords]}))
        yield "check_points", data.check_points, "point_id", geoms, meta


def collection_header(data: ExportData, grid: bool) -> dict:
    """The FeatureCollection members before `features`: `type`, and `description` (plus `crs`
    and `rfc7946: false` for the legacy grid variant)."""
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
    return doc


def feature_collection(data: ExportData, *, grid: bool = False) -> dict:
    """The GeoJSON document (a dict) for `data`; grid=True gives the legacy grid variant."""
    doc = collection_header(data, grid)
    features = []
    for layer, table, id_key, geoms, meta in _layers(data, grid):
        features += [orjson.loads(f) for f in _features(layer, table, id_key, geoms, meta, 0,
                                                        len(table))]
    doc["features"] = features
    return doc


def write_geojson(path: Path, data: ExportData, *, grid: bool = False) -> None:
    """Write `data` as GeoJSON to a new file at `path` (UTF-8).

    Each feature is one %-template filled with the JSON texts of its values; a column's values
    are encoded at once by orjson (shortest round-trip floats), FEATURE_CHUNK rows at a time
    to bound memory for large exports.
    """
    head = json.dumps(collection_header(data, grid), ensure_ascii=False, allow_nan=False,
                      separators=(",", ":")).encode()
    with open(path, "xb") as fh:
        fh.write(head[:-1] + b',"features":[')
        first = True
        for layer, table, id_key, geoms, meta in _layers(data, grid):
            for k in range(0, len(table), FEATURE_CHUNK):
                if not first:
                    fh.write(b",")
                first = False
                fh.write(b",".join(_features(layer, table, id_key, geoms, meta, k,
                                             k + FEATURE_CHUNK)))
        fh.write(b"]}\n")
