"""What an export holds, as column arrays: points, rays, lines, polygons, error ellipses, check
points and the surfaces of LoD2 buildings.

`collect` turns measurements (gsgeo.measure.point.Measurement objects, or their ``to_dict()``
JSON as the project store keeps it) plus lines and polygons given by point ids into an
`ExportData` that the GeoPackage, GeoJSON and CSV writers share, so every format carries the
same numbers. Everything is validated here, before a file is touched.

Coordinates are in the grid CRS of the measurements (E, N, H in the CRS's units); sigmas and
covariances in metres and m²; lengths and areas in metres and m² (gsgeo.measure.features).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from itertools import chain
from operator import attrgetter
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.crs.resolve import GridCRS, grid_crs, parse_crs
from gsgeo.errors import CRSError, GeometryError, GsgeoError, InputError
from gsgeo.measure.features import (
    LineArrays,
    PolygonArrays,
    line_measures,
    line_measures_many,
    polygon_measures,
    polygon_measures_many,
)
from gsgeo.measure.schema import RECORD_KEYS
from gsgeo.pointschema import BUILDING_MEASURES, BUILDING_TYPES, EXPORT_KEYS, PROVENANCE_KEYS

#: Column types of a point in an export (the README's "Point schema" and the provenance
#: columns after it, gsgeo.pointschema.EXPORT_KEYS): 'str', 'float' or 'int'.
POINT_TYPES: dict[str, str] = {k: "float" for k in EXPORT_KEYS}
POINT_TYPES.update(dict.fromkeys(
    ("point_id", "code", "description", "height_type", "vertical_datum", "crs", "operation",
     "measured_at", "measured_by"), "str"))
POINT_TYPES.update(dict.fromkeys(("n_rays", "n_rays_clicked", "n_rays_auto"), "int"))

#: Column types of the other layers (GeoPackage rays, lines, polygons, error_ellipses,
#: check_points), in column order; the OGC API's collections announce the same.
RAY_TYPES: dict[str, str] = {"point_id": "str", "ray_index": "int", "residual_px": "float",
                             "residual_m": "float", "outlier": "bool", "excluded": "bool"}
LINE_TYPES: dict[str, str] = {"line_id": "str", "point_ids": "str", "n_points": "int",
                              "length_3d": "float", "sigma_length_3d": "float",
                              "length_2d": "float", "sigma_length_2d": "float"}
POLYGON_TYPES: dict[str, str] = {"polygon_id": "str", "point_ids": "str", "n_points": "int",
                                 "area_2d": "float", "sigma_area_2d": "float",
                                 "perimeter_2d": "float", "sigma_perimeter_2d": "float"}
ELLIPSE_TYPES: dict[str, str] = {"point_id": "str", "ellipse_major_95": "float",
                                 "ellipse_minor_95": "float", "ellipse_bearing_deg": "float"}
CHECK_POINT_TYPES: dict[str, str] = {"point_id": "str", "role": "str", "description": "str",
                                     "easting": "float", "northing": "float",
                                     "height": "float", "measured": "bool",
                                     "d_easting": "float", "d_northing": "float",
                                     "d_height": "float"}

#: Vertices of an error-ellipse polygon (closed ring: one more).
ELLIPSE_VERTICES = 36


@dataclass
class Table:
    """Named columns of equal length: numpy float/int/bool arrays or object arrays of str/None."""

    columns: dict[str, np.ndarray]
    types: dict[str, str]  # name -> 'str' | 'float' | 'int' | 'bool'

    def __len__(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0


@dataclass
class ExportData:
    """Everything an export writes. Geometry arrays are in the grid CRS (E, N, H)."""

    crs: str  # as the measurements state it, e.g. 'EPSG:27700' or 'EPSG:27700+5701'
    horizontal_crs: str  # the projected part, for 2-D layers
    height_type: str
    vertical_datum: str
    points: Table
    point_xyz: np.ndarray  # (M, 3)
    point_llh: np.ndarray  # (M, 3) WGS 84 lon, lat (degrees), ellipsoidal height (m)
    rays: Table | None = None
    ray_xyz: np.ndarray | None = None  # (R, 2, 3) camera centre -> point
    lines: Table | None = None
    line_index: list[np.ndarray] = field(default_factory=list)  # point indices per line
    polygons: Table | None = None
    polygon_index: list[np.ndarray] = field(default_factory=list)  # ring, counterclockwise in E, N
    ellipses: Table | None = None
    ellipse_xy: np.ndarray | None = None  # (M', V + 1, 2) closed rings
    check_points: Table | None = None
    check_xyz: np.ndarray | None = None  # (C, 3), NaN height where unknown
    buildings: Table | None = None
    building_rings: list[np.ndarray] = field(default_factory=list)  # (k, 3) open rings, E N H


def _get(obj: Any, key: str, default: Any = None) -> Any:
    if isinstance(obj, Mapping):
        return obj.get(key, default)
    return getattr(obj, key, default)


def _is_failure(m: Any) -> bool:
    if type(m).__name__ == "Measurement":  # the common case, without an ABC check per point
        return False
    if isinstance(m, Mapping):
        return "error" in m and "point_id" in m and m.get("easting") is None and "rays" not in m
    return type(m).__name__ == "MeasurementFailure"


def _record(m: Any) -> Mapping[str, Any]:
    if isinstance(m, Mapping):
        missing = [k for k in RECORD_KEYS if k not in m]
        if missing:
            raise InputError(
                f"measurement {m.get('point_id', '?')!r}: not a point-schema record "
                f"(missing {', '.join(missing[:4])}{'...' if len(missing) > 4 else ''})")
        return m
    if not hasattr(m, "record"):
        raise InputError(f"cannot export {type(m).__name__}: expected gsgeo.crs Measurement objects")
    return m.record()


def _all_measurements(items: list) -> bool:
    """All items are gsgeo.crs Measurement objects (one set of types, no per-item frame)."""
    return all(t.__name__ == "Measurement" for t in set(map(type, items)))


GRID_FLOATS = ("easting", "northing", "height", "sigma_e", "sigma_n", "sigma_h", "ellipse_major_95",
               "ellipse_minor_95", "ellipse_bearing_deg", "operation_accuracy_m")
GRID_TEXTS = ("height_type", "vertical_datum", "crs", "operation")


def _fields(objs: list, names: tuple[str, ...]) -> list[list]:
    """The attributes `names` of every object, one list per name (no tuple per object: the
    garbage collector would walk them)."""
    return [list(map(attrgetter(k), objs)) for k in names]


def _floats(objs: list, names: tuple[str, ...]) -> np.ndarray:
    """(M, len(names)) float64 of the attributes of every object (two or more names; None -> NaN)."""
    get = attrgetter(*names)
    n, f = len(objs), len(names)
    try:
        flat = np.fromiter(chain.from_iterable(map(get, objs)), dtype=np.float64, count=n * f)
    except (TypeError, ValueError):  # None where a value is unknown
        vals = [math.nan if v is None else v for v in chain.from_iterable(map(get, objs))]
        try:
            flat = np.array(vals, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"columns {', '.join(names)}: expected numbers") from None
    return flat.reshape(n, f)


def _measurement_columns(ms: list) -> dict[str, Any] | None:
    """The point-schema columns of Measurement objects without a record() per point.

    Gives exactly what Measurement.record() gives (the export tests compare the two), with
    each attribute gathered in one pass over all points and the per-point numpy reductions
    done once. Float columns come back as float64 arrays, text columns as lists. None when
    an object is not a Measurement with a grid point and covariance (the caller then uses
    record()).
    """
    if not _all_measurements(ms):
        return None
    pid, code, desc, measured_at, grids, sols, exc = _fields(
        ms, ("point_id", "code", "description", "measured_at", "grid", "solution", "excluded"))
    if type(None) in set(map(type, grids)):
        return None
    covs = list(map(attrgetter("covariance"), grids))
    if type(None) in set(map(type, covs)):
        return None
    cov = np.concatenate(covs, dtype=np.float64).reshape(-1, 3, 3)
    n_all = np.fromiter(map(len, exc), dtype=np.int64, count=len(exc))
    n_excl = np.add.reduceat(np.concatenate(exc).astype(np.int64), np.cumsum(n_all) - n_all)
    px = list(map(attrgetter("residuals_px"), sols))
    if type(None) not in set(map(type, px)):
        lens = np.fromiter(map(len, px), dtype=np.int64, count=len(px))
        max_px: Any = np.maximum.reduceat(np.concatenate(px), np.cumsum(lens) - lens)
    else:  # a mix of angular and unweighted points
        max_px = [None if v is None else float(np.max(v)) for v in px]
    out: dict[str, Any] = {"point_id": pid, "code": code, "description": desc,
                           "measured_at": measured_at}
    gf = _floats(grids, GRID_FLOATS)
    out.update((k, gf[:, i]) for i, k in enumerate(GRID_FLOATS))
    out.update(zip(GRID_TEXTS, _fields(grids, GRID_TEXTS), strict=True))
    sf = _floats(sols, ("sigma0", "max_angle_deg", "rms_m"))
    out.update((k, sf[:, i]) for i, k in enumerate(("sigma0", "max_angle_deg", "rms_m")))
    mf = _floats(ms, ("lon", "lat", "h_wgs84"))
    out.update((k, mf[:, i]) for i, k in enumerate(("lon", "lat", "h_wgs84")))
    meas = list(map(attrgetter("sigma_meas"), ms))
    for k in ("sigma_e_meas", "sigma_n_meas", "sigma_h_meas"):
        out[k] = out[k.removesuffix("_meas")].copy()
    if set(map(type, meas)) != {type(None)}:  # some points carry a georeference's uncertainty
        have = np.flatnonzero([v is not None for v in meas])
        sm = np.array([meas[i] for i in have], dtype=np.float64).reshape(-1, 3)
        for i, k in enumerate(("sigma_e_meas", "sigma_n_meas", "sigma_h_meas")):
            out[k][have] = sm[:, i]
    out["n_rays"] = n_all - n_excl
    out["max_residual_px"] = max_px
    for k, (a, b) in {"cov_ee": (0, 0), "cov_en": (0, 1), "cov_eh": (0, 2), "cov_nn": (1, 1),
                      "cov_nh": (1, 2), "cov_hh": (2, 2)}.items():
        out[k] = cov[:, a, b]
    return out


def _column(values: list, kind: str, name: str, as_text: bool = True) -> np.ndarray:
    if kind == "str":
        if not as_text:
            out = np.empty(len(values), dtype=object)
            out[:] = values
            return out
        return np.array([None if v is None else str(v) for v in values], dtype=object)
    if kind == "int":
        return np.array(values, dtype=np.int32)
    try:
        return np.array(values, dtype=np.float64)  # None -> NaN
    except (TypeError, ValueError):
        raise InputError(f"column {name}: expected numbers") from None


def _rays(m: Any) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray, np.ndarray] | None:
    """Camera centres in the grid (N, 3), residuals px / m, outlier, excluded flags; None if absent."""
    org: np.ndarray | None
    if isinstance(m, Mapping):
        rays = m.get("rays") or []
        if not rays or any(r.get("origin_grid") is None for r in rays):
            return None
        org = np.array([r["origin_grid"] for r in rays], dtype=np.float64)
        px = np.array([math.nan if r.get("residual_px") is None else r["residual_px"] for r in rays])
        rm = np.array([math.nan if r.get("residual_m") is None else r["residual_m"] for r in rays])
        out = np.array([bool(r.get("outlier")) for r in rays])
        exc = np.array([bool(r.get("excluded")) for r in rays])
        return org, px, rm, out, exc
    org = getattr(m, "ray_origins_grid", None)
    if org is None:
        return None
    n = org.shape[0]
    px = m.residuals_px if m.residuals_px is not None else np.full(n, math.nan)
    rm = m.residuals_m if m.residuals_m is not None else np.full(n, math.nan)
    out = m.outliers if m.outliers is not None else np.zeros(n, dtype=bool)
    return org, px, rm, out, np.asarray(m.excluded, dtype=bool)


def _feature_parts(item: Any, kind: str, i: int) -> tuple[str, list[str]]:
    """(id, point ids) of a line/polygon given as session Feature, store record, dict or tuple."""
    if isinstance(item, (tuple, list)) and len(item) == 2 and isinstance(item[1], (list, tuple)):
        fid, pids = item
    else:
        fid = _get(item, "id")
        pids = _get(item, "points")
        if pids is None:
            pids = _get(item, "point_ids")
    if fid is None or pids is None or isinstance(pids, str):
        raise InputError("expected an id and a list of point ids", field=f"{kind}s[{i}]")
    return str(fid), [str(p) for p in pids]


def _resolve(kind: str, fid: str, pids: list[str], index: dict[str, int],
             failed: dict[str, str]) -> np.ndarray:
    out = []
    for p in pids:
        if p in index:
            out.append(index[p])
        elif p in failed:
            raise InputError(f"{kind} '{fid}': point '{p}' was not solved ({failed[p]})")
        else:
            raise InputError(f"{kind} '{fid}': unknown point id '{p}'")
    return np.array(out, dtype=np.int64)


def ellipse_rings(e: ArrayLike, n: ArrayLike, major: ArrayLike, minor: ArrayLike,
                  bearing_deg: ArrayLike, unit_m: float = 1.0,
                  vertices: int = ELLIPSE_VERTICES) -> np.ndarray:
    """Closed counterclockwise rings (M, vertices + 1, 2) of ellipses in (E, N).

    Semi-axes in metres (divided by unit_m for the CRS's units), bearing of the major axis in
    degrees clockwise from grid north.
    """
    b = np.radians(np.asarray(bearing_deg, dtype=np.float64))
    t = np.linspace(0.0, 2 * np.pi, vertices, endpoint=False)
    ct, st = np.cos(t)[None, :], np.sin(t)[None, :]
    a_ = np.asarray(major, dtype=np.float64) / unit_m
    b_ = np.asarray(minor, dtype=np.float64) / unit_m
    # Major axis u = (sin b, cos b); v = (-cos b, sin b) makes (u, v) counterclockwise:
    # p(t) = c + a cos t u + b sin t v. Written into one array (few large temporaries).
    ring = np.empty((b.shape[0], vertices + 1, 2))
    x, y = ring[:, :vertices, 0], ring[:, :vertices, 1]
    np.multiply((a_ * np.sin(b))[:, None], ct, out=x)
    x -= (b_ * np.cos(b))[:, None] * st
    x += np.asarray(e, dtype=np.float64)[:, None]
    np.multiply((a_ * np.cos(b))[:, None], ct, out=y)
    y += (b_ * np.sin(b))[:, None] * st
    y += np.asarray(n, dtype=np.float64)[:, None]
    ring[:, vertices] = ring[:, 0]
    return ring


def _provenance_columns(solved: list, ids: list[str],
                        provenance: Mapping[str, Mapping[str, Any]] | None) -> dict[str, list]:
    """The PROVENANCE_KEYS columns: from ``provenance`` (point id -> its values, as
    gsgeo.pointschema.provenance gives them) where it names the point; otherwise unknown
    measured_by and every ray taken as clicked (a Measurement or result does not say)."""
    given = provenance or {}
    cols: dict[str, list] = {k: [] for k in PROVENANCE_KEYS}
    for m, pid in zip(solved, ids, strict=True):
        got = given.get(pid)
        if got is None:
            rays = _get(m, "excluded")
            if rays is None:
                rays = _get(m, "rays") or ()
            got = {"measured_by": None, "n_rays_clicked": len(rays), "n_rays_auto": 0}
        for k in PROVENANCE_KEYS:
            cols[k].append(got.get(k))
    for k in ("n_rays_clicked", "n_rays_auto"):
        if any(not isinstance(v, int) or isinstance(v, bool) for v in cols[k]):
            raise InputError(f"column {k}: expected a whole number of rays for every point")
    return cols


def collect(measurements: Iterable[Any], *, lines: Iterable[Any] = (),
            polygons: Iterable[Any] = (), check_points: Iterable[Any] = (),
            buildings: Iterable[Any] = (), map_layers: bool = True,
            provenance: Mapping[str, Mapping[str, Any]] | None = None) -> ExportData:
    """Validate and gather everything an export writes (see module docstring).

    ``provenance``: point id -> its PROVENANCE_KEYS values (who measured it, rays clicked and
    matched automatically), the columns after the point schema; a point it does not name
    has measured_by unknown and all its rays counted as clicked.

    map_layers=False leaves out the rays, error ellipses and buildings (GeoPackage-only
    layers). ``buildings``: built LoD2 models in the measurements' grid CRS, each with ``id``,
    ``measures`` (a mapping) and ``surface_rings()`` ((kind, (k, 3) open ring) per surface),
    as gsgeo.buildings.model.BuildingModel has them.

    Raises InputError (nothing measured, unknown or unsolved point ids, malformed input),
    GeometryError (a bad line or polygon, prefixed with its id) or CRSError (no grid CRS, or
    measurements in different CRSs).
    """
    items = list(measurements)
    failed: dict[str, str] = {}
    solved = items
    if not _all_measurements(items):
        fail = [_is_failure(m) for m in items]
        failed = {str(_get(m, "point_id")): str(_get(m, "error"))
                  for m, f in zip(items, fail, strict=True) if f}
        solved = [m for m, f in zip(items, fail, strict=True) if not f]
    if not solved:
        why = f" ({len(failed)} point(s) could not be solved)" if failed else ""
        raise InputError(f"nothing to export: no measured points{why}")
    raw = _measurement_columns(solved)
    as_text = raw is None  # records from JSON: make every text field a str
    if raw is None:
        recs = [_record(m) for m in solved]
        raw = {k: [r[k] for r in recs] for k in RECORD_KEYS}
    ids = [str(v) for v in raw["point_id"]] if as_text else raw["point_id"]
    if (not isinstance(raw["easting"], np.ndarray) and None in raw["easting"]) or None in raw["crs"]:
        i = next(i for i, (e, c) in enumerate(zip(raw["easting"], raw["crs"], strict=True))
                 if e is None or c is None)
        raise CRSError(
            f"cannot export without grid coordinates (point '{ids[i]}' has none): solve "
            "with a projected CRS, e.g. --crs EPSG:27700")
    first = {k: raw[k][0] for k in ("point_id", "crs", "height_type", "vertical_datum")}
    for key in ("crs", "height_type", "vertical_datum"):
        if len(set(raw[key])) > 1:
            other = next(i for i, v in enumerate(raw[key]) if v != first[key])
            raise CRSError(
                f"points '{ids[0]}' and '{ids[other]}' differ in {key} "
                f"({first[key]!r} vs {raw[key][other]!r}); one export holds one CRS")
    index = dict(zip(ids, range(len(ids)), strict=True))
    if len(index) != len(ids):
        seen: set[str] = set()
        for dup in ids:  # the first id that comes a second time
            if dup in seen:
                break
            seen.add(dup)
        raise InputError(f"duplicate point id '{dup}' in the measurements")
    try:
        g = grid_crs(first["crs"])
    except CRSError as exc:
        raise CRSError(f"the measurements' CRS cannot be used for export: {exc}") from None
    crs_text = str(first["crs"])

    cols = {k: _column(raw[k], POINT_TYPES[k], k, as_text) for k in RECORD_KEYS}
    cols.update((k, _column(v, POINT_TYPES[k], k))
                for k, v in _provenance_columns(solved, [str(i) for i in ids],
                                                provenance).items())
    points = Table(cols, dict(POINT_TYPES))
    xyz = np.column_stack([cols["easting"], cols["northing"], cols["height"]])
    llh = np.column_stack([cols["lon"], cols["lat"], cols["h_wgs84"]])
    if not np.all(np.isfinite(xyz)):
        bad = ids[int(np.flatnonzero(~np.all(np.isfinite(xyz), axis=1))[0])]
        raise InputError(f"point '{bad}': easting, northing or height is not a finite number")
    cov = np.empty((len(ids), 3, 3))
    for (a, b), k in zip(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)),
                         ("cov_ee", "cov_en", "cov_eh", "cov_nn", "cov_nh", "cov_hh"), strict=True):
        cov[:, a, b] = cov[:, b, a] = cols[k]

    data = ExportData(crs=crs_text, horizontal_crs=g.id, height_type=str(first["height_type"]),
                      vertical_datum=str(first["vertical_datum"]), points=points,
                      point_xyz=xyz, point_llh=llh)
    if map_layers:
        _collect_rays(data, solved, xyz, ids)
    _collect_features(data, lines, polygons, index, failed, ids, xyz, cov, g)
    ok = np.isfinite(cols["ellipse_major_95"]) & np.isfinite(cols["ellipse_minor_95"])
    if map_layers and ok.any():
        sel = np.flatnonzero(ok)
        data.ellipses = Table({
            "point_id": cols["point_id"][sel],
            "ellipse_major_95": cols["ellipse_major_95"][sel],
            "ellipse_minor_95": cols["ellipse_minor_95"][sel],
            "ellipse_bearing_deg": cols["ellipse_bearing_deg"][sel],
        }, dict(ELLIPSE_TYPES))
        data.ellipse_xy = ellipse_rings(xyz[sel, 0], xyz[sel, 1], cols["ellipse_major_95"][sel],
                                        cols["ellipse_minor_95"][sel],
                                        np.nan_to_num(cols["ellipse_bearing_deg"][sel]),
                                        g.unit_factor)
    _collect_check_points(data, check_points, index, xyz, g)
    if map_layers:
        collect_buildings(data, buildings)
    for layer in ("points", "lines", "polygons", "check_points", "buildings"):
        if getattr(data, layer) is not None:
            _check_text(layer, getattr(data, layer))
    return data


def _check_text(layer: str, table: Table) -> None:
    """Every text value can be written as UTF-8 (JSON input can hold lone surrogates such as
    "\\ud800", which no export format can store)."""

    def ok(v: object) -> bool:
        try:
            str(v).encode("utf-8")
        except UnicodeEncodeError:
            return False
        return True

    for name, kind in table.types.items():
        if kind != "str":
            continue
        col = table.columns[name]
        try:
            text = "".join(col)
        except TypeError:  # None (unknown) or a non-str value
            text = "".join(["" if v is None else str(v) for v in col])
        if ok(text):
            continue
        k = next(k for k, v in enumerate(col) if not ok(v))
        ident = table.columns[next(iter(table.columns))][k]
        problem = f"{name} is not valid Unicode text (a lone surrogate such as \\ud800)"
        if ok(ident):  # named by its id, which a reader finds more easily than an index
            raise InputError(f"{layer} '{ident}': {problem}")
        raise InputError(problem, field=f"{layer}[{k}]")


def _measurement_rays(ms: list) -> tuple[np.ndarray, ...] | None:
    """`_rays` for many Measurement objects at once: (owners, counts, origins, px, m, out, exc)."""
    org, px, rm, out, exc = _fields(
        ms, ("ray_origins_grid", "residuals_px", "residuals_m", "outliers", "excluded"))
    if type(None) not in set(map(type, org)):
        have = np.arange(len(ms))
    else:
        have = np.array([i for i, o in enumerate(org) if o is not None], dtype=np.int64)
        if not have.size:
            return None
        org, px, rm, out, exc = ([v[i] for i in have] for v in (org, px, rm, out, exc))
    counts = np.fromiter(map(len, org), dtype=np.int64, count=len(org))

    def cat(vals: list[Any], fill: float) -> np.ndarray:
        if type(None) not in set(map(type, vals)):
            return np.concatenate(vals)
        return np.concatenate([np.full(c, fill) if v is None else np.asarray(v)
                               for v, c in zip(vals, counts, strict=True)])

    return (have, counts, np.concatenate(org), cat(px, math.nan), cat(rm, math.nan),
            cat(out, False).astype(bool), np.concatenate(exc).astype(bool))


def _collect_rays(data: ExportData, solved: list, xyz: np.ndarray, ids: list[str]) -> None:
    if _all_measurements(solved):
        fast = _measurement_rays(solved)
        if fast is None:
            return
        have, counts, org, px, rm, out, exc = fast
        # (owner, (origins, px, m, outlier, excluded)); origins are only read from _rays' parts
        parts: Sequence[tuple[int, tuple[np.ndarray | None, Any, Any, Any, Any]]] = \
            [(0, (None, px, rm, out, exc))]
    else:
        found = [(i, r) for i, m in enumerate(solved) if (r := _rays(m)) is not None]
        if not found:
            return
        parts = found
        have = np.array([i for i, _ in found])
        counts = np.array([r[0].shape[0] for _, r in found])
        org = np.concatenate([r[0] for _, r in found])
    owner = np.repeat(have, counts)
    seg = np.stack([org, xyz[owner]], axis=1)
    pid = np.array(ids, dtype=object)[owner]
    data.ray_xyz = seg
    data.rays = Table({
        "point_id": pid,
        "ray_index": (np.arange(owner.shape[0]) - np.repeat(np.cumsum(counts) - counts, counts)
                      ).astype(np.int32),
        "residual_px": np.concatenate([np.asarray(r[1], dtype=float) for _, r in parts]),
        "residual_m": np.concatenate([np.asarray(r[2], dtype=float) for _, r in parts]),
        "outlier": np.concatenate([np.asarray(r[3], dtype=bool) for _, r in parts]),
        "excluded": np.concatenate([np.asarray(r[4], dtype=bool) for _, r in parts]),
    }, dict(RAY_TYPES))


def _ids_text(pids: Sequence[str]) -> str:
    return json.dumps(list(pids), ensure_ascii=False)


def _parse_features(items: Iterable[Any], kind: str, index: dict[str, int],
                    failed: dict[str, str]) -> tuple[list, GsgeoError | None]:
    """(id, point ids, point indices) of each line/polygon up to the first malformed one, and its error."""
    seen: set[str] = set()
    rows = []
    try:
        for i, item in enumerate(items):
            fid, pids = _feature_parts(item, kind, i)
            if fid in seen:
                raise InputError(f"duplicate {kind} id '{fid}'")
            seen.add(fid)
            if kind == "polygon":
                given = len(pids)
                if len(pids) > 1 and pids[-1] == pids[0]:
                    pids = pids[:-1]  # closed explicitly; polygons close themselves
                dup = next((p for j, p in enumerate(pids) if p in pids[:j]), None)
                if dup is not None:
                    raise InputError(f"polygon '{fid}': point '{dup}' appears more than once")
                if len(pids) < 3:  # counted here, where the ids the user gave are known
                    of = f" (of {given} given)" if given > len(pids) else ""
                    raise GeometryError(f"polygon '{fid}': a polygon needs at least 3 distinct "
                                        f"points, got {len(pids)}{of}")
            rows.append((fid, pids, _resolve(kind, fid, pids, index, failed)))
    except GsgeoError as exc:
        return rows, exc
    return rows, None


def _measure_features(kind: str, rows: list, xyz: np.ndarray, cov: np.ndarray, unit: float,
                      vunit: float) -> Any:
    """Measures of all rows at once (LineArrays for lines, PolygonArrays for polygons); a row
    the batch flags goes through the single-feature function, which raises its error
    (prefixed with the feature's id) or gives its values."""
    out: LineArrays | PolygonArrays
    pts = [xyz[r[2]] for r in rows]
    covs = [cov[r[2]] for r in rows]
    if kind == "line":
        out, ok = line_measures_many(pts, covs, unit_m=unit, vertical_unit_m=vunit)
    else:
        out, ok = polygon_measures_many(pts, covs, unit_m=unit)
    single = line_measures if kind == "line" else polygon_measures
    for k in np.flatnonzero(~ok):
        fid, pids, _ = rows[k]
        try:
            m = single(pts[k], covs[k], pids, unit_m=unit, vertical_unit_m=vunit)
        except GsgeoError as exc:
            raise exc.part_of(None, f"{kind} '{fid}'") from None
        for name, value in vars(m).items():
            getattr(out, name)[k] = math.nan if value is None else value
    return out


def _collect_features(data: ExportData, lines: Iterable[Any], polygons: Iterable[Any],
                      index: dict[str, int], failed: dict[str, str], ids: list[str],
                      xyz: np.ndarray, cov: np.ndarray, g: GridCRS) -> None:
    unit, vunit = g.unit_factor, g.vertical_unit_factor
    rows, err = _parse_features(lines, "line", index, failed)
    if rows:
        m = _measure_features("line", rows, xyz, cov, unit, vunit)
        data.line_index = [r[2] for r in rows]
        data.lines = Table({
            "line_id": np.array([r[0] for r in rows], dtype=object),
            "point_ids": np.array([_ids_text(r[1]) for r in rows], dtype=object),
            "n_points": m.n_points.astype(np.int32),
            "length_3d": m.length_3d,
            "sigma_length_3d": m.sigma_length_3d,
            "length_2d": m.length_2d,
            "sigma_length_2d": m.sigma_length_2d,
        }, dict(LINE_TYPES))
    if err is not None:
        raise err
    rows, err = _parse_features(polygons, "polygon", index, failed)
    if rows:
        m = _measure_features("polygon", rows, xyz, cov, unit, vunit)
        data.polygon_index = [idx if ccw else idx[::-1]
                              for (_, _, idx), ccw in zip(rows, m.counterclockwise, strict=True)]
        data.polygons = Table({
            "polygon_id": np.array([r[0] for r in rows], dtype=object),
            "point_ids": np.array([_ids_text(r[1]) for r in rows], dtype=object),
            "n_points": m.n_points.astype(np.int32),
            "area_2d": m.area_2d,
            "sigma_area_2d": m.sigma_area_2d,
            "perimeter_2d": m.perimeter_2d,
            "sigma_perimeter_2d": m.sigma_perimeter_2d,
        }, dict(POLYGON_TYPES))
    if err is not None:
        raise err


def _collect_check_points(data: ExportData, check_points: Iterable[Any], index: dict[str, int],
                          xyz: np.ndarray, g: GridCRS) -> None:
    """Check points in the export's grid CRS: id and easting/northing[/height] (or x/y/z),
    ``role`` ("check" or "control"; "check" when not given), ``description`` (text, or
    empty)."""
    rows = []
    roles = []
    descriptions: list[str] = []
    for i, c in enumerate(check_points):
        cid = _get(c, "point_id", _get(c, "id"))
        vals = []
        for names in (("easting", "x"), ("northing", "y"), ("height", "z")):
            v = next((_get(c, k) for k in names if _get(c, k) is not None), None)
            vals.append(v)
        if cid is None or vals[0] is None or vals[1] is None:
            raise InputError("expected an id and easting/northing (x/y)", field=f"check_points[{i}]")
        crs = _get(c, "crs")
        if crs and not parse_crs(str(crs)).equals(parse_crs(data.crs)) and not \
                parse_crs(str(crs)).equals(parse_crs(data.horizontal_crs)):
            raise CRSError(f"check point '{cid}' is in {crs}, the export in {data.crs}; "
                           "transform the check points first")
        try:
            row = [float(v) if v is not None else math.nan for v in vals]
        except (TypeError, ValueError):
            raise InputError(f"check point '{cid}': coordinates must be numbers") from None
        rows.append((str(cid), row))
        roles.append(str(_get(c, "role") or "check"))
        descriptions.append(str(_get(c, "description") or ""))
    if not rows:
        return
    cxyz = np.array([r[1] for r in rows], dtype=np.float64)
    if not np.all(np.isfinite(cxyz[:, :2])):
        raise InputError("check points: easting and northing must be finite numbers")
    match = np.array([index.get(r[0], -1) for r in rows])
    d = np.full((len(rows), 3), math.nan)
    has = match >= 0
    d[has] = xyz[match[has]] - cxyz[has]
    data.check_xyz = cxyz
    data.check_points = Table({
        "point_id": np.array([r[0] for r in rows], dtype=object),
        "role": np.array(roles, dtype=object),
        "description": np.array(descriptions, dtype=object),
        "easting": cxyz[:, 0], "northing": cxyz[:, 1], "height": cxyz[:, 2],
        "measured": has,
        "d_easting": d[:, 0], "d_northing": d[:, 1], "d_height": d[:, 2],
    }, dict(CHECK_POINT_TYPES))


def collect_buildings(data: ExportData, buildings: Iterable[Any]) -> None:
    """The buildings layer of ``data``: one row per surface of each building (see collect)."""
    got = building_table(buildings)
    if got is not None:
        data.buildings, data.building_rings = got


def building_table(buildings: Iterable[Any]) -> tuple[Table, list[np.ndarray]] | None:
    """One row per surface of each building (columns BUILDING_TYPES) and the surfaces' open
    rings ((k, 3) E, N, H), or None without any; buildings as ``collect`` takes them."""
    rows: list[tuple[str, int, str, Mapping[str, Any]]] = []
    rings: list[np.ndarray] = []
    for b in buildings:
        bid = str(_get(b, "id"))
        measures = _get(b, "measures") or {}
        for k, (kind, ring) in enumerate(b.surface_rings()):
            r = np.asarray(ring, dtype=np.float64).reshape(-1, 3)
            if r.shape[0] < 3 or not np.all(np.isfinite(r)):
                raise InputError(f"building '{bid}': surface {k} is not a ring of finite "
                                 "E, N, H")
            rows.append((bid, k, str(kind), measures))
            rings.append(r)
    if not rows:
        return None
    cols: dict[str, np.ndarray] = {
        "building_id": np.array([r[0] for r in rows], dtype=object),
        "surface_index": np.array([r[1] for r in rows], dtype=np.int32),
        "surface_type": np.array([r[2] for r in rows], dtype=object),
        "roof_type": np.array([None if r[3].get("roof_type") is None else str(r[3]["roof_type"])
                               for r in rows], dtype=object),
    }
    for name in BUILDING_MEASURES:
        vals = [r[3].get(name) for r in rows]
        cols[name] = _column([math.nan if v is None else v for v in vals], "float", name)
    return Table(cols, dict(BUILDING_TYPES)), rings
