"""CSV writer: one row per measured point, a header row, the point schema in a fixed order.

Column order (CSV_COLUMNS): point_id, easting, northing, height, code, then the rest of the
point schema in DESIGN.md order (description, height_type, vertical_datum, crs, sigma_e, ...,
measured_at). Every row states its CRS, height type and vertical datum, so the file stands
alone. UTF-8 without BOM, comma separated, "\\n" line ends, empty field = unknown (null).

Numbers: easting, northing, height and h_wgs84 with 4 decimals (0.1 mm, in the CRS's units);
lon, lat with 10 decimals; every other number (sigmas, covariances, ellipses, ...) in full
precision (Python's shortest round-trip form). Lines, polygons and check points are not part
of the CSV (use GeoPackage or GeoJSON for them).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from gsgeo.crs.pipeline import RECORD_KEYS
from gsgeo.export.tables import ExportData

FIRST = ("point_id", "easting", "northing", "height", "code")
#: The CSV's columns, in order.
CSV_COLUMNS = FIRST + tuple(k for k in RECORD_KEYS if k not in FIRST)
FIXED_DECIMALS = {"easting": 4, "northing": 4, "height": 4, "h_wgs84": 4, "lon": 10, "lat": 10}


def _texts(col: np.ndarray, kind: str, name: str) -> list[str]:
    if kind == "str":
        return ["" if v is None else v for v in col]
    if kind == "int":
        return [str(v) for v in np.asarray(col).tolist()]
    arr = np.asarray(col, dtype=np.float64)
    if name in FIXED_DECIMALS:
        fmt = f"%.{FIXED_DECIMALS[name]}f"
        out = np.char.mod(fmt, arr).tolist()
    else:
        out = [repr(v) for v in arr.tolist()]
    if not np.all(np.isfinite(arr)):
        bad = ~np.isfinite(arr)
        out = ["" if b else s for s, b in zip(out, bad.tolist(), strict=True)]
    return out


def write_csv(path: Path, data: ExportData) -> None:
    """Write the points of `data` as CSV to a new file at `path`."""
    t = data.points
    cols = [_texts(t.columns[k], t.types[k], k) for k in CSV_COLUMNS]
    with open(path, "x", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(CSV_COLUMNS)
        w.writerows(zip(*cols, strict=True))
