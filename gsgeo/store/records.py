"""What a project holds, as plain records a storage backend reads and writes.

Rays are kept exactly as the session-JSON ray dicts (README, "Session JSON"); they are
the source of truth. The solved result of a point (``result``: the JSON of
``Measurement.to_dict()``, ``record``: the point-schema row) is derived data, recomputed from
the rays whenever the project's CRS, vertical datum, source CRS or sigma_px changes.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field

from gsgeo.errors import GsgeoError, InputError
from gsgeo.jsontypes import JSONObject
from gsgeo.pointschema import record_of


class NotFoundError(GsgeoError, LookupError):
    """A project, point, line, polygon, building or check point does not exist (HTTP 404)."""


class ConflictError(InputError):
    """The change clashes with what is stored, e.g. a duplicate id (HTTP 409). ``ids``: the
    stored items it clashes with, when there are such (the API's 409 lists them)."""

    def __init__(self, problem: str = "", *, ids: Collection[str] = (),
                 field: str | None = None, source: str | None = None) -> None:
        super().__init__(problem, field=field, source=source)
        self.ids = list(ids)


class PreconditionFailed(ConflictError):
    """A change made on a stale copy of a point, line, polygon or building: the stored
    ``version`` is not the one the client names (If-Match), or the item changed between
    reading and writing it (HTTP 412). ``current``: the stored version (None: not known)."""

    def __init__(self, problem: str = "", *, current: int | None = None,
                 field: str | None = None, source: str | None = None) -> None:
        super().__init__(problem, field=field, source=source)
        self.current = current


def require_version(what: str, current: int, accepted: Collection[int] | None) -> None:
    """Refuse a change of ``what`` (e.g. "point 'P1'") stored at version ``current`` unless
    ``accepted`` (the versions the client names; None: no condition) holds it."""
    if accepted is None or current in accepted:
        return
    if not accepted:  # e.g. only tags that are not versions of ours
        named = "the version given"
    elif len(accepted) == 1:
        named = f"version {next(iter(accepted))}"
    else:
        named = "any of versions " + ", ".join(map(str, sorted(accepted)))
    raise PreconditionFailed(f"{what} was changed by someone else: it is at version {current}, "
                             f"not {named}; reload it and try again", current=current)


@dataclass
class Project:
    """A measuring project: its scene and the settings its points are solved with.

    ``settings_rev`` counts changes of the solving settings (crs, vertical, geoid,
    source_crs, sigma_px); a point's result is current when its ``solved_rev`` equals it.
    """

    id: str
    name: str
    scene: str | None = None
    crs: str | None = None
    vertical: str | None = None
    geoid: str | None = None
    source_crs: str = "EPSG:4978"
    sigma_px: float = 1.0
    description: str = ""
    settings_rev: int = 0
    created_at: str = ""
    updated_at: str = ""
    # the scene georeference version its points were last measured in (None: not known)
    scene_version: int | None = None

    def settings(self) -> JSONObject:
        """The settings a point is solved with."""
        return {"crs": self.crs, "vertical": self.vertical, "geoid": self.geoid,
                "source_crs": self.source_crs, "sigma_px": self.sigma_px}


@dataclass
class PointRecord:
    """One measured point: its rays (session-JSON dicts), exclusions and solved result."""

    project_id: str
    id: str
    rays: list[JSONObject]
    code: str = ""
    description: str = ""
    excluded: list[int] = field(default_factory=list)  # 0-based ray indices left out
    result: JSONObject | None = None  # Measurement.to_dict(); None when not solved
    # The point-schema row: a view of ``result`` (gsgeo.pointschema.record_of), derived when
    # the record is made and not stored, so a rename changes one copy only.
    record: JSONObject | None = None
    error: str | None = None  # why the point could not be solved with the current settings
    solved_rev: int = -1
    seq: int = 0  # creation order
    created_at: str = ""
    updated_at: str = ""
    # The scene georeference the rays were taken under: {"version": int, "root_transform":
    # 16 numbers column-major}; None: the scene's frame before its first georeference change.
    frame: JSONObject | None = None
    # 1 when inserted, +1 on every update of the stored item (optimistic concurrency: the
    # API's ETag); the store writes it, a caller never sets it
    version: int = 1
    # who measured it (the rays): a user's name, "local" for the operator on loopback; None
    # for points stored before accounts existed
    measured_by: str | None = None

    def __post_init__(self) -> None:
        if self.record is None and self.result is not None:
            self.record = record_of(self.result)


@dataclass
class FeatureRecord:
    """A line or polygon: an ordered list of point ids (kind 'line' or 'polygon')."""

    project_id: str
    kind: str
    id: str
    point_ids: list[str]
    code: str = ""
    description: str = ""
    seq: int = 0
    created_at: str = ""
    updated_at: str = ""
    # 1 when inserted, +1 on every update of the stored item (optimistic concurrency: the
    # API's ETag); the store writes it, a caller never sets it
    version: int = 1


@dataclass
class BuildingRecord:
    """An LoD2 building as given: its session-JSON form (``spec``: id, roofs as rings of point
    ids, ground, attributes, regularise). Its model is derived from the points when read."""

    project_id: str
    id: str
    spec: JSONObject
    seq: int = 0
    created_at: str = ""
    updated_at: str = ""
    # 1 when inserted, +1 on every update of the stored item (optimistic concurrency: the
    # API's ETag); the store writes it, a caller never sets it
    version: int = 1


@dataclass
class CheckPointRecord:
    """Ground truth (role 'check') or control (role 'control') in the CRS it was given in.

    Coordinates are easting/northing/height (or x/y/z, lon/lat/h as the CRS's axis order
    puts them, always x = easting or longitude first); height may be missing.
    """

    project_id: str
    id: str
    x: float
    y: float
    z: float | None
    crs: str
    role: str = "check"
    source: str = ""
    created_at: str = ""
    sigma_h: float | None = None  # stated 1-sigma horizontal precision, metres (None: not stated)
    sigma_v: float | None = None  # stated 1-sigma vertical precision, metres
    description: str = ""  # what and where the mark is ("PK nail in kerb"), as given
