"""The audit trail: who changed what in a project, when, with the values before and after.

Each change is written by the service method that makes it, in the same transaction, so the
trail holds a change exactly when the change is stored. The acting user is a plain name that
the caller (the HTTP server, per request) sets with :func:`acting_as`; without one it is
"local" (the operator on loopback, or a command run on this machine).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.store import (
    FeatureRecord,
    NotFoundError,
    PointRecord,
    Project,
    Store,
    Transaction,
)
from gsgeo.store.accountrecords import AuditEntry
from gsgeo.store.records import BuildingRecord, CheckPointRecord

#: The actor when none is set.
LOCAL = "local"
ACTOR: ContextVar[str] = ContextVar("gsgeo_actor", default=LOCAL)
#: Record keys a point's audit values keep (its position and quality, not every column).
POINT_KEYS = ("easting", "northing", "height", "sigma_e", "sigma_n", "sigma_h", "n_rays")


@contextmanager
def acting_as(name: str) -> Iterator[None]:
    """Within the block, changes are recorded as made by ``name``."""
    token = ACTOR.set(name)
    try:
        yield
    finally:
        ACTOR.reset(token)


def current_actor() -> str:
    """Who changes are recorded as made by, here and now."""
    return ACTOR.get()


def record(tx: Transaction, pid: str, action: str, kind: str, item: str | None = None,
           before: JSON = None, after: JSON = None) -> None:
    """Append one entry to project ``pid``'s trail, inside ``tx`` (the change's transaction)."""
    tx.append_audit(AuditEntry(project_id=pid, actor=current_actor(), action=action, kind=kind,
                               item=item, before=before, after=after))


def point_values(pt: PointRecord) -> JSONObject:
    """A point as the trail shows it: id, code, description, rays and excluded rays, and its
    solved position (grid units of the project's CRS) and sigmas (metres)."""
    out: JSONObject = {"id": pt.id, "code": pt.code, "description": pt.description,
                       "rays": len(pt.rays), "excluded": list(pt.excluded)}
    if pt.record is not None:
        out.update({k: pt.record.get(k) for k in POINT_KEYS})
    else:
        out["error"] = pt.error
    return out


def feature_values(f: FeatureRecord) -> JSONObject:
    """A line or polygon as the trail shows it."""
    return {"id": f.id, "point_ids": list(f.point_ids), "code": f.code,
            "description": f.description}


def building_values(b: BuildingRecord) -> JSONObject:
    """A building as the trail shows it: its session-JSON form."""
    return dict(b.spec)


def check_point_values(c: CheckPointRecord) -> JSONObject:
    """A check or control point as the trail shows it (coordinates in its own CRS)."""
    return {"id": c.id, "x": c.x, "y": c.y, "z": c.z, "crs": c.crs, "role": c.role,
            "sigma_h": c.sigma_h, "sigma_v": c.sigma_v, "source": c.source}


def project_values(p: Project) -> JSONObject:
    """A project's name, description, scene and solving settings."""
    return {"name": p.name, "description": p.description, "scene": p.scene} | p.settings()


def changed(before: JSONObject, after: JSONObject) -> tuple[JSONObject, JSONObject]:
    """Only the keys whose values differ (the compact before/after of a change)."""
    keys = [k for k in after if before.get(k) != after.get(k)] + \
        [k for k in before if k not in after]
    return {k: before.get(k) for k in keys}, {k: after.get(k) for k in keys}


def entry_json(e: AuditEntry) -> JSONObject:
    """One entry as the API answers it."""
    return {"seq": e.seq, "at": e.at, "user": e.actor, "action": e.action, "kind": e.kind,
            "item": e.item, "before": e.before, "after": e.after}


def audit_page(store: Store, pid: str, *, item: str | None = None, offset: int = 0,
               limit: int = 100, newest_first: bool = True) -> JSONObject:
    """A page of project ``pid``'s trail: ``entries`` (newest first, or oldest first),
    ``total`` and ``counts`` per action (of ``item`` when given)."""
    with store.transaction(write=False) as tx:
        entries = tx.list_audit(pid, item, offset, limit, newest_first)
        counts = tx.count_audit(pid, item)
        # a deleted project's trail stays readable; a project that never was is not found
        if not counts and tx.get_project(pid) is None:
            raise NotFoundError(f"project '{pid}' does not exist")
    return {"entries": [entry_json(e) for e in entries], "total": sum(counts.values()),
            "counts": dict(counts), "offset": offset, "limit": limit}
