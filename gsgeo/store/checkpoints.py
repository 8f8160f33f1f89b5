"""Reading check points (ground truth or control) from CSV, GeoJSON or GeoPackage.

Every file yields (id, x, y, z) in the CRS the user states, x = easting (or longitude), y =
northing (or latitude), z = height or None. The id column is the first of ``point_id``, ``id``,
``name``, ``label`` found (case-insensitive); CSV coordinates come from ``easting/northing/
height``, ``e/n/h``, ``x/y/z`` or ``lon/lat/h``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import warnings
from dataclasses import dataclass
from typing import Any

from gsgeo.errors import InputError
from gsgeo.store.validate import item_id

ID_COLUMNS = ("point_id", "id", "name", "label")
X_COLUMNS = ("easting", "e", "x", "lon", "longitude")
Y_COLUMNS = ("northing", "n", "y", "lat", "latitude")
Z_COLUMNS = ("height", "h", "z", "elevation", "alt", "h_wgs84")
FORMATS = ("csv", "geojson", "gpkg")
MAX_CHECK_POINTS = 100_000


@dataclass
class CheckPointRow:
    id: str
    x: float
    y: float
    z: float | None


def format_from_name(filename: str | None) -> str | None:
    if not filename:
        return None
    suffix = filename.rsplit(".", 1)[-1].lower() if "." in filename else ""
    return {"csv": "csv", "txt": "csv", "geojson": "geojson", "json": "geojson",
            "gpkg": "gpkg"}.get(suffix)


def _num(value: Any, where: str, optional: bool = False) -> float | None:
    if value is None or (isinstance(value, str) and not value.strip()):
        if optional:
            return None
        raise InputError(f"{where}: missing")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected a number, got {str(value)[:30]!r}") from None
    if not math.isfinite(v):
        if optional and math.isnan(v):
            return None
        raise InputError(f"{where}: expected a finite number")
    return v


def _pick(columns: list[str], names: tuple[str, ...]) -> str | None:
    lower = {c.strip().lower(): c for c in columns}
    for n in names:
        if n in lower:
            return lower[n]
    return None


def _read_csv(data: bytes) -> list[CheckPointRow]:
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError("file: a CSV file must be UTF-8 text") from None
    try:
        dialect = csv.Sniffer().sniff(text[:4096], delimiters=",;\t")
    except csv.Error:
        dialect = csv.excel
    reader = csv.DictReader(io.StringIO(text), dialect=dialect)
    cols = reader.fieldnames or []
    cid, cx, cy = _pick(cols, ID_COLUMNS), _pick(cols, X_COLUMNS), _pick(cols, Y_COLUMNS)
    cz = _pick(cols, Z_COLUMNS)
    if cid is None or cx is None or cy is None:
        raise InputError(
            "file: the CSV header needs an id column (point_id, id or name) and coordinate "
            f"columns (easting/northing[/height] or x/y[/z]); found {', '.join(cols)[:200]}")
    rows = []
    for i, r in enumerate(reader, start=2):
        where = f"file line {i}"
        rows.append(CheckPointRow(item_id(r.get(cid), f"{where}, column {cid}"),
                                  _num(r.get(cx), f"{where}, column {cx}"),
                                  _num(r.get(cy), f"{where}, column {cy}"),
                                  _num(r.get(cz), f"{where}, column {cz}", True) if cz else None))
    return rows


def _feature_id(props: dict, fallback: Any, where: str) -> str:
    for key in ID_COLUMNS:
        for k, v in props.items():
            if k.lower() == key and v is not None:
                return item_id(v, f"{where}.properties.{k}")
    if fallback is not None:
        return item_id(fallback, f"{where}.id")
    raise InputError(f"{where}: no point id (properties point_id, id or name)")


def _read_geojson(data: bytes) -> list[CheckPointRow]:
    try:
        doc = json.loads(data.decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"file: not valid GeoJSON: {exc}") from None
    if isinstance(doc, dict) and doc.get("type") == "Feature":
        doc = {"type": "FeatureCollection", "features": [doc]}
    if not isinstance(doc, dict) or not isinstance(doc.get("features"), list):
        raise InputError("file: expected a GeoJSON FeatureCollection")
    rows = []
    for i, f in enumerate(doc["features"]):
        where = f"features[{i}]"
        if not isinstance(f, dict):
            raise InputError(f"{where}: expected a Feature object")
        geom = f.get("geometry")
        if not isinstance(geom, dict) or geom.get("type") != "Point":
            raise InputError(f"{where}.geometry: expected a Point")
        c = geom.get("coordinates")
        if not isinstance(c, list) or len(c) not in (2, 3):
            raise InputError(f"{where}.geometry.coordinates: expected 2 or 3 numbers")
        props = f.get("properties") or {}
        if not isinstance(props, dict):
            raise InputError(f"{where}.properties: expected an object")
        rows.append(CheckPointRow(
            _feature_id(props, f.get("id"), where),
            _num(c[0], f"{where}.geometry.coordinates[0]"),
            _num(c[1], f"{where}.geometry.coordinates[1]"),
            _num(c[2], f"{where}.geometry.coordinates[2]", True) if len(c) == 3 else None))
    return rows


def _read_gpkg(data: bytes) -> tuple[list[CheckPointRow], str | None]:
    import pyogrio

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            layers = pyogrio.list_layers(io.BytesIO(data))
            point_layers = [name for name, gt in layers if gt and "point" in str(gt).lower()]
            if not point_layers:
                raise InputError("file: the GeoPackage has no point layer")
            df = pyogrio.read_dataframe(io.BytesIO(data), layer=point_layers[0])
    except InputError:
        raise
    except Exception as exc:  # GDAL raises its own error types for unreadable files
        raise InputError(f"file: cannot be read as a GeoPackage: {exc}") from None
    cid = _pick([str(c) for c in df.columns if c != "geometry"], ID_COLUMNS)
    if cid is None:
        raise InputError(f"file: layer '{point_layers[0]}' has no point_id, id or name column")
    rows = []
    for i, (pid, geom) in enumerate(zip(df[cid], df.geometry, strict=True)):
        where = f"layer {point_layers[0]} feature {i}"
        if geom is None or geom.geom_type != "Point":
            raise InputError(f"{where}: expected a Point geometry")
        z = geom.z if geom.has_z else None
        rows.append(CheckPointRow(item_id(pid, f"{where}, column {cid}"),
                                  _num(geom.x, f"{where} x"), _num(geom.y, f"{where} y"),
                                  _num(z, f"{where} z", True)))
    crs = None
    if df.crs is not None:
        epsg = df.crs.to_epsg()
        crs = f"EPSG:{epsg}" if epsg else df.crs.to_wkt()
    return rows, crs


def read_check_points(data: bytes, fmt: str) -> tuple[list[CheckPointRow], str | None]:
    """Rows of a check-point file and the CRS the file itself declares (GeoPackage only)."""
    if fmt not in FORMATS:
        raise InputError(f"format: must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if fmt == "csv":
        rows, crs = _read_csv(data), None
    elif fmt == "geojson":
        rows, crs = _read_geojson(data), None
    else:
        rows, crs = _read_gpkg(data)
    if not rows:
        raise InputError("file: contains no check points")
    if len(rows) > MAX_CHECK_POINTS:
        raise InputError(f"file: more than {MAX_CHECK_POINTS} check points")
    seen: set[str] = set()
    for r in rows:
        if r.id in seen:
            raise InputError(f"file: duplicate point id '{r.id}'")
        seen.add(r.id)
    return rows, crs
