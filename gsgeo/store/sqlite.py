"""The embedded store: one SQLite file (WAL journal), schema versioned by migrations.

Durability: WAL with ``synchronous=FULL``, so a committed change survives a kill -9 and a
power cut; a transaction that has not committed leaves no trace. Each thread gets its own
connection; write transactions start with ``BEGIN IMMEDIATE`` so two writers never
interleave (the second waits up to ``busy_timeout``).
"""

from __future__ import annotations

import json
import sqlite3
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from datetime import UTC, datetime, timedelta
from pathlib import Path

import orjson

from gsgeo.errors import GsgeoError
from gsgeo.jsontypes import JSON
from gsgeo.pointschema import RECORD_KEYS
from gsgeo.store.accountrecords import AuditEntry, UserRecord
from gsgeo.store.base import PointFilter, PointRow, Store, Transaction, instant
from gsgeo.store.migrations import MIGRATIONS, SCHEMA_VERSION
from gsgeo.store.records import (
    BuildingRecord,
    CheckPointRecord,
    ConflictError,
    FeatureRecord,
    PointRecord,
    PreconditionFailed,
    Project,
)
from gsgeo.store.sqlitebulk import write_results

#: File name of the store inside the data directory.
DB_NAME = "gsgeo.sqlite"
BUSY_TIMEOUT_MS = 30_000


class StoreError(GsgeoError):
    """The store file cannot be opened or is of an unknown (newer) schema."""


def now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _dumps(value: JSON) -> str:
    """Compact JSON text (orjson: a point's result is written and read on every re-measure).
    Non-finite numbers are written as null (JSON has no NaN; a re-measured result arrives as
    Measurement.to_dict() gives it), numpy values as numbers; integers beyond 64 bits, which
    orjson refuses, go through the standard library."""
    try:
        return orjson.dumps(value, option=orjson.OPT_SERIALIZE_NUMPY).decode()
    except orjson.JSONEncodeError:  # e.g. integers beyond 64 bits: the standard library's
        return json.dumps(value, separators=(",", ":"), allow_nan=False)


def _loads(text: str | None) -> JSON:
    return None if text is None else orjson.loads(text)


#: One json_extract call gives a point's record as a JSON array, in RECORD_KEYS order: the
#: stored result is parsed once, in C, and the rest of it (rays, covariances) never reaches Python.
RECORD_SQL = "json_extract(result, " + ", ".join(f"'$.{k}'" for k in RECORD_KEYS) + ")"
#: How many of a point's rays were matched automatically ("auto": true; gsgeo.pointschema).
AUTO_RAYS_SQL = ("SELECT count(*) FROM json_each(points.rays)"
                 " WHERE json_type(json_each.value, '$.auto') = 'true'")


EPOCH = datetime(1970, 1, 1, tzinfo=UTC)


def micros(t: datetime) -> int:
    """Microseconds since 1970-01-01T00:00Z of a timezone-aware instant (exact)."""
    return (t - EPOCH) // timedelta(microseconds=1)


def instant_micros(text: object) -> int | None:
    """SQL function ``gsgeo_instant``: the instant a measured_at text names
    (gsgeo.store.base.instant, the rule of every backend) in microseconds since 1970, NULL
    when it names none (SQLite's own julianday() would read a text without a zone as UTC)."""
    t = instant(text)
    return None if t is None else micros(t)


def _point_where(pid: str, where: PointFilter | None) -> tuple[str, list[object]]:
    """The WHERE clause (and its arguments) of the solved points of ``pid`` passing ``where``
    (PointFilter.matches, as SQL)."""
    sql = "project_id = ? AND result IS NOT NULL"
    args: list[object] = [pid]
    if where is None:
        return sql, args
    if where.code is not None:
        sql += " AND code = ?"  # the column is kept equal to the result's code
        args.append(where.code)
    when = "gsgeo_instant(json_extract(result, '$.measured_at'))"
    if where.measured_from is not None:
        sql += f" AND {when} >= ?"
        args.append(micros(where.measured_from))
    if where.measured_to is not None:
        sql += f" AND {when} <= ?"
        args.append(micros(where.measured_to))
    if where.box is not None:
        kx, ky, x0, y0, x1, y1 = where.box
        if kx not in RECORD_KEYS or ky not in RECORD_KEYS:
            raise ValueError(f"not point-schema keys: {kx}, {ky}")
        x, y = f"json_extract(result, '$.{kx}')", f"json_extract(result, '$.{ky}')"
        sql += f" AND {y} BETWEEN ? AND ?"
        args += [y0, y1]
        sql += f" AND {x} BETWEEN ? AND ?" if x0 <= x1 else f" AND ({x} >= ? OR {x} <= ?)"
        args += [x0, x1]
    return sql, args


class SQLiteTransaction(Transaction):
    def __init__(self, con: sqlite3.Connection):
        self.con = con

    def _one(self, sql: str, args: tuple = ()) -> sqlite3.Row | None:
        return self.con.execute(sql, args).fetchone()

    def _next_seq(self, sql: str, args: tuple) -> int:
        # COALESCE(MAX(seq), 0) + 1: an aggregate answers exactly one row, even on no rows
        return int(self.con.execute(sql, args).fetchone()[0])

    def _all(self, sql: str, args: tuple = ()) -> list[sqlite3.Row]:
        return self.con.execute(sql, args).fetchall()

    def _stale(self, table: str, where: str, args: tuple, what: str, read: int) -> None:
        """Raise PreconditionFailed for an update that matched no row because the stored
        version is no longer ``read`` (the one the caller read)."""
        row = self._one(f"SELECT version FROM {table} WHERE {where}", args)
        current = None if row is None else int(row[0])
        now = "is deleted" if current is None else f"is at version {current}"
        raise PreconditionFailed(f"{what} changed meanwhile: it {now}, not version {read} "
                                 "as read", current=current)

    def _insert(self, sql: str, args: tuple, what: str) -> None:
        try:
            self.con.execute(sql, args)
        except sqlite3.IntegrityError as exc:
            if "UNIQUE" in str(exc) or "PRIMARY KEY" in str(exc):
                raise ConflictError(f"{what} already exists") from None
            raise

    # projects -------------------------------------------------------------------------
    @staticmethod
    def _project(row: sqlite3.Row) -> Project:
        return Project(id=row["id"], name=row["name"], description=row["description"],
                       scene=row["scene"], crs=row["crs"], vertical=row["vertical"],
                       geoid=row["geoid"], source_crs=row["source_crs"],
                       sigma_px=row["sigma_px"], settings_rev=row["settings_rev"],
                       created_at=row["created_at"], updated_at=row["updated_at"],
                       scene_version=row["scene_version"])

    def list_projects(self) -> list[Project]:
        return [self._project(r) for r in self._all("SELECT * FROM projects ORDER BY created_at, id")]

    def get_project(self, pid: str) -> Project | None:
        row = self._one("SELECT * FROM projects WHERE id = ?", (pid,))
        return None if row is None else self._project(row)

    def insert_project(self, p: Project) -> None:
        p.created_at = p.updated_at = now_iso()
        self._insert(
            "INSERT INTO projects (id, name, description, scene, crs, vertical, geoid, source_crs,"
            " sigma_px, settings_rev, created_at, updated_at, scene_version)"
            " VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (p.id, p.name, p.description, p.scene, p.crs, p.vertical, p.geoid, p.source_crs,
             p.sigma_px, p.settings_rev, p.created_at, p.updated_at, p.scene_version),
            f"project '{p.id}'",
        )

    def update_project(self, p: Project) -> None:
        p.updated_at = now_iso()
        self.con.execute(
            "UPDATE projects SET name=?, description=?, scene=?, crs=?, vertical=?, geoid=?,"
            " source_crs=?, sigma_px=?, settings_rev=?, updated_at=?, scene_version=? WHERE id=?",
            (p.name, p.description, p.scene, p.crs, p.vertical, p.geoid, p.source_crs,
             p.sigma_px, p.settings_rev, p.updated_at, p.scene_version, p.id),
        )

    def delete_project(self, pid: str) -> bool:
        return self.con.execute("DELETE FROM projects WHERE id = ?", (pid,)).rowcount > 0

    # points ---------------------------------------------------------------------------
    @staticmethod
    def _point(row: sqlite3.Row) -> PointRecord:
        return PointRecord(project_id=row["project_id"], id=row["id"], seq=row["seq"],
                           code=row["code"], description=row["description"],
                           rays=orjson.loads(row["rays"]), excluded=orjson.loads(row["excluded"]),
                           result=_loads(row["result"]),
                           error=row["error"], solved_rev=row["solved_rev"],
                           created_at=row["created_at"], updated_at=row["updated_at"],
                           frame=_loads(row["frame"]), version=row["version"],
                           measured_by=row["measured_by"])

    def list_points(self, pid: str, results: bool = True) -> list[PointRecord]:
        # plain tuples in a fixed column order: a re-measure lists every point of a project,
        # and sqlite3.Row's lookups by name were a good part of that
        cur = self.con.cursor()
        cur.row_factory = None
        rows = cur.execute(
            "SELECT project_id, id, seq, code, description, rays, excluded, "
            f"{'result' if results else 'NULL'}, error, solved_rev, created_at, updated_at, "
            "frame, version, measured_by FROM points WHERE project_id = ? ORDER BY seq",
            (pid,)).fetchall()
        frames: dict[str, JSON] = {}  # the points of a scene share few frames: each parsed once
        loads = orjson.loads
        return [PointRecord(project_id=p, id=i, seq=q, code=c, description=d, rays=loads(r),
                            excluded=loads(x), result=None if res is None else loads(res),
                            error=e, solved_rev=sr, created_at=ca, updated_at=ua,
                            frame=None if f is None else (frames[f] if f in frames else
                                                          frames.setdefault(f, loads(f))),
                            version=v, measured_by=mb)
                for (p, i, q, c, d, r, x, res, e, sr, ca, ua, f, v, mb) in rows]

    def count_point_records(self, pid: str, where: PointFilter | None = None) -> int:
        sql, args = _point_where(pid, where)
        return int(self.con.execute(f"SELECT COUNT(*) FROM points WHERE {sql}", args).fetchone()[0])

    def page_point_records(self, pid: str, where: PointFilter | None = None, offset: int = 0,
                           limit: int | None = None) -> list[PointRow]:
        sql, args = _point_where(pid, where)
        rows = self.con.execute(
            f"SELECT id, updated_at, {RECORD_SQL}, measured_by, json_array_length(rays),"
            f" ({AUTO_RAYS_SQL}) FROM points WHERE {sql} ORDER BY seq"
            " LIMIT ? OFFSET ?", [*args, -1 if limit is None else limit, offset]).fetchall()
        keys = RECORD_KEYS
        return [PointRow(r[0], dict(zip(keys, orjson.loads(r[2]), strict=True)), r[1],
                         {"measured_by": r[3], "n_rays_clicked": r[4] - r[5],
                          "n_rays_auto": r[5]})
                for r in rows]

    def get_point(self, pid: str, point_id: str) -> PointRecord | None:
        row = self._one("SELECT * FROM points WHERE project_id = ? AND id = ?", (pid, point_id))
        return None if row is None else self._point(row)

    def point_ids(self, pid: str) -> list[str]:
        rows = self._all("SELECT id FROM points WHERE project_id = ? ORDER BY seq", (pid,))
        return [r[0] for r in rows]

    def insert_point(self, p: PointRecord) -> None:
        p.created_at = p.updated_at = now_iso()
        p.version = 1
        p.seq = self._next_seq("SELECT COALESCE(MAX(seq), 0) + 1 FROM points WHERE project_id = ?",
                               (p.project_id,))
        self._insert(
            "INSERT INTO points (project_id, id, seq, code, description, rays, excluded, result,"
            " error, solved_rev, created_at, updated_at, frame, measured_by)"
            " VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (p.project_id, p.id, p.seq, p.code, p.description, _dumps(p.rays),
             _dumps(p.excluded), None if p.result is None else _dumps(p.result),
             p.error, p.solved_rev,
             p.created_at, p.updated_at, None if p.frame is None else _dumps(p.frame),
             p.measured_by),
            f"point '{p.id}'",
        )

    def update_point(self, p: PointRecord, old_id: str | None = None) -> None:
        p.updated_at = now_iso()
        key = (p.project_id, old_id or p.id)
        try:
            cur = self.con.execute(
                "UPDATE points SET id=?, code=?, description=?, rays=?, excluded=?, result=?,"
                " error=?, solved_rev=?, updated_at=?, frame=?, measured_by=?, version=version+1"
                " WHERE project_id=? AND id=? AND version=?",
                (p.id, p.code, p.description, _dumps(p.rays), _dumps(p.excluded),
                 None if p.result is None else _dumps(p.result),
                 p.error, p.solved_rev,
                 p.updated_at, None if p.frame is None else _dumps(p.frame), p.measured_by,
                 *key, p.version),
            )
        except sqlite3.IntegrityError as exc:
            if "UNIQUE" in str(exc) or "PRIMARY KEY" in str(exc):
                raise ConflictError(f"point '{p.id}' already exists") from None
            raise
        if cur.rowcount == 0:
            self._stale("points", "project_id=? AND id=?", key, f"point '{key[1]}'", p.version)
        p.version += 1

    def update_results(self, points: Iterable[PointRecord]) -> None:
        """In chunks, written on a second thread while the next are made
        (gsgeo.store.sqlitebulk)."""
        write_results(self.con, points, now_iso(), _dumps)

    def delete_point(self, pid: str, point_id: str) -> bool:
        cur = self.con.execute("DELETE FROM points WHERE project_id = ? AND id = ?", (pid, point_id))
        return cur.rowcount > 0

    # lines and polygons ---------------------------------------------------------------
    @staticmethod
    def _feature(row: sqlite3.Row) -> FeatureRecord:
        return FeatureRecord(project_id=row["project_id"], kind=row["kind"], id=row["id"],
                             seq=row["seq"], point_ids=json.loads(row["point_ids"]),
                             code=row["code"], description=row["description"],
                             created_at=row["created_at"], updated_at=row["updated_at"],
                             version=row["version"])

    def list_features(self, pid: str, kind: str) -> list[FeatureRecord]:
        rows = self._all("SELECT * FROM features WHERE project_id = ? AND kind = ? ORDER BY seq",
                         (pid, kind))
        return [self._feature(r) for r in rows]

    def get_feature(self, pid: str, kind: str, fid: str) -> FeatureRecord | None:
        row = self._one("SELECT * FROM features WHERE project_id = ? AND kind = ? AND id = ?",
                        (pid, kind, fid))
        return None if row is None else self._feature(row)

    def insert_feature(self, f: FeatureRecord) -> None:
        f.created_at = f.updated_at = now_iso()
        f.version = 1
        f.seq = self._next_seq("SELECT COALESCE(MAX(seq), 0) + 1 FROM features WHERE project_id = ?"
                               " AND kind = ?", (f.project_id, f.kind))
        self._insert(
            "INSERT INTO features (project_id, kind, id, seq, point_ids, code, description,"
            " created_at, updated_at) VALUES (?,?,?,?,?,?,?,?,?)",
            (f.project_id, f.kind, f.id, f.seq, _dumps(f.point_ids), f.code, f.description,
             f.created_at, f.updated_at),
            f"{f.kind} '{f.id}'",
        )

    def update_feature(self, f: FeatureRecord, old_id: str | None = None) -> None:
        f.updated_at = now_iso()
        key = (f.project_id, f.kind, old_id or f.id)
        try:
            cur = self.con.execute(
                "UPDATE features SET id=?, point_ids=?, code=?, description=?, updated_at=?,"
                " version=version+1 WHERE project_id=? AND kind=? AND id=? AND version=?",
                (f.id, _dumps(f.point_ids), f.code, f.description, f.updated_at,
                 *key, f.version),
            )
        except sqlite3.IntegrityError as exc:
            if "UNIQUE" in str(exc) or "PRIMARY KEY" in str(exc):
                raise ConflictError(f"{f.kind} '{f.id}' already exists") from None
            raise
        if cur.rowcount == 0:
            self._stale("features", "project_id=? AND kind=? AND id=?", key,
                        f"{f.kind} '{key[2]}'", f.version)
        f.version += 1

    def delete_feature(self, pid: str, kind: str, fid: str) -> bool:
        cur = self.con.execute("DELETE FROM features WHERE project_id = ? AND kind = ? AND id = ?",
                               (pid, kind, fid))
        return cur.rowcount > 0

    # buildings ------------------------------------------------------------------------
    @staticmethod
    def _building(row: sqlite3.Row) -> BuildingRecord:
        return BuildingRecord(project_id=row["project_id"], id=row["id"], seq=row["seq"],
                              spec=orjson.loads(row["spec"]), created_at=row["created_at"],
                              updated_at=row["updated_at"], version=row["version"])

    def list_buildings(self, pid: str) -> list[BuildingRecord]:
        rows = self._all("SELECT * FROM buildings WHERE project_id = ? ORDER BY seq", (pid,))
        return [self._building(r) for r in rows]

    def get_building(self, pid: str, bid: str) -> BuildingRecord | None:
        row = self._one("SELECT * FROM buildings WHERE project_id = ? AND id = ?", (pid, bid))
        return None if row is None else self._building(row)

    def insert_building(self, b: BuildingRecord) -> None:
        b.created_at = b.updated_at = now_iso()
        b.version = 1
        b.seq = self._next_seq("SELECT COALESCE(MAX(seq), 0) + 1 FROM buildings"
                               " WHERE project_id = ?", (b.project_id,))
        self._insert(
            "INSERT INTO buildings (project_id, id, seq, spec, created_at, updated_at)"
            " VALUES (?,?,?,?,?,?)",
            (b.project_id, b.id, b.seq, _dumps(b.spec), b.created_at, b.updated_at),
            f"building '{b.id}'",
        )

    def update_building(self, b: BuildingRecord, old_id: str | None = None) -> None:
        b.updated_at = now_iso()
        key = (b.project_id, old_id or b.id)
        try:
            cur = self.con.execute(
                "UPDATE buildings SET id=?, spec=?, updated_at=?, version=version+1"
                " WHERE project_id=? AND id=? AND version=?",
                (b.id, _dumps(b.spec), b.updated_at, *key, b.version))
        except sqlite3.IntegrityError as exc:
            if "UNIQUE" in str(exc) or "PRIMARY KEY" in str(exc):
                raise ConflictError(f"building '{b.id}' already exists") from None
            raise
        if cur.rowcount == 0:
            self._stale("buildings", "project_id=? AND id=?", key, f"building '{key[1]}'",
                        b.version)
        b.version += 1

    def delete_building(self, pid: str, bid: str) -> bool:
        cur = self.con.execute("DELETE FROM buildings WHERE project_id = ? AND id = ?",
                               (pid, bid))
        return cur.rowcount > 0

    # check points ---------------------------------------------------------------------
    def list_check_points(self, pid: str) -> list[CheckPointRecord]:
        rows = self._all("SELECT * FROM check_points WHERE project_id = ? ORDER BY id", (pid,))
        return [CheckPointRecord(project_id=r["project_id"], id=r["id"], x=r["x"], y=r["y"],
                                 z=r["z"], crs=r["crs"], role=r["role"], source=r["source"],
                                 created_at=r["created_at"], sigma_h=r["sigma_h"],
                                 sigma_v=r["sigma_v"], description=r["description"])
                for r in rows]

    def upsert_check_points(self, records: list[CheckPointRecord]) -> None:
        t = now_iso()
        self.con.executemany(
            "INSERT INTO check_points (project_id, id, x, y, z, crs, role, source, created_at,"
            " sigma_h, sigma_v, description) VALUES (?,?,?,?,?,?,?,?,?,?,?,?)"
            " ON CONFLICT (project_id, id)"
            " DO UPDATE SET x=excluded.x, y=excluded.y, z=excluded.z, crs=excluded.crs,"
            " role=excluded.role, source=excluded.source, created_at=excluded.created_at,"
            " sigma_h=excluded.sigma_h, sigma_v=excluded.sigma_v,"
            " description=excluded.description",
            [(c.project_id, c.id, c.x, c.y, c.z, c.crs, c.role, c.source, t, c.sigma_h,
              c.sigma_v, c.description) for c in records],
        )

    def delete_check_point(self, pid: str, cid: str) -> bool:
        cur = self.con.execute("DELETE FROM check_points WHERE project_id = ? AND id = ?", (pid, cid))
        return cur.rowcount > 0

    def delete_all_check_points(self, pid: str) -> int:
        return self.con.execute("DELETE FROM check_points WHERE project_id = ?", (pid,)).rowcount

    # users ----------------------------------------------------------------------------
    @staticmethod
    def _user(r: sqlite3.Row) -> UserRecord:
        return UserRecord(name=r["name"], role=r["role"], token_hash=r["token_hash"],
                          created_at=r["created_at"])

    def list_users(self) -> list[UserRecord]:
        return [self._user(r) for r in self._all("SELECT * FROM users ORDER BY name")]

    def insert_user(self, u: UserRecord) -> None:
        u.created_at = now_iso()
        self._insert("INSERT INTO users (name, role, token_hash, created_at) VALUES (?,?,?,?)",
                     (u.name, u.role, u.token_hash, u.created_at), f"user '{u.name}'")

    def delete_user(self, name: str) -> bool:
        return self.con.execute("DELETE FROM users WHERE name = ?", (name,)).rowcount > 0

    def user_by_token_hash(self, token_hash: str) -> UserRecord | None:
        row = self._one("SELECT * FROM users WHERE token_hash = ?", (token_hash,))
        return None if row is None else self._user(row)

    # the audit trail ------------------------------------------------------------------
    def append_audit(self, e: AuditEntry) -> None:
        e.at = now_iso()
        cur = self.con.execute(
            "INSERT INTO audit (project_id, at, actor, action, kind, item, before, after)"
            " VALUES (?,?,?,?,?,?,?,?)",
            (e.project_id, e.at, e.actor, e.action, e.kind, e.item,
             None if e.before is None else _dumps(e.before),
             None if e.after is None else _dumps(e.after)))
        e.seq = int(cur.lastrowid or 0)

    def list_audit(self, pid: str, item: str | None = None, offset: int = 0,
                   limit: int | None = None, newest_first: bool = True) -> list[AuditEntry]:
        cond, args = ("project_id = ?", [pid]) if item is None else \
            ("project_id = ? AND item = ?", [pid, item])
        order = "DESC" if newest_first else "ASC"
        rows = self._all(f"SELECT * FROM audit WHERE {cond} ORDER BY seq {order} LIMIT ? OFFSET ?",
                         (*args, -1 if limit is None else limit, offset))
        return [AuditEntry(project_id=r["project_id"], actor=r["actor"], action=r["action"],
                           kind=r["kind"], item=r["item"], before=_loads(r["before"]),
                           after=_loads(r["after"]), at=r["at"], seq=r["seq"]) for r in rows]

    def count_audit(self, pid: str, item: str | None = None) -> dict[str, int]:
        cond, args = ("project_id = ?", (pid,)) if item is None else \
            ("project_id = ? AND item = ?", (pid, item))
        rows = self._all(f"SELECT action, COUNT(*) FROM audit WHERE {cond} GROUP BY action"
                         " ORDER BY action", args)
        return {r[0]: int(r[1]) for r in rows}


class SQLiteStore(Store):
    """Projects in one SQLite file.

    ``path`` is the database file (created with its directory when absent).
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StoreError(f"cannot create the data directory: {exc}",
                             source=str(self.path.parent)) from None
        self._local = threading.local()
        self._connections: list[sqlite3.Connection] = []
        self._lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._watch: sqlite3.Connection | None = None  # for revision()
        self._migrate()

    def _connect(self) -> sqlite3.Connection:
        con = getattr(self._local, "con", None)
        if con is not None:
            return con
        try:
            con = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_MS / 1000,
                                  isolation_level=None, check_same_thread=False)
            con.row_factory = sqlite3.Row
            con.create_function("gsgeo_instant", 1, instant_micros, deterministic=True)
            mode = con.execute("PRAGMA journal_mode=WAL").fetchone()[0]
            if mode.lower() != "wal":
                raise StoreError(f"cannot switch to WAL journal mode (got {mode})",
                                 source=str(self.path))
            con.execute("PRAGMA synchronous=FULL")
            con.execute("PRAGMA foreign_keys=ON")
            con.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"cannot open as a gsgeo store: {exc}", source=str(self.path)) from None
        self._local.con = con
        self._local.depth = 0
        with self._lock:
            self._connections.append(con)
        return con

    def _migrate(self) -> None:
        con = self._connect()
        try:
            con.execute("BEGIN IMMEDIATE")
            version = con.execute("PRAGMA user_version").fetchone()[0]
            if version > SCHEMA_VERSION:
                con.execute("ROLLBACK")
                raise StoreError(
                    f"{self.path}: schema version {version} is newer than this gsgeo "
                    f"understands ({SCHEMA_VERSION}); upgrade gsgeo")
            con.execute("COMMIT")
            for v in range(version, SCHEMA_VERSION):
                con.execute("BEGIN IMMEDIATE")
                try:
                    # re-check under the write lock: another process may have migrated
                    if con.execute("PRAGMA user_version").fetchone()[0] != v:
                        con.execute("ROLLBACK")
                        continue
                    for stmt in _statements(MIGRATIONS[v]):
                        con.execute(stmt)
                    con.execute(f"PRAGMA user_version = {v + 1}")
                    con.execute("COMMIT")
                except BaseException:
                    if con.in_transaction:
                        con.execute("ROLLBACK")
                    raise
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"cannot open as a gsgeo store: {exc}", source=str(self.path)) from None

    def revision(self) -> int | None:
        # SQLite's data_version changes when another connection (any thread or process)
        # commits; this connection of its own never writes, so every commit counts.
        with self._lock:
            if self._watch is None:
                try:
                    self._watch = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_MS / 1000,
                                                  isolation_level=None,
                                                  check_same_thread=False)
                except sqlite3.Error:
                    return None
                self._connections.append(self._watch)
            try:
                return int(self._watch.execute("PRAGMA data_version").fetchone()[0])
            except sqlite3.Error:
                return None

    @property
    def schema_version(self) -> int:
        return self._connect().execute("PRAGMA user_version").fetchone()[0]

    @contextmanager
    def transaction(self, write: bool = True) -> Iterator[SQLiteTransaction]:
        con = self._connect()
        if self._local.depth:  # nested: part of the enclosing transaction
            self._local.depth += 1
            try:
                yield SQLiteTransaction(con)
            finally:
                self._local.depth -= 1
            return
        if write:  # queue this process's writers here rather than in SQLite's busy sleeps
            self._write_lock.acquire()
        try:
            con.execute("BEGIN IMMEDIATE" if write else "BEGIN")
            self._local.depth = 1
            try:
                yield SQLiteTransaction(con)
            except BaseException:
                if con.in_transaction:
                    con.execute("ROLLBACK")
                raise
            else:
                con.execute("COMMIT")
            finally:
                self._local.depth = 0
        finally:
            if write:
                self._write_lock.release()

    def check_integrity(self) -> list[str]:
        con = self._connect()
        problems = [r[0] for r in con.execute("PRAGMA integrity_check").fetchall() if r[0] != "ok"]
        problems += [f"foreign key violation in {r[0]} row {r[1]}"
                     for r in con.execute("PRAGMA foreign_key_check").fetchall()]
        return problems

    def close(self) -> None:
        """Close every connection; the store reconnects if it is used again."""
        with self._lock:
            for con in self._connections:
                try:
                    con.close()
                except sqlite3.Error:
                    pass
            self._connections.clear()
            self._watch = None
        self._local = threading.local()


def _statements(script: str) -> list[str]:
    """Split a migration script into statements (no semicolons inside our literals)."""
    return [s.strip() for s in script.split(";") if s.strip()]


def open_store(data_dir: str | Path) -> SQLiteStore:
    """The store of a data directory: ``DATA/gsgeo.sqlite``."""
    return SQLiteStore(Path(data_dir) / DB_NAME)
