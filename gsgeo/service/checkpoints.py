"""Reading check points (ground truth or control) from CSV, GeoJSON or GeoPackage.

Every file yields (id, x, y, z) in the CRS the user states, x = easting (or longitude), y =
northing (or latitude), z = height or None. The id column is the first of ``point_id``, ``id``,
``name``, ``label`` found (case-insensitive); CSV coordinates come from ``easting/northing/
height``, ``e/n/h``, ``x/y/z`` or ``lon/lat/h``.

The files come from users and the network, so reading is bounded: CSV fields up to the csv
module's field limit (128 KiB), JSON nesting up to orjson's depth limit (1024), numbers that
fit a double, at most ``MAX_CHECK_POINTS`` points (counted while reading), and GeoPackages
only when they are SQLite files (no other GDAL format, which could name files on the
server). Every failure is an InputError naming the file and what is wrong in it.
"""

from __future__ import annotations

import csv
import io
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, overload

import orjson

from gsgeo.errors import InputError
from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.limits import number_text
from gsgeo.service.validate import item_id

ID_COLUMNS = ("point_id", "id", "name", "label")
X_COLUMNS = ("easting", "e", "x", "lon", "longitude")
Y_COLUMNS = ("northing", "n", "y", "lat", "latitude")
Z_COLUMNS = ("height", "h", "z", "elevation", "alt", "h_wgs84")
SIGMA_H_COLUMNS = ("sigma_h", "sigma_horizontal", "sigma_en", "sigma_xy")
SIGMA_V_COLUMNS = ("sigma_v", "sigma_vertical", "sigma_z")
FORMATS = ("csv", "geojson", "gpkg")
MAX_CHECK_POINTS = 100_000
SQLITE_MAGIC = b"SQLite format 3\x00"


@dataclass
class CheckPointRow:
    """One point of a file: id, coordinates in the file's CRS, stated sigmas (m) or None."""

    id: str
    x: float
    y: float
    z: float | None
    sigma_h: float | None = None
    sigma_v: float | None = None
    description: str = ""


#: Columns (or properties) read as a point's description, the first found (case-insensitive).
DESCRIPTION_COLUMNS = ("description", "desc", "remark", "remarks", "note")
#: The longest description kept (characters).
MAX_DESCRIPTION = 300


def _description(value: JSON, field: str) -> str:
    """A point's description: text (a number is written as given), at most MAX_DESCRIPTION
    characters; empty when missing."""
    if value is None:
        return ""
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        raise InputError("expected text", field=field)
    text = str(value).strip()
    if len(text) > MAX_DESCRIPTION:
        raise InputError(f"longer than {MAX_DESCRIPTION} characters", field=field)
    return text


def _sigma(value: JSON, field: str) -> float | None:
    """A stated precision: empty/None, or a positive number of metres."""
    v = _num(value, field, True)
    if v is not None and not v > 0:
        raise InputError("a precision (sigma) must be a positive number of metres", field=field)
    return v


def _sigmas(get: dict[str, JSON], names: Sequence[str], at: str) -> tuple[float | None, float | None]:
    """(sigma_h, sigma_v) of one row given as {column: value}."""
    ch, cv = _pick(names, SIGMA_H_COLUMNS), _pick(names, SIGMA_V_COLUMNS)
    return (None if ch is None else _sigma(get.get(ch), f"{at}, column {ch}"),
            None if cv is None else _sigma(get.get(cv), f"{at}, column {cv}"))


def format_from_name(filename: str | None) -> str | None:
    if not filename:
        return None
    suffix = filename.rsplit(".", 1)[-1].lower() if "." in filename else ""
    return {"csv": "csv", "txt": "csv", "geojson": "geojson", "json": "geojson",
            "gpkg": "gpkg"}.get(suffix)


@overload
def _num(value: JSON, field: str, optional: Literal[False] = False) -> float: ...


@overload
def _num(value: JSON, field: str, optional: bool) -> float | None: ...


def _num(value: JSON, field: str, optional: bool = False) -> float | None:
    """A coordinate of a check-point file; ``field`` is where it is in the file (line and
    column of a CSV, JSON path of a GeoJSON)."""
    if value is None or (isinstance(value, str) and not value.strip()):
        if optional:
            return None
        raise InputError("missing", field=field)
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        raise InputError(f"expected a number, got {type(value).__name__}", field=field)
    if isinstance(value, str):  # ASCII decimals only; "nan" is an optional value left out
        text = value.strip()
        if optional and text.lower() == "nan":
            return None
        return number_text(text, field)
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"expected a number, got {str(value)[:30]!r}", field=field) from None
    except OverflowError:
        raise InputError("the number is too large", field=field) from None
    if not math.isfinite(v):
        if optional and math.isnan(v):
            return None
        raise InputError("expected a finite number", field=field)
    return v


def _pick(columns: Sequence[str], names: tuple[str, ...]) -> str | None:
    lower = {c.strip().lower(): c for c in columns}
    for n in names:
        if n in lower:
            return lower[n]
    return None


def _count(rows: list[CheckPointRow]) -> None:
    if len(rows) > MAX_CHECK_POINTS:
        raise InputError(f"more than {MAX_CHECK_POINTS} check points")


def _read_csv(data: bytes) -> list[CheckPointRow]:
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"a CSV file must be UTF-8 text (byte {exc.start} is not)") from None
    try:
        dialect = csv.Sniffer().sniff(text[:4096], delimiters=",;\t")
    except csv.Error:
        dialect = csv.excel
    reader = csv.DictReader(io.StringIO(text), dialect=dialect)
    rows: list[CheckPointRow] = []
    try:
        cols = reader.fieldnames or []
        cid, cx, cy = _pick(cols, ID_COLUMNS), _pick(cols, X_COLUMNS), _pick(cols, Y_COLUMNS)
        cz = _pick(cols, Z_COLUMNS)
        cd = _pick(cols, DESCRIPTION_COLUMNS)
        if cid is None or cx is None or cy is None:
            raise InputError(
                "the CSV header needs an id column (point_id, id or name) and coordinate "
                f"columns (easting/northing[/height] or x/y[/z]); found {', '.join(cols)[:200]!r}")
        for r in reader:
            at = f"line {reader.line_num}"
            rows.append(CheckPointRow(
                item_id(r.get(cid), f"{at}, column {cid}"),
                _num(r.get(cx), f"{at}, column {cx}"),
                _num(r.get(cy), f"{at}, column {cy}"),
                _num(r.get(cz), f"{at}, column {cz}", True) if cz else None,
                *_sigmas(dict(r), cols, at),
                _description(r.get(cd), f"{at}, column {cd}") if cd else ""))
            _count(rows)
    except csv.Error as exc:
        limit = csv.field_size_limit()
        what = f"a field is longer than {limit} characters" if "field limit" in str(exc) \
            else f"not readable as CSV ({exc})"
        raise InputError(what, field=f"line {reader.line_num + 1}") from None
    return rows


def _feature_id(props: JSONObject, fallback: JSON, field: str) -> str:
    for key in ID_COLUMNS:
        for k, v in props.items():
            if k.lower() == key and v is not None:
                return item_id(v, f"{field}.properties.{k}")
    if fallback is not None:
        return item_id(fallback, f"{field}.id")
    raise InputError("no point id (properties point_id, id or name)", field=field)


def _read_geojson(data: bytes) -> list[CheckPointRow]:
    try:
        # orjson: bounded nesting, numbers as int64/uint64 or double (no inf, no NaN)
        doc = orjson.loads(data.removeprefix(b"\xef\xbb\xbf"))
    except orjson.JSONDecodeError as exc:
        raise InputError(f"not valid JSON: {exc}") from None
    if isinstance(doc, dict) and doc.get("type") == "Feature":
        doc = {"type": "FeatureCollection", "features": [doc]}
    if not isinstance(doc, dict) or not isinstance(doc.get("features"), list):
        raise InputError("expected a GeoJSON FeatureCollection")
    if len(doc["features"]) > MAX_CHECK_POINTS:
        raise InputError(f"more than {MAX_CHECK_POINTS} check points")
    rows = []
    for i, f in enumerate(doc["features"]):
        at = f"features[{i}]"
        if not isinstance(f, dict):
            raise InputError("expected a Feature object", field=at)
        geom = f.get("geometry")
        if not isinstance(geom, dict) or geom.get("type") != "Point":
            raise InputError("expected a Point", field=f"{at}.geometry")
        c = geom.get("coordinates")
        if not isinstance(c, list) or len(c) not in (2, 3):
            raise InputError("expected 2 or 3 numbers", field=f"{at}.geometry.coordinates")
        props = f.get("properties") or {}
        if not isinstance(props, dict):
            raise InputError("expected an object", field=f"{at}.properties")
        rows.append(CheckPointRow(
            _feature_id(props, f.get("id"), at),
            _num(c[0], f"{at}.geometry.coordinates[0]"),
            _num(c[1], f"{at}.geometry.coordinates[1]"),
            _num(c[2], f"{at}.geometry.coordinates[2]", True) if len(c) == 3 else None,
            *_sigmas(props, list(props), f"{at}.properties"),
            _description(props.get(dk), f"{at}.properties.{dk}")
            if (dk := _pick(list(props), DESCRIPTION_COLUMNS)) else ""))
    return rows


def _read_gpkg(data: bytes) -> tuple[list[CheckPointRow], str | None]:
    import pyogrio
    import shapely
    from pyogrio import raw

    from gsgeo.crs.resolve import network_off, parse_crs
    from gsgeo.errors import CRSError

    network_off()  # GDAL's PROJ reads the file's CRS: no grid downloads

    # GDAL would open any format it knows (a VRT, say, that reads files of the server)
    if not data.startswith(SQLITE_MAGIC):
        raise InputError("not a GeoPackage (not an SQLite file)")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            layers = pyogrio.list_layers(io.BytesIO(data))
            point_layers = [name for name, gt in layers if gt and "point" in str(gt).lower()]
            if not point_layers:
                raise InputError("the GeoPackage has no point layer")
            layer = point_layers[0]
            meta, _, wkb, columns = raw.read(io.BytesIO(data), layer=layer,
                                             max_features=MAX_CHECK_POINTS + 1)
            names = [str(c) for c in meta["fields"]]
            cid = _pick(names, ID_COLUMNS)
            if cid is None:
                raise InputError(f"layer '{layer}' has no point_id, id or name column")
            geoms = shapely.from_wkb(wkb)
    except InputError:
        raise
    except Exception as exc:  # GDAL and GEOS raise their own error types for unreadable files
        raise InputError(f"cannot be read as a GeoPackage: {exc}") from None
    ids = columns[names.index(cid)]
    sig_cols = [c for c in (_pick(names, SIGMA_H_COLUMNS), _pick(names, SIGMA_V_COLUMNS)) if c]
    sig = {c: columns[names.index(c)] for c in sig_cols}
    cd = _pick(names, DESCRIPTION_COLUMNS)
    descs = columns[names.index(cd)] if cd else None
    rows: list[CheckPointRow] = []
    for i, (pid, geom) in enumerate(zip(ids, geoms, strict=True)):
        at = f"layer {layer} feature {i}"
        if geom is None or geom.geom_type != "Point" or geom.is_empty:
            raise InputError("expected a Point geometry", field=at)
        z = geom.z if geom.has_z else None
        pid = pid.item() if hasattr(pid, "item") else pid  # numpy scalar -> int, float, str
        rows.append(CheckPointRow(item_id(pid, f"{at}, column {cid}"),
                                  _num(float(geom.x), f"{at} x"),
                                  _num(float(geom.y), f"{at} y"),
                                  _num(None if z is None else float(z), f"{at} z", True),
                                  *_sigmas({c: _plain(v[i]) for c, v in sig.items()}, sig_cols,
                                           at),
                                  _description(_plain(descs[i]), f"{at}, column {cd}")
                                  if descs is not None else ""))
        _count(rows)
    crs = None
    if meta.get("crs"):
        try:
            file_crs = parse_crs(meta["crs"])
            epsg = file_crs.to_epsg()
            crs = f"EPSG:{epsg}" if epsg else file_crs.to_wkt()
        except CRSError as exc:
            raise InputError(f"the layer's CRS cannot be read: {exc}") from None
    return rows, crs


def _plain(value: object) -> JSON:
    """A GeoPackage field value (numpy scalar) as a plain JSON number or text."""
    v = value.item() if hasattr(value, "item") else value
    return v if isinstance(v, (int, float, str)) or v is None else str(v)


def _rows(data: bytes, fmt: str) -> tuple[list[CheckPointRow], str | None]:
    if fmt == "csv":
        rows, crs = _read_csv(data), None
    elif fmt == "geojson":
        rows, crs = _read_geojson(data), None
    else:
        rows, crs = _read_gpkg(data)
    if not rows:
        raise InputError("contains no check points")
    _count(rows)
    seen: set[str] = set()
    for r in rows:
        if r.id in seen:
            raise InputError(f"duplicate point id {r.id!r}")
        seen.add(r.id)
    return rows, crs


def read_check_points(data: bytes, fmt: str,
                      name: str | None = None) -> tuple[list[CheckPointRow], str | None]:
    """Rows of a check-point file and the CRS the file itself declares (GeoPackage only).

    A file that cannot be read raises InputError about the field ``file`` whose problem names
    the file, the place in it and what is wrong: ``file: 'NAME': line 3, column x: missing``."""
    if fmt not in FORMATS:
        raise InputError(f"must be one of {', '.join(FORMATS)}, got {fmt!r}", field="format")
    try:
        return _rows(data, fmt)
    except InputError as exc:
        label = repr(name[:100]) if name else f"the {fmt} file"
        raise exc.part_of("file", label) from None
