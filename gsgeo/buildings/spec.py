"""The JSON form of a building (session files, the HTTP API, the store): parse and write back.

A building is a set of roof faces, each an ordered ring of measured point ids (not closed: the
first id is not repeated), plus a ground. Faces share point ids along common edges; the
topology of the model comes from these ids only. ``walls`` (optional) are vertical faces the
roof faces cannot express: a step between a lower and a higher roof part, given as a ring of
ids the roofs use (e.g. the lower roof's edge and the eave above it).

``ground`` is one of: a number (the ground height H in the project's height system, CRS
vertical units), a point id (a measured ground point: its H), or an object with exactly one of
``height``, ``point`` or ``dtm`` (the path of a DTM GeoTIFF sampled under the footprint) and an
optional ``sigma`` (1-sigma of the ground height, metres).

Example::

    {"id": "B1", "roofs": [["E1", "E2", "R2", "R1"], ["E3", "E4", "R1", "R2"]],
     "ground": 10.0, "attributes": {"function": "residential"},
     "regularise": ["horizontal_eaves"]}
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from gsgeo.errors import InputError
from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.limits import id_text

#: Optional constraints the adjustment can add.
REGULARISE = ("horizontal_eaves", "rectangular")
#: Attribute names the CityJSON writer fills itself; a user attribute may not take them.
RESERVED_ATTRIBUTES = ("measuredHeight", "roofType", "volume", "footprintArea", "eavesHeight",
                       "ridgeHeight", "groundHeight", "sigmaMeasuredHeight", "sigmaVolume",
                       "sigmaFootprintArea", "sigmaEavesHeight", "sigmaRidgeHeight",
                       "adjustmentSigma0")
#: Largest 1-sigma (m) of a given ground height.
MAX_GROUND_SIGMA_M = 1000.0
KEYS = ("id", "roofs", "walls", "ground", "attributes", "regularise")
GROUND_KEYS = ("height", "point", "dtm", "sigma")

JSONValue = JSON


@dataclass(frozen=True)
class Ground:
    """Where the building stands: exactly one of ``height`` / ``point_id`` / ``dtm`` is set.

    ``height``: H in the project's height system (CRS vertical units); ``point_id``: a measured
    point whose H is the ground; ``dtm``: path of a DTM GeoTIFF sampled under the footprint;
    ``sigma``: optional 1-sigma of the ground height in metres (default 0 for a given height).
    """

    height: float | None = None
    point_id: str | None = None
    dtm: str | None = None
    sigma: float | None = None


@dataclass(frozen=True)
class BuildingSpec:
    """One building as the user describes it (ids only; coordinates come from the points)."""

    id: str
    roofs: tuple[tuple[str, ...], ...]
    ground: Ground
    attributes: dict[str, JSONValue] = field(default_factory=dict)
    regularise: tuple[str, ...] = ()
    walls: tuple[tuple[str, ...], ...] = ()


class _Problems:
    """Collects every problem of a document, then raises one InputError naming them all."""

    def __init__(self, where: str) -> None:
        self.where = where
        self.items: list[tuple[str, str]] = []

    def add(self, fld: str, problem: str) -> None:
        self.items.append((fld, problem))

    def raise_if_any(self) -> None:
        if not self.items:
            return
        if len(self.items) == 1:
            fld, problem = self.items[0]
            raise InputError(problem, field=fld)
        text = "; ".join(f"{f}: {p}" for f, p in self.items)
        raise InputError(f"{len(self.items)} problems: {text}", field=self.where)


def _field(where: str, name: str) -> str:
    return f"{where}.{name}" if where else name


def _ring_list(value: Any, fld: str, what: str, problems: _Problems,
               min_faces: int) -> tuple[tuple[str, ...], ...]:
    if not isinstance(value, list):
        problems.add(fld, f"expected a list of {what} (each a list of point ids)")
        return ()
    if len(value) < min_faces:
        problems.add(fld, f"expected at least {min_faces} {what}, got none")
        return ()
    rings: list[tuple[str, ...]] = []
    for i, ring in enumerate(value):
        rf = f"{fld}[{i}]"
        if not isinstance(ring, list):
            problems.add(rf, "expected a list of point ids (one face, in order around it)")
            continue
        ids: list[str] = []
        ok = True
        for j, pid in enumerate(ring):
            try:
                ids.append(id_text(pid, f"{rf}[{j}]"))
            except InputError as exc:
                problems.add(exc.field or rf, exc.problem)
                ok = False
        if not ok:
            continue
        if len(ids) < 3:
            problems.add(rf, f"a face needs at least 3 point ids, got {len(ids)}")
            continue
        if ids[0] == ids[-1]:
            problems.add(rf, f"the ring repeats its first point {ids[0]!r} at the end: give "
                             "each corner once (the ring closes by itself)")
            continue
        repeated = [p for k, p in enumerate(ids) if p in ids[:k]]
        if repeated:
            problems.add(rf, f"point {repeated[0]!r} appears more than once in the face")
            continue
        rings.append(tuple(ids))
    return tuple(rings)


def _number(value: Any, fld: str, problems: _Problems, unit: str) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        problems.add(fld, f"expected a number ({unit})")
        return None
    try:
        v = float(value)
    except OverflowError:
        problems.add(fld, f"expected a finite number ({unit})")
        return None
    if not math.isfinite(v):
        problems.add(fld, f"expected a finite number ({unit})")
        return None
    return v


def _ground(value: Any, fld: str, problems: _Problems) -> Ground:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        h = _number(value, fld, problems, "the ground height")
        return Ground(height=h)
    if isinstance(value, str):
        try:
            return Ground(point_id=id_text(value, fld))
        except InputError as exc:
            problems.add(fld, exc.problem)
            return Ground()
    if not isinstance(value, dict):
        problems.add(fld, "expected a height (number), a ground point id (text) or an object "
                          "with one of 'height', 'point', 'dtm'")
        return Ground()
    for k in value:
        if k not in GROUND_KEYS:
            problems.add(f"{fld}.{k}", f"unknown key (expected one of {', '.join(GROUND_KEYS)})")
    given = [k for k in ("height", "point", "dtm") if k in value]
    if len(given) != 1:
        problems.add(fld, "give exactly one of 'height', 'point', 'dtm'"
                     + (f" (got {', '.join(given)})" if given else ""))
        return Ground()
    sigma = None
    if "sigma" in value:
        sigma = _number(value["sigma"], f"{fld}.sigma", problems, "metres")
        if sigma is not None and not 0 <= sigma <= MAX_GROUND_SIGMA_M:
            problems.add(f"{fld}.sigma", f"must be between 0 and {MAX_GROUND_SIGMA_M:g} m, "
                                         f"got {sigma:g}")
            sigma = None
    key = given[0]
    if key == "height":
        return Ground(height=_number(value["height"], f"{fld}.height", problems,
                                     "the ground height"), sigma=sigma)
    if key == "point":
        try:
            return Ground(point_id=id_text(value["point"], f"{fld}.point"), sigma=sigma)
        except InputError as exc:
            problems.add(exc.field or fld, exc.problem)
            return Ground()
    dtm = value["dtm"]
    if not isinstance(dtm, str) or not dtm.strip() or "\x00" in dtm:
        problems.add(f"{fld}.dtm", "expected the path of a DTM GeoTIFF (text)")
        return Ground()
    return Ground(dtm=dtm, sigma=sigma)


def parse_building(doc: object, where: str = "building") -> BuildingSpec:
    """The building described by ``doc`` (its JSON form), or InputError naming every problem.

    ``where``: the JSON path of ``doc`` in its document (e.g. ``buildings[2]``); the error's
    field is the path of the faulty value (one problem) or ``where`` (several, all listed).
    """
    problems = _Problems(where)
    if not isinstance(doc, dict):
        raise InputError("expected an object with 'id', 'roofs' and 'ground'", field=where)
    for k in doc:
        if k not in KEYS:
            problems.add(_field(where, str(k)), f"unknown key (expected {', '.join(KEYS)})")
    bid = ""
    if "id" not in doc:
        problems.add(_field(where, "id"), "missing: every building needs an id")
    else:
        try:
            bid = id_text(doc["id"], _field(where, "id"))
        except InputError as exc:
            problems.add(exc.field or _field(where, "id"), exc.problem)
    roofs: tuple[tuple[str, ...], ...] = ()
    if "roofs" not in doc:
        problems.add(_field(where, "roofs"), "missing: a building needs its roof faces")
    else:
        roofs = _ring_list(doc["roofs"], _field(where, "roofs"), "roof faces", problems, 1)
    walls = _ring_list(doc.get("walls", []), _field(where, "walls"), "walls", problems, 0)
    roof_ids = {p for r in roofs for p in r}
    for i, wall in enumerate(walls):
        strangers = [p for p in wall if p not in roof_ids]
        if strangers and roofs:
            problems.add(_field(where, f"walls[{i}]"),
                         f"point {strangers[0]!r} is on no roof face: a wall joins roof edges")
    ground = Ground()
    if "ground" not in doc:
        problems.add(_field(where, "ground"), "missing: give a height, a ground point id or "
                                              "{\"dtm\": PATH}")
    else:
        ground = _ground(doc["ground"], _field(where, "ground"), problems)
    attributes: dict[str, JSONValue] = {}
    raw_attr = doc.get("attributes", {})
    if not isinstance(raw_attr, dict):
        problems.add(_field(where, "attributes"), "expected an object")
    else:
        for k, v in raw_attr.items():
            if k in RESERVED_ATTRIBUTES:
                problems.add(_field(where, f"attributes.{k}"),
                             "is computed by gsgeo; give your own attribute another name")
            else:
                attributes[str(k)] = v
    regularise: list[str] = []
    raw_reg = doc.get("regularise", [])
    if not isinstance(raw_reg, list):
        problems.add(_field(where, "regularise"), f"expected a list of {', '.join(REGULARISE)}")
    else:
        for i, r in enumerate(raw_reg):
            if r not in REGULARISE:
                problems.add(_field(where, f"regularise[{i}]"),
                             f"unknown regularisation {r!r} (expected {' or '.join(REGULARISE)})")
            elif r in regularise:
                problems.add(_field(where, f"regularise[{i}]"), f"{r!r} is given twice")
            else:
                regularise.append(r)
    problems.raise_if_any()
    return BuildingSpec(id=bid, roofs=roofs, ground=ground, attributes=attributes,
                        regularise=tuple(regularise), walls=walls)


def ground_to_json(ground: Ground) -> JSON:
    """The JSON form of ``ground`` (the shortest one that says the same)."""
    if ground.sigma is None:
        if ground.height is not None:
            return ground.height
        if ground.point_id is not None:
            return ground.point_id
    out: JSONObject = {}
    if ground.height is not None:
        out["height"] = ground.height
    elif ground.point_id is not None:
        out["point"] = ground.point_id
    elif ground.dtm is not None:
        out["dtm"] = ground.dtm
    if ground.sigma is not None:
        out["sigma"] = ground.sigma
    return out


def building_to_json(spec: BuildingSpec) -> JSONObject:
    """The JSON form of ``spec``: ``parse_building(building_to_json(s)) == s``."""
    out: JSONObject = {"id": spec.id, "roofs": [list(r) for r in spec.roofs],
                       "ground": ground_to_json(spec.ground)}
    if spec.walls:
        out["walls"] = [list(w) for w in spec.walls]
    if spec.attributes:
        out["attributes"] = dict(spec.attributes)
    if spec.regularise:
        out["regularise"] = list(spec.regularise)
    return out


def point_ids(spec: BuildingSpec) -> list[str]:
    """Every point id the building uses, each once, in order: roofs, walls, the ground point."""
    out: dict[str, None] = {}
    for ring in (*spec.roofs, *spec.walls):
        for p in ring:
            out.setdefault(p)
    if spec.ground.point_id is not None:
        out.setdefault(spec.ground.point_id)
    return list(out)
