"""The one factory of PROJ transformers (cached) and the choice of operation.

Every pyproj Transformer, TransformerGroup and Proj of gsgeo is built here. A Transformer is
built once per (source, target, PROJ data directory) and reused for every point
(``functools.lru_cache``); gsgeo never builds one per point. Each factory turns PROJ's network
off before building (:func:`gsgeo.crs.resolve.network_off`). Operations are chosen
explicitly from PROJ's ranked candidates (`TransformerGroup`) so that the operation used is
known before transforming and recorded with each result.

Threads: a plain pyproj Transformer is thread-safe (one PROJ object per thread), but the
transformers of a TransformerGroup are not, so candidate groups are cached per thread.
"""

from __future__ import annotations

import functools
import threading
import warnings
from collections import Counter
from dataclasses import dataclass

import numpy as np
import pyproj
from pyproj import Transformer
from pyproj.transformer import TransformerGroup

from gsgeo.crs.resolve import network_off, parse_crs


def _datadir() -> str:
    # Part of every cache key: a grid added to the PROJ data path changes the operations.
    return pyproj.datadir.get_data_dir()


def crs_key(crs: object) -> str:
    """The text a CRS is cached under: text as given, "EPSG:n" for an int, else its WKT."""
    if isinstance(crs, str):
        return crs
    if isinstance(crs, int) and not isinstance(crs, bool):
        return f"EPSG:{crs}"
    return parse_crs(crs).to_wkt()


@functools.lru_cache(maxsize=128)
def _transformer(src: str, dst: str, allow_ballpark: bool, datadir: str) -> Transformer:
    network_off()
    BUILDS["transformers"] += 1
    return Transformer.from_crs(parse_crs(src), parse_crs(dst), always_xy=True,
                                allow_ballpark=allow_ballpark)


def transformer(src: object, dst: object, *, allow_ballpark: bool = True) -> Transformer:
    """A cached, always_xy Transformer between two CRSs (anything :func:`parse_crs` takes),
    PROJ's own choice of operation. With ``allow_ballpark=False`` PROJ raises ProjError
    rather than fall back to a ballpark operation (e.g. a missing geoid grid)."""
    return _transformer(crs_key(src), crs_key(dst), allow_ballpark, _datadir())


@functools.lru_cache(maxsize=128)
def _pipeline(definition: str, datadir: str) -> Transformer:
    network_off()
    return Transformer.from_pipeline(definition)


def pipeline(definition: str) -> Transformer:
    """A cached Transformer from a PROJ pipeline string."""
    return _pipeline(definition, _datadir())


@functools.lru_cache(maxsize=32)
def _projection(crs: str, datadir: str) -> pyproj.Proj:
    network_off()
    return pyproj.Proj(parse_crs(crs))


def projection(crs: object) -> pyproj.Proj:
    """A cached pyproj Proj of a projected CRS (for ``get_factors``: convergence, scale)."""
    return _projection(crs_key(crs), _datadir())


@dataclass(frozen=True)
class Candidates:
    """PROJ's ranked operations between two CRSs, split by availability."""

    available: tuple[Transformer, ...]
    unavailable: tuple  # pyproj Operation objects (their grids are missing)


# pyproj warns "Best transformation is not available due to missing Grid(...)" when it
# builds a group; gsgeo reports missing grids itself, by name, where they matter. A filter
# for exactly that message (catch_warnings would not be thread-safe).
warnings.filterwarnings("ignore", message="Best transformation is not available",
                        category=UserWarning)

_local = threading.local()
#: How many Transformers ("transformers") and TransformerGroups ("groups") were built (tests
#: check that points reuse them).
BUILDS: Counter = Counter()


def candidates(src: object, dst: object) -> Candidates:
    """Cached TransformerGroup candidates (best first) between two CRSs (anything
    :func:`parse_crs` takes)."""
    cache = getattr(_local, "groups", None)
    if cache is None:
        cache = _local.groups = {}
    src, dst = crs_key(src), crs_key(dst)
    key = (src, dst, _datadir())
    found = cache.get(key)
    if found is None:
        network_off()
        tg = TransformerGroup(parse_crs(src), parse_crs(dst), always_xy=True)
        found = Candidates(tuple(tg.transformers), tuple(tg.unavailable_operations))
        BUILDS["groups"] += 1
        if len(cache) >= 128:
            cache.clear()
        cache[key] = found
    return found


def in_area(t: Transformer, lon: float, lat: float) -> bool:
    """Whether (lon, lat) in degrees lies in the operation's area of use (True if none)."""
    a = t.area_of_use
    if a is None:
        return True
    w, s, e, n = a.west, a.south, a.east, a.north
    if not (s <= lat <= n):
        return False
    if w <= e:
        return w <= lon <= e
    return lon >= w or lon <= e  # crosses the antimeridian


def is_ballpark(description: str) -> bool:
    return "ballpark" in description.lower()


def accuracy_m(t: Transformer) -> float | None:
    """Accuracy of an operation in metres: 0 for a pure conversion, None when unknown."""
    acc = t.accuracy
    if acc is None or acc < 0:
        # PROJ reports -1 both for "unknown" and for conversions; a conversion has no
        # datum change at all.
        return 0.0 if _is_conversion(t) else None
    return float(acc)


def _is_conversion(t: Transformer) -> bool:
    desc = t.description.lower()
    if is_ballpark(desc):
        return False
    try:
        ops = t.operations or ()
    except Exception:  # noqa: BLE001 - pyproj raises different types across versions
        ops = ()
    if ops:
        return all(getattr(o, "type_name", "") == "Conversion" for o in ops)
    return "inverse of" not in desc and " to " not in desc


def choose(src: object, dst: object, lon: float, lat: float) -> tuple[Transformer, bool]:
    """The best available operation whose area of use contains (lon, lat).

    Returns (transformer, inside_area). When no candidate covers the point, the best overall
    is returned with inside_area False (the caller warns).
    """
    c = candidates(src, dst)
    if not c.available:
        return transformer(src, dst), False
    for t in c.available:
        if in_area(t, lon, lat):
            return t, True
    return c.available[0], False


def transform_xy(t: Transformer, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    xx, yy = t.transform(x, y, errcheck=False)
    return np.asarray(xx, dtype=np.float64), np.asarray(yy, dtype=np.float64)
