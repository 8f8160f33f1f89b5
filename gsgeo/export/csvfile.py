"""CSV writer: one row per measured point, a header row, the point schema in a fixed order.

Column order (CSV_COLUMNS): point_id, easting, northing, height, code, then the rest of the
point schema in its documented order (description, height_type, vertical_datum, crs, sigma_e, ...,
measured_at), then who measured the point and how its rays were aimed (measured_by,
n_rays_clicked, n_rays_auto). Every row states its CRS, height type and vertical datum, so the file stands
alone. UTF-8 without BOM, comma separated, "\\n" line ends, empty field = unknown (null).

Numbers: easting, northing, height and h_wgs84 with 4 decimals (0.1 mm, in the CRS's units);
lon, lat with 10 decimals; every other number (sigmas, covariances, ellipses, ...) in full
precision (the shortest text that reads back to the same double, e.g. 1.5e-7). Text is quoted
as Python's csv module does by default (only where it holds a comma, quote or line break).
Lines, polygons and check points are not part of the CSV (use GeoPackage or GeoJSON for them).

Written column by column: each column's values become text at once (orjson for full-precision
floats, one %-format for fixed decimals), then rows are joined, CHUNK rows at a time.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import orjson

from gsgeo.export.tables import ExportData
from gsgeo.pointschema import EXPORT_KEYS

FIRST = ("point_id", "easting", "northing", "height", "code")
#: The CSV's columns, in order.
CSV_COLUMNS = FIRST + tuple(k for k in EXPORT_KEYS if k not in FIRST)
FIXED_DECIMALS = {"easting": 4, "northing": 4, "height": 4, "h_wgs84": 4, "lon": 10, "lat": 10}
CHUNK = 10000
_SPECIAL = (",", '"', "\r", "\n")


def _quote(v: object) -> str:
    """A text field as csv.writer (QUOTE_MINIMAL) writes it; None -> empty."""
    if v is None:
        return ""
    s = v if isinstance(v, str) else str(v)
    if any(c in s for c in _SPECIAL):
        return '"' + s.replace('"', '""') + '"'
    return s


def _texts(col: np.ndarray, kind: str, name: str) -> list[str]:
    """The CSV text of each value of a column; empty where unknown (None, NaN, infinite)."""
    n = len(col)
    if kind == "str":
        vals = list(col)
        texts = {v: _quote(v) for v in set(vals)}  # few distinct values in most columns
        return list(map(texts.__getitem__, vals))
    if kind == "int":
        return [str(v) for v in np.asarray(col).tolist()]
    arr = np.asarray(col, dtype=np.float64)
    if name in FIXED_DECIMALS:
        fmt = f"%.{FIXED_DECIMALS[name]}f"
        out = (",".join([fmt] * n) % tuple(arr.tolist())).split(",") if n else []
    else:
        text = orjson.dumps(np.ascontiguousarray(arr), option=orjson.OPT_SERIALIZE_NUMPY)
        out = text.decode()[1:-1].split(",") if n else []
    if not np.all(np.isfinite(arr)):
        for i in np.flatnonzero(~np.isfinite(arr)).tolist():
            out[i] = ""
    return out


def write_csv(path: Path, data: ExportData) -> None:
    """Write the points of `data` as CSV to a new file at `path`."""
    t = data.points
    with open(path, "x", encoding="utf-8", newline="") as fh:
        fh.write(",".join(CSV_COLUMNS) + "\n")
        for k in range(0, len(t), CHUNK):
            cols = [_texts(t.columns[c][k:k + CHUNK], t.types[c], c) for c in CSV_COLUMNS]
            fh.write("\n".join(map(",".join, zip(*cols, strict=True))) + "\n")
