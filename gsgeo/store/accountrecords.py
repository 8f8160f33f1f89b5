"""Users (with a role and the hash of their API token) and audit entries, as plain records."""

from __future__ import annotations

from dataclasses import dataclass

from gsgeo.jsontypes import JSON

#: The roles a user may have: ``admin`` (everything), ``surveyor`` (reads and writes
#: projects), ``viewer`` (reads only).
ROLES = ("admin", "surveyor", "viewer")


@dataclass
class UserRecord:
    """A user of the API. ``token_hash``: hex SHA-256 of the user's token (the token itself is
    never stored); ``created_at``: UTC, ISO 8601."""

    name: str
    role: str
    token_hash: str
    created_at: str = ""


@dataclass
class AuditEntry:
    """One change of a project, as the audit trail keeps it (append-only).

    ``actor``: the user's name ("local" for the operator on loopback); ``at``: when (UTC, ISO
    8601, set by the store); ``action``: e.g. "created", "changed", "deleted", "ray excluded",
    "re-solved", "control imported", "georeferenced", "georeference undone"; ``kind``: what
    was changed ("project", "point", "line", "polygon", "building", "check point",
    "settings"); ``item``: its id (None: the project as a whole); ``before`` / ``after``: the
    values before and after (JSON; None where there is none). ``seq``: its place in the
    trail, set by the store."""

    project_id: str
    actor: str
    action: str
    kind: str
    item: str | None = None
    before: JSON = None
    after: JSON = None
    at: str = ""
    seq: int = 0
