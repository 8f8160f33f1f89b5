"""Measuring a project's point: its typed rays (gsgeo.measure.Rays) with the project's
settings (crs, vertical or geoid, source_crs, sigma_px) through gsgeo.measure.point.

Words: *solve* is the least-squares maths (gsgeo.solve); *measure* is that plus the CRS path
(rays to grid coordinates), as done here; *re-measure* is measuring stored points again, e.g.
after a settings change; *resolve* is left to gsgeo.crs (parsing a CRS text).
"""

from __future__ import annotations

import gc
import math
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import orjson

from gsgeo.crs.frames import ecef_to_geodetic
from gsgeo.crs.grid import to_grid_many
from gsgeo.crs.modelmatrix import (
    IDENTITY,
    apply_directions,
    apply_points,
    invert_affine,
    is_similarity,
    matrix4,
)
from gsgeo.errors import CRSError, GsgeoError, InputError
from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.measure import Measurement, Rays, SolveSettings, measure_point
from gsgeo.measure.framecov import FrameCovariance
from gsgeo.measure.rays import RAY_KEYS, RAY_PROVENANCE_KEYS
from gsgeo.measure.schema import record_of
from gsgeo.session import parse_rays
from gsgeo.solve.linalg import FloatArray


def json_ready(value: Any) -> JSON:
    """``value`` with every non-finite float replaced by None (JSON has no NaN) and numpy
    values as plain numbers and lists. One orjson round trip (fast: a point's result holds
    hundreds of numbers); values orjson cannot take go through :func:`plain_json`."""
    try:
        return orjson.loads(orjson.dumps(value, option=orjson.OPT_SERIALIZE_NUMPY
                                         | orjson.OPT_NON_STR_KEYS))
    except (orjson.JSONEncodeError, TypeError):
        return plain_json(value)


def plain_json(value: Any) -> JSON:
    """The slow, general :func:`json_ready`: recursion over dicts, lists and ``tolist()``."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: plain_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_json(v) for v in value]
    if hasattr(value, "tolist"):  # numpy scalars and arrays
        return plain_json(value.tolist())
    return value


def stored_rays(rays: list[JSONObject]) -> Rays:
    """The typed rays of a point's session-JSON rays as stored (or given); errors name
    ``rays[i].<member>``.

    Plain ray objects (numbers where numbers belong) go straight into arrays, checked once by
    Rays; anything else takes the session reader, whose messages name the JSON problem.
    """
    try:
        if all(isinstance(r, dict) and r.keys() <= _RAY_KEYS for r in rays):
            return Rays.from_columns(
                [_numbers(r["origin"], 3) for r in rays],
                [_numbers(r["direction"], 3) for r in rays],
                [_number(r.get("ifov")) for r in rays],
                [_maybe_numbers(r.get("pixel"), 2) for r in rays],
                [_maybe_numbers(r.get("viewport"), 2) for r in rays],
                [_maybe_numbers(r.get("model_matrix"), 16) for r in rays],
                [r.get("auto") is True for r in rays])
    except (KeyError, TypeError, ValueError, OverflowError):
        pass
    return parse_rays(rays)[1]


@contextmanager
def without_cyclic_gc() -> Iterator[None]:
    """Hold Python's cyclic garbage collector while re-measuring many points at once.

    A re-measure allocates some 50 dicts and lists per point, all acyclic (freed by reference
    counting); the collector's full passes over every live object, triggered by those
    allocations, took a third of re-measuring 10 000 points. It is process-wide, so it is
    switched on again at once afterwards (if it was on)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def stored_rays_many(stored: Sequence[list[JSONObject]],
                     carries: Sequence[FloatArray | None]) -> list[Rays | GsgeoError]:
    """The typed rays of many stored points, each carried by its similarity (4, 4; None: not
    carried), as ``stored_rays(rays).mapped(carry)`` gives them, on stacked arrays: one pass
    over the JSON, one check of the stack (gsgeo.measure.Rays.split). Rays under a viewer
    modelMatrix that is a similarity are taken to georeferenced ECEF first (so they carry no
    matrix); anything unusual (a distorting matrix, a malformed or out-of-range ray) takes the
    per-point path, whose messages name the problem."""
    n = len(stored)
    try:
        flat = [r for rays in stored for r in rays]
        if not all(isinstance(r, dict) and r.keys() <= _RAY_KEYS for r in flat):
            raise TypeError("not plain ray objects")
        counts = [len(rays) for rays in stored]
        o = np.array([r["origin"] for r in flat], dtype=np.float64).reshape(-1, 3)
        d = np.array([r["direction"] for r in flat], dtype=np.float64).reshape(-1, 3)
        nan2 = [math.nan, math.nan]
        f = np.array([r.get("ifov", math.nan) for r in flat], dtype=np.float64)
        px = np.array([r.get("pixel") or nan2 for r in flat], dtype=np.float64).reshape(-1, 2)
        vp = np.array([r.get("viewport") or nan2 for r in flat], dtype=np.float64).reshape(-1, 2)
        point_of = np.repeat(np.arange(n), counts)
        mats: dict[tuple[float, ...], list[int]] = {}
        for i, r in enumerate(flat):
            given = r.get("model_matrix")
            if given is not None:
                if not isinstance(given, list):
                    raise TypeError("not a matrix")
                # grouped as given (1 and 1.0 hash alike); matrix4 checks the numbers
                mats.setdefault(tuple(given), []).append(i)
        for key, rows in mats.items():
            m = matrix4(key)
            if not is_similarity(m):
                raise TypeError("a distorting model matrix: measured point by point")
            sel = np.asarray(rows)
            if np.array_equal(m, IDENTITY):  # a georeferenced scene: rendered = georeferenced
                d[sel] /= np.linalg.norm(d[sel], axis=1, keepdims=True)
                continue
            inv = invert_affine(m)
            o[sel] = apply_points(inv, o[sel])
            d[sel] = apply_directions(inv, d[sel])
        groups: dict[int, list[int]] = {}
        for k, c in enumerate(carries):
            if c is not None:
                groups.setdefault(id(c), []).append(k)
        for ks in groups.values():
            c = carries[ks[0]]
            assert c is not None  # grouped only when given
            sel = np.flatnonzero(np.isin(point_of, ks))
            d2 = d[sel] @ c[:3, :3].T
            o[sel] = o[sel] @ c[:3, :3].T + c[:3, 3]
            d[sel] = d2 / np.linalg.norm(d2, axis=1, keepdims=True)
        if not np.all(np.isfinite(d)):
            raise ValueError("a direction cannot be carried")
        auto = np.array([r.get("auto") is True for r in flat], dtype=bool)
        split = Rays.split(o, d, counts, f, px, vp, auto)
        if split is None:
            raise ValueError("a ray out of range: measured point by point")
        return list(split)
    except (KeyError, TypeError, ValueError, OverflowError):
        out: list[Rays | GsgeoError] = []
        for rays, c in zip(stored, carries, strict=True):
            try:
                typed = stored_rays(rays)
                out.append(typed if c is None else typed.mapped(c))
            except GsgeoError as exc:
                out.append(exc)
        return out


_RAY_KEYS = frozenset(RAY_KEYS + RAY_PROVENANCE_KEYS)


def _number(v: JSON) -> float | None:
    if v is None:
        return None
    if type(v) is not float and type(v) is not int:
        raise TypeError("not a number")
    return v


def _numbers(v: JSON, n: int) -> list[float]:
    if not isinstance(v, list) or len(v) != n or not all(
            type(x) is float or type(x) is int for x in v):
        raise TypeError("not a vector")
    return [float(x) for x in v if type(x) is float or type(x) is int]


def _maybe_numbers(v: JSON, n: int) -> list[float] | None:
    return None if v is None else _numbers(v, n)


def check_excluded(excluded: list[int], n_rays: int, field: str = "excluded") -> list[int]:
    """Sorted distinct 0-based indices of excluded rays; InputError (about ``field``) for an
    index out of range or fewer than two rays left."""
    out = sorted({int(i) for i in excluded})
    for i in out:
        if not 0 <= i < n_rays:
            raise InputError(f"ray index {i} is out of range (the point has {n_rays} rays, "
                             f"indices 0 to {n_rays - 1})", field=field)
    if n_rays - len(out) < 2:
        raise InputError(f"at least two rays must remain in the solution ({n_rays} rays, "
                         f"{len(out)} excluded)", field=field)
    return out


def find_geoid(geoid: str | None, data_dir: Path | None) -> Path | None:
    """A geoid named in a project is a file in DATA/geoids/ (never an arbitrary path)."""
    if not geoid:
        return None
    if data_dir is None:
        raise CRSError("no data directory to look up geoid grids in", field="geoid")
    gdir = (Path(data_dir) / "geoids").resolve()
    path = (gdir / geoid).resolve()
    if path.parent != gdir or not path.is_file():
        raise CRSError(f"no geoid grid '{geoid}' in {gdir} (put the GeoTIFF there)",
                       field="geoid")
    return path


def solve_settings(settings: JSONObject, data_dir: Path | None,
                   frame: FrameCovariance | None = None) -> SolveSettings:
    """A project's settings (checked by gsgeo.service.projects.validate_settings) as the typed
    core's, the geoid looked up in DATA/geoids/, ``frame`` the scene georeference's
    uncertainty."""
    return SolveSettings(crs=settings.get("crs"), vertical=settings.get("vertical"),
                         geoid=find_geoid(settings.get("geoid"), data_dir),
                         source_crs=settings.get("source_crs") or "EPSG:4978",
                         sigma_px=float(settings.get("sigma_px") or 1.0), frame=frame)


def locate_points(points: Sequence[Sequence[float]], settings: JSONObject,
                  data_dir: Path | None, model_matrix: Sequence[float] | None = None
                  ) -> list[JSONObject]:
    """Points the viewer shows (rendered ECEF, metres; ``model_matrix`` the tileset's, 16
    numbers column-major, None: identity) in a project's grid: easting, northing, height (the
    grid's units, its vertical datum) and WGS 84 lon, lat (degrees), h_wgs84 (m); without a
    grid CRS only the WGS 84 members. E.g. the splat under the viewer's cursor."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if model_matrix is not None:
        m = matrix4(model_matrix)
        if not np.array_equal(m, IDENTITY):
            pts = apply_points(invert_affine(m), pts)
    s = solve_settings(settings, data_dir)
    if s.crs:
        g = to_grid_many(pts, None, s.crs, vertical=s.vertical, geoid=s.geoid,
                         source_crs=s.source_crs)
        cols = {"easting": g.easting, "northing": g.northing, "height": g.height,
                "lon": g.lon, "lat": g.lat, "h_wgs84": g.h_wgs84}
    else:
        lon, lat, h = ecef_to_geodetic(pts, s.source_crs)
        cols = {"lon": np.asarray(lon), "lat": np.asarray(lat), "h_wgs84": np.asarray(h)}
    lists = {k: np.asarray(v, dtype=np.float64).tolist() for k, v in cols.items()}
    return [{k: v[i] for k, v in lists.items()} for i in range(pts.shape[0])]


def measure(rays: Rays, settings: JSONObject, excluded: list[int],
            data_dir: Path | None = None, *, point_id: str = "P", code: str = "",
            description: str = "", frame: FrameCovariance | None = None) -> Measurement:
    """The gsgeo.measure.point Measurement of ``rays`` with a project's ``settings``."""
    return measure_point(rays, solve_settings(settings, data_dir, frame), point_id=point_id,
                         code=code, description=description, exclude=excluded)


def measured_result(m: Measurement) -> JSONObject:
    """The stored result of a Measurement (to_dict, JSON-ready); its point-schema record is
    derived from it (gsgeo.measure.schema.record_of), never stored beside it."""
    return json_ready(m.to_dict())


def with_record(result: JSONObject | None) -> JSONObject | None:
    """The point-schema record of a stored result, or None."""
    return None if result is None else record_of(result)
