"""The storage interface: what a backend (SQLite today, PostgreSQL/PostGIS later) provides.

All reads and writes happen inside ``store.transaction()``; a backend commits the whole
block or nothing, so a crash, a kill or an exception in the middle never leaves half a
change behind. Write transactions are serialised (SQLite: ``BEGIN IMMEDIATE``), so code
running inside one may read, decide and write without races.

Versions (optimistic concurrency): a point, line/polygon or building is stored with version 1
and every update of it adds one. ``update_point`` / ``update_feature`` / ``update_building``
write only when the stored version is still the record's ``version`` (the one read) and raise
:class:`~gsgeo.store.records.PreconditionFailed` otherwise (naming the stored version); on
success they set the record's ``version`` to the new one. ``update_results`` adds one to each
point it writes, unchecked (a re-measure writes derived state of points it has just read).
"""

from __future__ import annotations

import re
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from datetime import datetime

from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.pointschema import provenance
from gsgeo.store.accountrecords import AuditEntry, UserRecord
from gsgeo.store.records import (
    BuildingRecord,
    CheckPointRecord,
    FeatureRecord,
    PointRecord,
    Project,
)
from gsgeo.store.surfaces import BuildingSurface

#: The measured_at text a time filter compares: an ISO 8601 instant with its time zone (Z or
#: +-HH[:]MM), at most microseconds; any other text (one without a zone above all) names no
#: instant and passes no time filter, in every backend (their SQL uses this same pattern,
#: anchored). ASCII digits only.
INSTANT = (r"[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9]{2}:[0-9]{2}:[0-9]{2}(\.[0-9]{1,6})?"
           r"(Z|[+-][0-9]{2}:?[0-9]{2})")


def instant(text: object) -> datetime | None:
    """The (timezone-aware) instant a measured_at text names, None when it names none
    (see INSTANT)."""
    if not isinstance(text, str) or re.fullmatch(INSTANT, text) is None:
        return None
    try:
        return datetime.fromisoformat(text)
    except ValueError:  # e.g. month 13
        return None


@dataclass(frozen=True)
class PointFilter:
    """Which solved points a page of records holds (every given condition must hold).

    ``code``: equal to it. ``measured_from`` / ``measured_to``: the record's ``measured_at``
    (UTC) within these instants, both inclusive (timezone-aware datetimes). ``box``: (x key,
    y key, min x, min y, max x, max y) over two record keys, e.g. ("lon", "lat", ...) in
    degrees or ("easting", "northing", ...) in the grid's units; min x > max x wraps around
    (a box over the antimeridian).
    """

    code: str | None = None
    measured_from: datetime | None = None
    measured_to: datetime | None = None
    box: tuple[str, str, float, float, float, float] | None = None

    def matches(self, record: JSONObject) -> bool:
        """Whether a point-schema record passes (the reference the backends' queries follow)."""
        if self.code is not None and record.get("code") != self.code:
            return False
        if self.measured_from is not None or self.measured_to is not None:
            t = instant(record.get("measured_at"))
            if t is None:
                return False
            if (self.measured_from is not None and t < self.measured_from) or \
                    (self.measured_to is not None and t > self.measured_to):
                return False
        if self.box is not None:
            kx, ky, x0, y0, x1, y1 = self.box
            x, y = record.get(kx), record.get(ky)
            if not isinstance(x, (int, float)) or not isinstance(y, (int, float)):
                return False
            inside_x = x0 <= x <= x1 if x0 <= x1 else (x >= x0 or x <= x1)
            if not (inside_x and y0 <= y <= y1):
                return False
        return True


@dataclass(frozen=True)
class PointRow:
    """A solved point as a page of records gives it: id, point-schema record, last change,
    and its provenance (gsgeo.pointschema.PROVENANCE_KEYS: who measured it, its rays
    clicked and matched automatically)."""

    id: str
    record: JSONObject
    updated_at: str
    provenance: JSONObject = field(default_factory=dict)


def result_values(points: Iterable[PointRecord], now: str
                  ) -> Iterator[tuple[JSON, str | None, int, JSON, str, str]]:
    """What ``Transaction.update_results`` writes, one point at a time as ``points`` come:
    (result, error, solved_rev, frame, project_id, id) with the result and frame as JSON
    values (None where absent). Each record's ``updated_at`` becomes ``now`` and its
    ``version`` goes up by one (a new result is a new version of the point)."""
    for p in points:
        p.updated_at = now
        p.version += 1
        yield p.result, p.error, p.solved_rev, p.frame, p.project_id, p.id


def result_rows(points: Iterable[PointRecord], now: str, dumps: Callable[[JSON], str]
                ) -> Iterator[tuple[object, ...]]:
    """:func:`result_values` as a backend's executemany pulls them: (result, error,
    solved_rev, frame, updated_at, project_id, id), texts made with ``dumps``; a frame record
    shared by many points is encoded once."""
    frames: dict[int, tuple[JSON, str]] = {}  # id(frame) -> (frame, its text)
    for result, error, solved_rev, frame, pid, point_id in result_values(points, now):
        text = None
        if frame is not None:
            got = frames.get(id(frame))
            if got is None or got[0] is not frame:
                got = frames[id(frame)] = (frame, dumps(frame))
            text = got[1]
        yield (None if result is None else dumps(result), error, solved_rev, text,
               now, pid, point_id)


class Transaction(ABC):
    """One atomic unit of work on the store."""

    # projects
    @abstractmethod
    def list_projects(self) -> list[Project]: ...
    @abstractmethod
    def get_project(self, pid: str) -> Project | None: ...
    @abstractmethod
    def insert_project(self, project: Project) -> None: ...
    @abstractmethod
    def update_project(self, project: Project) -> None: ...
    @abstractmethod
    def delete_project(self, pid: str) -> bool: ...

    # points
    @abstractmethod
    def list_points(self, pid: str, results: bool = True) -> list[PointRecord]:
        """The project's points in creation order; ``results=False`` leaves their stored
        results unread (None), for callers that are about to measure them again."""
    @abstractmethod
    def get_point(self, pid: str, point_id: str) -> PointRecord | None: ...
    @abstractmethod
    def point_ids(self, pid: str) -> list[str]: ...
    @abstractmethod
    def insert_point(self, point: PointRecord) -> None: ...
    @abstractmethod
    def update_point(self, point: PointRecord, old_id: str | None = None) -> None:
        """Write ``point`` if its stored version is ``point.version`` (else PreconditionFailed);
        ``old_id`` is its previous id when it is being renamed."""
    def update_results(self, points: Iterable[PointRecord]) -> None:
        """Write the measured state (result, error, solved_rev, frame) of many points at once,
        e.g. after a re-measure; their other fields are as stored, their versions go up by one
        each (unchecked). Backends may do it in bulk;
        ``points`` is consumed once, in order (a generator may make each result as it goes)."""
        for pt in points:
            self.update_point(pt)

    @abstractmethod
    def delete_point(self, pid: str, point_id: str) -> bool: ...

    def count_point_records(self, pid: str, where: PointFilter | None = None) -> int:
        """How many solved points (those with a result) of the project pass ``where``.

        This default reads every point; a backend answers it from an index instead."""
        f = where or PointFilter()
        return sum(1 for p in self.list_points(pid) if p.record is not None and f.matches(p.record))

    def page_point_records(self, pid: str, where: PointFilter | None = None, offset: int = 0,
                           limit: int | None = None) -> list[PointRow]:
        """One page of the solved points passing ``where``, in creation order: ``offset``
        rows skipped, at most ``limit`` (None: all) returned, each with its record only
        (not the whole stored result) and its provenance. This default reads every point; a backend reads only
        the page."""
        f = where or PointFilter()
        rows = [PointRow(p.id, p.record, p.updated_at, provenance(p.rays, p.measured_by))
                for p in self.list_points(pid)
                if p.record is not None and f.matches(p.record)]
        return rows[offset:] if limit is None else rows[offset:offset + limit]

    # lines and polygons
    @abstractmethod
    def list_features(self, pid: str, kind: str) -> list[FeatureRecord]: ...
    @abstractmethod
    def get_feature(self, pid: str, kind: str, fid: str) -> FeatureRecord | None: ...
    @abstractmethod
    def insert_feature(self, feature: FeatureRecord) -> None: ...
    @abstractmethod
    def update_feature(self, feature: FeatureRecord, old_id: str | None = None) -> None:
        """Write ``feature`` if its stored version is ``feature.version`` (as update_point)."""
    @abstractmethod
    def delete_feature(self, pid: str, kind: str, fid: str) -> bool: ...

    # buildings
    @abstractmethod
    def list_buildings(self, pid: str) -> list[BuildingRecord]:
        """The project's buildings in creation order."""
    @abstractmethod
    def get_building(self, pid: str, bid: str) -> BuildingRecord | None: ...
    @abstractmethod
    def insert_building(self, building: BuildingRecord) -> None: ...
    @abstractmethod
    def update_building(self, building: BuildingRecord, old_id: str | None = None) -> None:
        """Write ``building`` if its stored version is ``building.version`` (as update_point);
        ``old_id`` is its previous id when it is being renamed."""
    @abstractmethod
    def delete_building(self, pid: str, bid: str) -> bool: ...

    def keeps_building_surfaces(self) -> bool:
        """Whether this store keeps the surfaces of built buildings for GIS clients (then the
        service calls :meth:`set_building_surfaces` whenever a building's model may change)."""
        return False

    def set_building_surfaces(self, pid: str, bid: str,
                              surfaces: Sequence[BuildingSurface]) -> None:
        """Replace the kept surfaces of building ``bid`` (none: it cannot be built now). They
        go with the building when it is deleted and follow it when it is renamed. A store that
        keeps none ignores this."""
        return None

    def buildings_without_surfaces(self) -> list[tuple[str, str]]:
        """(project id, building id) of every building of which no surface is kept (one
        stored by a gsgeo that kept none, or one that cannot be built); empty where the
        store keeps none."""
        return []

    # check points
    @abstractmethod
    def list_check_points(self, pid: str) -> list[CheckPointRecord]: ...
    @abstractmethod
    def upsert_check_points(self, records: list[CheckPointRecord]) -> None: ...
    @abstractmethod
    def delete_check_point(self, pid: str, cid: str) -> bool: ...
    @abstractmethod
    def delete_all_check_points(self, pid: str) -> int: ...

    # users (accounts) -----------------------------------------------------------------
    @abstractmethod
    def list_users(self) -> list[UserRecord]:
        """Every user, by name."""
    @abstractmethod
    def insert_user(self, user: UserRecord) -> None:
        """Store a new user (ConflictError when the name is taken); sets ``created_at``."""
    @abstractmethod
    def delete_user(self, name: str) -> bool: ...
    @abstractmethod
    def user_by_token_hash(self, token_hash: str) -> UserRecord | None:
        """The user whose token has this hash (hex SHA-256), if any."""

    # the audit trail (append-only: nothing updates or deletes an entry) ---------------
    @abstractmethod
    def append_audit(self, entry: AuditEntry) -> None:
        """Append ``entry``; sets its ``at`` (UTC now) and ``seq``."""
    @abstractmethod
    def list_audit(self, pid: str, item: str | None = None, offset: int = 0,
                   limit: int | None = None, newest_first: bool = True) -> list[AuditEntry]:
        """A page of the project's entries (only those of ``item`` when given), newest first
        or oldest first."""
    @abstractmethod
    def count_audit(self, pid: str, item: str | None = None) -> dict[str, int]:
        """How many entries the project has (of ``item`` when given), per action."""


class Store(ABC):
    """A place where projects live."""

    @abstractmethod
    def transaction(self, write: bool = True) -> AbstractContextManager[Transaction]:
        """Context manager: the block's reads and writes commit together or not at all."""

    @abstractmethod
    def close(self) -> None: ...

    def revision(self) -> int | None:
        """A number that changes whenever a change is committed to the store, by this
        process or another; None when the backend cannot tell (callers then cache nothing
        that is derived from stored data)."""
        return None

    @abstractmethod
    def check_integrity(self) -> list[str]:
        """Problems found in the stored data (empty when sound)."""

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


