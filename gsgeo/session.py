"""The session JSON (README, "Session JSON"): rays of measured points, lines, polygons and
LoD2 buildings (gsgeo.buildings.spec: roof faces as rings of point ids, a ground).

`load_session` / `parse_session` validate the whole document and raise
:class:`~gsgeo.errors.InputError` with the JSON path of the first problem
(e.g. ``points[2].rays[0].direction``), so a surveyor can find it in the file.

The file is read with bounds: at most ``MAX_SESSION_BYTES``, strict UTF-8 JSON parsed by orjson
(nesting deeper than 1024 levels, numbers beyond a 64-bit float, NaN / Infinity literals and
unpaired surrogates are refused with their line and column). This module checks the JSON
shape; a point's rays become :class:`gsgeo.measure.Rays`, whose constructor checks the ranges
of ifov, origins, directions and model matrices once (:mod:`gsgeo.limits`, as sigma_px and
the id rule here). :func:`measure_session` and :func:`measure_session_point` measure
sessions and their points through gsgeo.measure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import orjson

from gsgeo import limits
from gsgeo.buildings.spec import BuildingSpec, parse_building
from gsgeo.errors import InputError, join_field
from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.measure import Measurement, MeasurementFailure, Rays, SolveSettings, measure_points
from gsgeo.measure import measure_point as measure_rays
from gsgeo.solve.linalg import FloatArray

#: Largest session file read, bytes (10 000 points of 10 rays take about 5 MB).
MAX_SESSION_BYTES = 200 * 1024 * 1024

IDENTITY16 = (1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0)


@dataclass
class Ray:
    """One aim: rendered-ECEF origin and direction (metres), optional pixel metadata."""

    origin: FloatArray
    direction: FloatArray
    ifov: float | None = None
    pixel: tuple[float, float] | None = None
    viewport: tuple[float, float] | None = None
    model_matrix: FloatArray | None = None  # 16 numbers, column-major; None = identity
    # provenance: matched automatically (True; its reference click's aiming error is shared,
    # gsgeo.solve.sharedaim) or clicked (False; None: not said, a click), and the match score
    # (peak NCC, None: none; kept with the ray, not used by the solver)
    auto: bool | None = None
    score: float | None = None

    def provenance(self) -> JSONObject:
        """The ray's ``auto`` and ``score`` members as given (none when not given)."""
        out: JSONObject = {}
        if self.auto is not None:
            out["auto"] = self.auto
        if self.score is not None:
            out["score"] = self.score
        return out

    def to_dict(self) -> JSONObject:
        out: JSONObject = {
            "origin": [float(v) for v in self.origin],
            "direction": [float(v) for v in self.direction],
        }
        if self.ifov is not None:
            out["ifov"] = self.ifov
        if self.pixel is not None:
            out["pixel"] = list(self.pixel)
        if self.viewport is not None:
            out["viewport"] = list(self.viewport)
        if self.model_matrix is not None:
            out["model_matrix"] = [float(v) for v in self.model_matrix]
        return out | self.provenance()


@dataclass
class SessionPoint:
    """A point of the session: id, code, description and its rays.

    ``typed`` is the validated :class:`~gsgeo.measure.Rays` when the point was parsed from
    JSON; :meth:`to_rays` builds (and validates) it for a point made in code.
    """

    id: str
    rays: list[Ray]
    code: str = ""
    description: str = ""
    typed: Rays | None = field(default=None, repr=False, compare=False)

    def to_rays(self) -> Rays:
        """The point's rays as the typed core (validated once)."""
        if self.typed is None:
            self.typed = Rays.from_columns(
                [r.origin for r in self.rays], [r.direction for r in self.rays],
                [r.ifov for r in self.rays], [r.pixel for r in self.rays],
                [r.viewport for r in self.rays],
                [None if r.model_matrix is None else r.model_matrix for r in self.rays],
                [r.auto for r in self.rays])
        return self.typed


@dataclass
class Feature:
    """A line or polygon given by the ids of its points, in order."""

    id: str
    points: list[str]


@dataclass
class Session:
    points: list[SessionPoint]
    source_crs: str = "EPSG:4978"
    crs: str | None = None
    vertical: str | None = None
    sigma_px: float = 1.0
    lines: list[Feature] = field(default_factory=list)
    polygons: list[Feature] = field(default_factory=list)
    buildings: list[BuildingSpec] = field(default_factory=list)


def load_session(path: str | Path) -> Session:
    """Read and validate a session JSON file (at most MAX_SESSION_BYTES, UTF-8)."""
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            data = fh.read(MAX_SESSION_BYTES + 1)  # bounded even for /dev/zero or a pipe
    except FileNotFoundError:
        raise InputError("no such file", source=str(p)) from None
    except IsADirectoryError:
        raise InputError("is a directory, not a session JSON file", source=str(p)) from None
    except OSError as exc:
        raise InputError(f"cannot be read: {exc.strerror or exc}", source=str(p)) from None
    if len(data) > MAX_SESSION_BYTES:
        raise InputError(f"larger than {MAX_SESSION_BYTES // 2**20} MiB; not a session file",
                         source=str(p))
    try:
        return parse_session(parse_json(data))
    except InputError as exc:
        raise exc.in_source(str(p)) from None


def parse_json(data: bytes | str) -> JSON:
    """Decode JSON text strictly and with bounded depth (orjson), or InputError saying what and
    where: nesting deeper than 1024 levels, a number beyond a 64-bit float, NaN / Infinity,
    invalid UTF-8 or unpaired surrogates. A leading UTF-8 byte order mark is skipped."""
    if isinstance(data, str):
        data = data.encode("utf-8", "surrogatepass")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    try:
        return orjson.loads(data)
    except orjson.JSONDecodeError as exc:
        what = {"depth limit exceeded": "JSON nested more than 1024 levels deep",
                "number is infinity when parsed as double": "a number too large for a 64-bit float",
                }.get(exc.msg, f"not valid JSON: {exc.msg}")
        raise InputError(f"{what} at line {exc.lineno}, column {exc.colno}") from None


def _describe(value: JSON) -> str:
    """A short description of a JSON value for a message (never the whole of a large value)."""
    if isinstance(value, bool) or value is None:
        return {True: "true", False: "false", None: "null"}[value]
    if isinstance(value, str):
        return repr(value[:30] + ("..." if len(value) > 30 else ""))
    if isinstance(value, list):
        return f"a list of {len(value)} items"
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, int) and value.bit_length() > limits.MAX_INT_BITS:
        return f"an integer of {value.bit_length()} bits"
    return str(value)[:30]


def _number(value: JSON, field: str | None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"expected a number, got {_describe(value)}", field=field)
    try:
        v = float(value)
    except OverflowError:
        raise InputError("expected a finite number, got an integer too large for a float",
                         field=field) from None
    if not math.isfinite(v):
        raise InputError("expected a finite number", field=field)
    return v


def _vector(value: JSON, n: int, field: str | None) -> FloatArray:
    if not isinstance(value, list) or len(value) != n:
        raise InputError(f"expected a list of {n} numbers", field=field)
    return np.array([_number(v, join_field(field, f"[{i}]")) for i, v in enumerate(value)])


def _text(value: JSON, field: str | None, default: str = "") -> str:
    if value is None:
        return default
    if not isinstance(value, (str, int)) or isinstance(value, bool) or (
            isinstance(value, int) and value.bit_length() > limits.MAX_INT_BITS):
        raise InputError("expected text", field=field)
    return str(value)


def _ray_members(doc: JSON, field: str | None) -> Ray:
    """The JSON shape of one ray object (numbers, lengths, members); ranges are the typed
    core's (gsgeo.measure.Rays)."""
    if not isinstance(doc, dict):
        raise InputError("expected an object with origin and direction", field=field)
    for key in ("origin", "direction"):
        if key not in doc:
            raise InputError(f"missing '{key}'", field=field)
    at = {key: join_field(field, key)
          for key in ("origin", "direction", "ifov", "pixel", "viewport", "model_matrix")}
    origin = _vector(doc["origin"], 3, at["origin"])
    direction = _vector(doc["direction"], 3, at["direction"])
    ifov = None
    if doc.get("ifov") is not None:
        ifov = _number(doc["ifov"], at["ifov"])
    pixel = viewport = mm = None
    if doc.get("pixel") is not None:
        pixel = tuple(_vector(doc["pixel"], 2, at["pixel"]).tolist())
    if doc.get("viewport") is not None:
        viewport = tuple(_vector(doc["viewport"], 2, at["viewport"]).tolist())
    if doc.get("model_matrix") is not None:
        mm = _vector(doc["model_matrix"], 16, at["model_matrix"])
    auto = doc.get("auto")
    if auto is not None and not isinstance(auto, bool):
        raise InputError(f"expected true (matched automatically) or false (clicked), got "
                         f"{_describe(auto)}", field=join_field(field, "auto"))
    score = None if doc.get("score") is None else _number(doc["score"], join_field(field, "score"))
    return Ray(origin, direction, ifov, pixel, viewport, mm, auto, score)


def parse_rays(docs: Sequence[JSON], field: str = "") -> tuple[list[Ray], Rays]:
    """Validate ray objects of the session JSON: their JSON shape here, their ranges once in
    gsgeo.measure.Rays. Errors name ``field`` (the JSON path of the point) and the ray's
    member inside it, e.g. ``rays[1].direction``."""
    rays = [_ray_members(r, join_field(field, f"rays[{i}]")) for i, r in enumerate(docs)]
    try:
        typed = SessionPoint("", rays).to_rays()
    except InputError as exc:
        raise exc.within(field) if field else exc from None
    return rays, typed


def parse_ray(doc: JSON, field: str = "ray") -> Ray:
    """Validate one ray object of the session JSON; errors name ``field`` (the ray's JSON
    path) and the member inside it, e.g. ``ray.direction``; ``field=""`` names members alone."""
    ray = _ray_members(doc, field)
    try:
        SessionPoint("", [ray]).to_rays()
    except InputError as exc:
        member = (exc.field or "").removeprefix("rays[0]").lstrip(".")
        raise exc.at(join_field(field, member) if member else field or None) from None
    return ray


def parse_point(doc: JSON, field: str = "point") -> SessionPoint:
    """Validate one point object (id, code, description, rays); errors name ``field`` (the
    point's JSON path) and the member inside it; ``field=""`` names members alone (``rays[1]``)."""
    if not isinstance(doc, dict):
        raise InputError("expected an object with id and rays", field=field)
    if "id" not in doc:
        raise InputError("missing 'id'", field=field)
    pid = limits.id_text(doc["id"], join_field(field, "id"))
    rays = doc.get("rays")
    if not isinstance(rays, list):
        raise InputError(f"expected a list of rays, got {_describe(rays)}",
                         field=join_field(field, "rays"))
    parsed, typed = parse_rays(rays, field)
    return SessionPoint(
        id=pid,
        rays=parsed,
        code=_text(doc.get("code"), join_field(field, "code")),
        description=_text(doc.get("description"), join_field(field, "description")),
        typed=typed,
    )


def _features(doc: JSON, key: str) -> list[Feature]:
    items = doc.get(key)
    if items is None:
        return []
    if not isinstance(items, list):
        raise InputError(f"expected a list, got {_describe(items)}", field=key)
    out = []
    for i, item in enumerate(items):
        at = f"{key}[{i}]"
        if not isinstance(item, dict) or "id" not in item:
            raise InputError("expected an object with id and points", field=at)
        pts = item.get("points")
        if not isinstance(pts, list) or not pts:
            raise InputError("expected a list of point ids", field=f"{at}.points")
        out.append(Feature(limits.id_text(item["id"], f"{at}.id"),
                           [limits.id_text(p, f"{at}.points[{j}]") for j, p in enumerate(pts)]))
    return out


def _buildings(doc: JSONObject) -> list[BuildingSpec]:
    """The session's buildings (gsgeo.buildings.spec.parse_building each), ids unique."""
    items = doc.get("buildings")
    if items is None:
        return []
    if not isinstance(items, list):
        raise InputError(f"expected a list of buildings, got {_describe(items)}",
                         field="buildings")
    out = [parse_building(item, f"buildings[{i}]") for i, item in enumerate(items)]
    seen: set[str] = set()
    for i, b in enumerate(out):
        if b.id in seen:
            raise InputError(f"duplicate building id '{b.id}'", field=f"buildings[{i}].id")
        seen.add(b.id)
    return out


def parse_session(doc: JSON) -> Session:
    """Validate a decoded session document."""
    if not isinstance(doc, dict):
        raise InputError("the session must be a JSON object with a 'points' list")
    pts = doc.get("points")
    if not isinstance(pts, list):
        raise InputError("expected a list of points"
                         + ("" if pts is None else f", got {_describe(pts)}"), field="points")
    points = [parse_point(p, f"points[{i}]") for i, p in enumerate(pts)]
    seen: set[str] = set()
    for i, p in enumerate(points):
        if p.id in seen:
            raise InputError(f"duplicate point id '{p.id}'", field=f"points[{i}].id")
        seen.add(p.id)
    sigma_px = 1.0
    if doc.get("sigma_px") is not None:
        sigma_px = limits.sigma_px(_number(doc["sigma_px"], "sigma_px"))
    return Session(
        points=points,
        source_crs=_text(doc.get("source_crs"), "source_crs", "EPSG:4978") or "EPSG:4978",
        crs=_text(doc.get("crs"), "crs") or None,
        vertical=_text(doc.get("vertical"), "vertical") or None,
        sigma_px=sigma_px,
        lines=_features(doc, "lines"),
        polygons=_features(doc, "polygons"),
        buildings=_buildings(doc),
    )


def measure_session_point(
    point: SessionPoint,
    *,
    crs: str | None,
    vertical: str | None = None,
    geoid: str | Path | None = None,
    source_crs: str = "EPSG:4978",
    sigma_px: float = 1.0,
    exclude: Sequence[int] = (),
) -> Measurement:
    """gsgeo.measure.measure_point of a session point (its typed rays and these settings)."""
    return measure_rays(point.to_rays(),
                        SolveSettings(crs=crs, vertical=vertical, geoid=geoid,
                                      source_crs=source_crs or "EPSG:4978", sigma_px=sigma_px),
                        point_id=point.id, code=point.code, description=point.description,
                        exclude=exclude)


def measure_session(
    session: Session,
    *,
    crs: str | None = None,
    vertical: str | None = None,
    geoid: str | Path | None = None,
    source_crs: str | None = None,
    sigma_px: float | None = None,
) -> list[Measurement | MeasurementFailure]:
    """Measure every point of a session (gsgeo.measure.measure_points); overrides fall back to
    the session's values."""
    settings = SolveSettings.parse(
        crs=crs if crs is not None else session.crs,
        vertical=vertical if vertical is not None else session.vertical, geoid=geoid,
        source_crs=source_crs or session.source_crs,
        sigma_px=sigma_px if sigma_px is not None else session.sigma_px)
    return measure_points([(p.id, p.code, p.description, p.to_rays()) for p in session.points],
                          settings)
