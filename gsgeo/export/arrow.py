"""Export tables as Arrow C streams (nanoarrow), for pyogrio's Arrow write path.

GDAL writes a whole Arrow batch per layer (OGR_L_WriteArrowBatch), several times cheaper than
pyogrio's feature-by-feature `write`. The columns are built from numpy buffers without
copying values one by one: floats with a validity bitmap where NaN (NaN = null, as
``nan_as_null`` did), int32, bit-packed booleans, UTF-8 text with int64 offsets, and the
geometry as a large-binary column of WKB (gsgeo.export.wkb).
"""

from __future__ import annotations

from typing import Any

import nanoarrow as na
import numpy as np

from gsgeo.errors import InputError
from gsgeo.export.tables import Table

#: Name of the geometry column in the Arrow stream (and in the GeoPackage).
GEOMETRY = "geom"


def _bits(mask: np.ndarray) -> np.ndarray:
    return np.packbits(mask, bitorder="little")


def _offsets(lengths: np.ndarray) -> np.ndarray:
    out = np.zeros(lengths.shape[0] + 1, dtype=np.int64)
    np.cumsum(lengths, out=out[1:])
    return out


def _text(name: str, col: Any) -> Any:
    """UTF-8 large_string array of an object column of str / None."""
    vals = np.asarray(col, dtype=object)
    n = vals.shape[0]
    null = np.equal(vals, np.array(None, dtype=object))
    if null.any():
        vals = vals.copy()
        vals[null] = ""
    try:
        items = vals.tolist()
        text = "".join(items)
    except TypeError:  # a non-str value: write its str(), as the row writers do
        items = [str(v) for v in vals.tolist()]
        text = "".join(items)
    try:
        data = text.encode("utf-8")
        if len(data) == len(text):  # ASCII: one byte per character
            lengths = np.fromiter(map(len, items), dtype=np.int64, count=n)
        else:
            lengths = np.fromiter((len(s.encode("utf-8")) for s in items), dtype=np.int64, count=n)
    except UnicodeEncodeError:
        raise InputError(f"column {name}: text that is not valid Unicode") from None
    validity = _bits(~null) if null.any() else None
    return na.c_array_from_buffers(na.large_string(), n, [validity, _offsets(lengths), data])


def column(name: str, col: Any, kind: str) -> Any:
    """An Arrow array of one table column; kind 'str', 'float', 'int' or 'bool'."""
    if kind == "str":
        return _text(name, col)
    if kind == "int":
        a = np.ascontiguousarray(col, dtype=np.int32)
        return na.c_array_from_buffers(na.int32(), a.shape[0], [None, a])
    if kind == "bool":
        a = np.asarray(col, dtype=bool)
        return na.c_array_from_buffers(na.bool_(), a.shape[0], [None, _bits(a)])
    a = np.ascontiguousarray(col, dtype=np.float64)
    nan = np.isnan(a)
    validity = _bits(~nan) if nan.any() else None
    return na.c_array_from_buffers(na.float64(), a.shape[0], [validity, a])


def table_stream(geometry: tuple[np.ndarray, np.ndarray], table: Table) -> Any:
    """An Arrow C stream (one batch): the WKB geometry column, then the table's columns in order.

    geometry : (offsets int64 (M + 1,), data uint8) as from gsgeo.export.wkb.
    """
    offsets, data = geometry
    n = offsets.shape[0] - 1
    if len(table) != n:
        raise ValueError(f"{n} geometries for {len(table)} rows")
    names = [GEOMETRY, *table.columns]
    arrays = [na.c_array_from_buffers(na.large_binary(), n, [None, offsets, data])]
    arrays += [column(k, v, table.types[k]) for k, v in table.columns.items()]
    schema = na.struct({k: a.schema for k, a in zip(names, arrays, strict=True)})
    batch = na.c_array_from_buffers(schema, n, [None], children=arrays)
    return na.c_array_stream(batch)
