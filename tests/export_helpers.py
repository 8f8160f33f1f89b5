"""A synthetic measured scene for export tests: points around a house near Coventry (lon -1.5,
lat 52.5, inside EPSG:27700, UTM zone 30N and EGM96), lines and polygons by point id, and a fake
OSGM15 geoid so EPSG:27700+5701 heights can be computed offline."""

from __future__ import annotations

import contextlib

import numpy as np
import pyproj
import rasterio
from affine import Affine
from crs_helpers import camera_origins, noisy_directions

from gsgeo.crs.frames import EnuFrame, geodetic_to_ecef
from gsgeo.session import parse_session

LON0, LAT0, H0 = -1.5, 52.5, 95.0
IFOV = 0.0008
#: Local east, north, up offsets (m) of the points from (LON0, LAT0, H0).
LAYOUT = {
    "P1": (0.0, 0.0, 0.0), "P2": (10.0, 0.0, 0.5), "P3": (10.0, 8.0, 1.0),
    "P4": (0.0, 8.0, 0.2), "P5": (5.0, 4.0, 6.0), "P6": (15.0, -3.0, 0.0),
}
UNWEIGHTED = {"P6"}  # no ifov: unweighted model, max_residual_px null


def session_doc(rng, *, crs=None, lines=None, polygons=None, points=LAYOUT) -> dict:
    centre = geodetic_to_ecef(LON0, LAT0, H0).reshape(3)
    frame = EnuFrame(centre)
    pts = []
    for k, (pid, enu) in enumerate(points.items()):
        p = frame.to_ecef(np.array(enu, dtype=float))
        o = camera_origins(p, 4 + k % 2, rng)
        d = noisy_directions(o, p, IFOV, rng)
        rays = []
        for oo, dd in zip(o, d, strict=True):
            ray = {"origin": oo.tolist(), "direction": dd.tolist()}
            if pid not in UNWEIGHTED:
                ray["ifov"] = IFOV
            rays.append(ray)
        pts.append({"id": pid, "code": "roof" if pid == "P5" else "corner",
                    "description": f"synthetic point {pid}", "rays": rays})
    doc = {"source_crs": "EPSG:4978", "crs": crs, "sigma_px": 1.0, "points": pts,
           "lines": [{"id": "L1", "points": ["P1", "P2", "P3"]}, {"id": "L2", "points": ["P5", "P6"]}]
           if lines is None else lines,
           # given clockwise in (E, N); exports must write it counterclockwise
           "polygons": [{"id": "A1", "points": ["P1", "P4", "P3", "P2"]}] if polygons is None else polygons}
    return doc


def session(rng, **kw):
    return parse_session(session_doc(rng, **kw))


def undulation(lon, lat):
    """Fake geoid undulation (m): smooth, about 48 m near the scene."""
    return 45.0 + 0.5 * (lon + 9.0) + 0.2 * (lat - 49.0)


def write_fake_osgm15(directory) -> None:
    """A GeoTIFF named as PROJ's OSGM15 grid (ETRS89 -> ODN), bilinear-exact for `undulation`."""
    res = 0.25
    west, north, cols, rows = -9.0, 61.0, 49, 49  # pixel centres on multiples of res
    lon = west + np.arange(cols) * res
    lat = north - np.arange(rows) * res
    n = undulation(lon[None, :], lat[:, None]).astype(np.float64)
    with rasterio.open(directory / "uk_os_OSGM15_GB.tif", "w", driver="GTiff", width=cols,
                       height=rows, count=1, dtype="float32", crs="EPSG:4258",
                       transform=Affine(res, 0, west - res / 2, 0, -res, north + res / 2)) as ds:
        ds.write(n.astype(np.float32), 1)


@contextlib.contextmanager
def proj_data_dir(path):
    """PROJ finds grids in `path` too, for the duration of the block."""
    original = pyproj.datadir.get_data_dir()
    try:
        pyproj.datadir.append_data_dir(str(path))
        yield
    finally:
        pyproj.datadir.set_data_dir(original)


def reference_geojson(data, grid: bool = False) -> dict:
    """The GeoJSON document of an ExportData built with dicts and the json module, as the first
    writer did: the properties of each table row in column order, NaN -> null, positions
    rounded (lon, lat 1e-9 degrees; heights and grid coordinates 0.1 mm), polygon rings
    counterclockwise in the coordinates written, check points without geometry in RFC 7946."""
    import json
    import math

    from gsgeo.export.geojson import collection_header

    def rows(table):
        cols = []
        for name, col in table.columns.items():
            if table.types[name] == "float":
                cols.append([v if math.isfinite(v) else None for v in np.asarray(col, float).tolist()])
            elif table.types[name] in ("int", "bool"):
                cols.append(np.asarray(col).tolist())
            else:
                cols.append(list(col))
        return [dict(zip(table.columns, r, strict=True)) for r in zip(*cols, strict=True)]

    xyz = data.point_xyz if grid else data.point_llh
    pos = np.round(xyz, 4) if grid else np.column_stack([np.round(xyz[:, :2], 9), np.round(xyz[:, 2], 4)])
    pos = pos.tolist()
    feats = [{"type": "Feature", "id": p["point_id"], "geometry": {"type": "Point", "coordinates": q},
              "properties": {"layer": "points", **p}} for q, p in zip(pos, rows(data.points), strict=True)]
    meta = {"crs": data.crs, "height_type": data.height_type}
    for layer, table, index, key in (("lines", data.lines, data.line_index, "line_id"),
                                     ("polygons", data.polygons, data.polygon_index, "polygon_id")):
        if table is None:
            continue
        for idx, p in zip(index, rows(table), strict=True):
            p["point_ids"] = json.loads(p["point_ids"])
            ring = [int(i) for i in idx]
            if layer == "lines":
                geom = {"type": "LineString", "coordinates": [pos[i] for i in ring]}
            else:
                r = np.array([xyz[i, :2] for i in ring + ring[:1]])
                if np.sum(r[:-1, 0] * r[1:, 1] - r[1:, 0] * r[:-1, 1]) < 0:
                    ring = ring[::-1]
                geom = {"type": "Polygon", "coordinates": [[pos[i] for i in ring + ring[:1]]]}
            feats.append({"type": "Feature", "id": p[key], "geometry": geom,
                          "properties": {"layer": layer, **p, **meta}})
    if data.check_points is not None:
        for c, p in zip(data.check_xyz, rows(data.check_points), strict=True):
            geom = None
            if grid:
                cc = c.tolist() if math.isfinite(c[2]) else c[:2].tolist()
                geom = {"type": "Point", "coordinates": [round(v, 4) for v in cc]}
            feats.append({"type": "Feature", "id": p["point_id"], "geometry": geom,
                          "properties": {"layer": "check_points", **p, **meta}})
    doc = collection_header(data, grid)    # the header members and their wording: the writer's own
    doc["features"] = feats
    return json.loads(json.dumps(doc, allow_nan=False))


def reference_csv(data) -> str:
    """The CSV of an ExportData's points written with the csv module, as the first writer did:
    repr() for full-precision floats, %-format for fixed decimals, empty for None and NaN
    (rows end in CRLF here so that csv.writer quotes a carriage return inside a field)."""
    import csv
    import io

    from gsgeo.export.csvfile import CSV_COLUMNS, FIXED_DECIMALS

    t = data.points
    cols = []
    for k in CSV_COLUMNS:
        kind = t.types[k]
        if kind == "str":
            cols.append(["" if v is None else v for v in t.columns[k]])
        elif kind == "int":
            cols.append([str(v) for v in np.asarray(t.columns[k]).tolist()])
        else:
            fmt = f"%.{FIXED_DECIMALS[k]}f" if k in FIXED_DECIMALS else None
            cols.append(["" if not np.isfinite(v) else (fmt % v if fmt else repr(v))
                         for v in np.asarray(t.columns[k], dtype=float).tolist()])
    buf = io.StringIO(newline="")
    w = csv.writer(buf, lineterminator="\r\n")  # "\r" in a field is quoted only then
    w.writerow(CSV_COLUMNS)
    w.writerows(zip(*cols, strict=True))
    return buf.getvalue()
