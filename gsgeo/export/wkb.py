"""ISO WKB for many geometries of one shape, assembled with numpy (no per-feature Python).

Each function returns ``(offsets, data)``: ``data`` (uint8) holds the WKB of all geometries
one after another, geometry k is ``data[offsets[k]:offsets[k + 1]]`` (offsets int64, length
M + 1): the layout of an Arrow (large) binary column. Little-endian, ISO type codes (Z types
1001, 1002, 1003), the same bytes as ``shapely.to_wkb(..., flavor="iso", byte_order=1)``.
Coordinates are written as given (E, N[, H] in the CRS's units); nothing is checked here.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

POINT, LINESTRING, POLYGON = 1, 2, 3


def _pack(fields: list[tuple[str, str, tuple[int, ...]]], m: int) -> np.ndarray:
    return np.empty(m, dtype=np.dtype([(n, t, s) for n, t, s in fields]))  # packed, no padding


def _result(rec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    size = rec.dtype.itemsize
    return np.arange(rec.shape[0] + 1, dtype=np.int64) * size, rec.view(np.uint8).reshape(-1)


def _type_code(kind: int, dims: int) -> int:
    if dims not in (2, 3):
        raise ValueError(f"coordinates must have 2 or 3 dimensions, got {dims}")
    return kind + (1000 if dims == 3 else 0)


def points(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """WKB Points of (M, D) coordinates, D = 2 or 3."""
    c = np.asarray(xyz, dtype="<f8")
    m, dims = c.shape
    rec = _pack([("order", "u1", ()), ("type", "<u4", ()), ("xyz", "<f8", (dims,))], m)
    rec["order"] = 1
    rec["type"] = _type_code(POINT, dims)
    rec["xyz"] = c
    return _result(rec)


def linestrings(coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """WKB LineStrings of (M, N, D) coordinates: M lines of N >= 2 vertices each."""
    c = np.asarray(coords, dtype="<f8")
    m, n, dims = c.shape
    rec = _pack([("order", "u1", ()), ("type", "<u4", ()), ("n", "<u4", ()),
                 ("xyz", "<f8", (n, dims))], m)
    rec["order"] = 1
    rec["type"] = _type_code(LINESTRING, dims)
    rec["n"] = n
    rec["xyz"] = c
    return _result(rec)


def polygons(rings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """WKB Polygons of one exterior ring each, (M, N, D) coordinates of closed rings."""
    c = np.asarray(rings, dtype="<f8")
    m, n, dims = c.shape
    rec = _pack([("order", "u1", ()), ("type", "<u4", ()), ("rings", "<u4", ()), ("n", "<u4", ()),
                 ("xyz", "<f8", (n, dims))], m)
    rec["order"] = 1
    rec["type"] = _type_code(POLYGON, dims)
    rec["rings"] = 1
    rec["n"] = n
    rec["xyz"] = c
    return _result(rec)


def from_bytes(items: Iterable[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """(offsets, data) of a sequence of WKB byte strings (e.g. from shapely.to_wkb)."""
    items = list(items)
    offsets = np.zeros(len(items) + 1, dtype=np.int64)
    np.cumsum(np.fromiter(map(len, items), dtype=np.int64, count=len(items)), out=offsets[1:])
    return offsets, np.frombuffer(b"".join(items), dtype=np.uint8)
