"""The shared store: PostgreSQL (with PostGIS) through psycopg 3 and a connection pool.

Several ``gsgeo serve`` processes, on one host or many, may open one database. Every
transaction is one PostgreSQL transaction. Write transactions first take one advisory lock
(``pg_advisory_xact_lock``), so writers are serialised across processes exactly as SQLite's
``BEGIN IMMEDIATE`` serialises them, and code inside one may read, decide and write without
races; readers take a ``REPEATABLE READ READ ONLY`` snapshot and never wait for a writer (a
re-solve of a whole project does not block them). The schema is created and migrated on open
(gsgeo.store.pgmigrations); each project has PostGIS views for GIS clients
(gsgeo.store.pgviews).
"""

from __future__ import annotations

import json
import re
import threading
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from datetime import UTC
from typing import Any, TypeVar
from urllib.parse import urlsplit

import orjson
import psycopg
import psycopg_pool
from psycopg import sql
from psycopg.rows import dict_row
from psycopg.types.json import set_json_loads

from gsgeo.errors import InputError
from gsgeo.jsontypes import JSON
from gsgeo.pointschema import RECORD_KEYS
from gsgeo.store.accountrecords import AuditEntry, UserRecord
from gsgeo.store.base import INSTANT, PointFilter, PointRow, Store, Transaction, result_rows
from gsgeo.store.pgmigrations import MIGRATIONS, SCHEMA_VERSION
from gsgeo.store.pgviews import VIEWS_VERSION, create_views, drop_views
from gsgeo.store.records import (
    BuildingRecord,
    CheckPointRecord,
    ConflictError,
    FeatureRecord,
    PointRecord,
    PreconditionFailed,
    Project,
)
from gsgeo.store.sqlite import StoreError, now_iso
from gsgeo.store.surfaces import BuildingSurface

#: The advisory lock every write transaction holds (any constant; "gsgeo" in ASCII).
WRITE_LOCK = 0x6773_6765_6F
#: Another one, held while the schema is migrated.
MIGRATE_LOCK = WRITE_LOCK + 1
BEGIN_WRITE = (f"BEGIN ISOLATION LEVEL READ COMMITTED; SELECT pg_advisory_xact_lock({WRITE_LOCK})"
               .encode())
CONNECT_TIMEOUT_S = 10
POOL_SIZE = 16
#: Connections opened at once (a request then rarely waits for the pool to grow).
POOL_MIN = 4
Row = dict[str, Any]
ArgsT = TypeVar("ArgsT", bound=Sequence[object])


#: A NUL character escaped in JSON text (an odd number of backslashes before u0000).
JSON_NUL = re.compile(r"(?<!\\)(\\\\)*\\u0000")
NUL_MESSAGE = "holds a NUL character (U+0000), which the PostgreSQL store cannot keep"


def json_text(value: JSON) -> str:
    """Compact JSON text, as the SQLite store writes it (non-finite numbers as null, numpy
    values as numbers, integers beyond 64 bits through the standard library). A string with
    a NUL character is refused (InputError): PostgreSQL's jsonb, which the views and filters
    read the stored JSON as, cannot hold one."""
    try:
        text = orjson.dumps(value, option=orjson.OPT_SERIALIZE_NUMPY).decode()
    except orjson.JSONEncodeError:
        text = json.dumps(value, separators=(",", ":"), allow_nan=False)
    if "u0000" in text and JSON_NUL.search(text):
        raise InputError(f"a text {NUL_MESSAGE}")
    return text


def nul_free(args: ArgsT) -> ArgsT:
    """``args`` after checking that no text among them holds a NUL character (PostgreSQL
    text cannot; SQL would fail with an internal error): InputError naming it otherwise."""
    for a in args:
        if isinstance(a, str) and "\x00" in a:
            raise InputError(f"{a.replace(chr(0), '<NUL>')[:40]!r} {NUL_MESSAGE}")
    return args


def safe_url(url: str) -> str:
    """The URL without its password, for messages."""
    try:
        u = urlsplit(url)
        if u.password is not None:
            host = u.netloc.rsplit("@", 1)[1]
            return u._replace(netloc=f"{u.username}:***@{host}").geturl()
    except ValueError:
        return "(an unparsable URL)"
    return url


def check_url(url: str) -> None:
    """Raise StoreError unless ``url`` is a ``postgresql://`` URL libpq can read."""
    scheme = url.split("://", 1)[0].lower() if "://" in url else ""
    if scheme not in ("postgresql", "postgres"):
        raise StoreError(f"{safe_url(url)!r} is not a PostgreSQL URL "
                         "(postgresql://USER[:PASSWORD]@HOST:PORT/DATABASE)", field="store")
    try:
        parts = psycopg.conninfo.conninfo_to_dict(url)
    except psycopg.ProgrammingError as exc:
        raise StoreError(f"{safe_url(url)}: not a valid PostgreSQL URL: {exc}",
                         field="store") from None
    if not parts.get("dbname"):
        raise StoreError(f"{safe_url(url)}: the URL names no database (…/DATABASE)",
                         field="store")


def _point_where(pid: str, where: PointFilter | None) -> tuple[sql.Composable, list[object]]:
    """The WHERE clause of the solved points of ``pid`` passing ``where``
    (PointFilter.matches, as SQL over the stored result)."""
    parts: list[sql.Composable] = [sql.SQL("project_id = %s AND result IS NOT NULL")]
    args: list[object] = [pid]
    if where is None:
        return parts[0], args
    if where.code is not None:
        parts.append(sql.SQL("code = %s"))  # the column is kept equal to the result's code
        args.append(where.code)
    when = sql.SQL("(CASE WHEN result->>'measured_at' ~ %s"
                   " THEN gsgeo_timestamptz(result->>'measured_at') END)")
    instant = f"^{INSTANT}$"
    if where.measured_from is not None:
        parts.append(sql.SQL("{} >= %s").format(when))
        args += [instant, where.measured_from.astimezone(UTC)]
    if where.measured_to is not None:
        parts.append(sql.SQL("{} <= %s").format(when))
        args += [instant, where.measured_to.astimezone(UTC)]
    if where.box is not None:
        kx, ky, x0, y0, x1, y1 = where.box
        if kx not in RECORD_KEYS or ky not in RECORD_KEYS:
            raise ValueError(f"not point-schema keys: {kx}, {ky}")

        def num(k: str) -> sql.Composable:
            return sql.SQL("(CASE WHEN json_typeof(result->{k}) = 'number'"
                           " THEN (result->>{k})::float8 END)").format(k=sql.Literal(k))

        parts.append(sql.SQL("{} BETWEEN %s AND %s").format(num(ky)))
        args += [y0, y1]
        parts.append(sql.SQL("{} BETWEEN %s AND %s" if x0 <= x1 else "({x} >= %s OR {x} <= %s)"
                             ).format(num(kx), x=num(kx)))
        args += [x0, x1]
    return sql.SQL(" AND ").join(parts), args


class PostgresTransaction(Transaction):
    def __init__(self, con: psycopg.Connection[Row]):
        self.con = con

    def _one(self, query: str, args: tuple = ()) -> Row | None:
        return self.con.execute(query.encode(), nul_free(args)).fetchone()

    def _all(self, query: str, args: tuple = ()) -> list[Row]:
        return self.con.execute(query.encode(), nul_free(args)).fetchall()

    def _count(self, query: str, args: tuple) -> int:
        cur = self.con.execute(query.encode(), nul_free(args))
        return int(cur.rowcount)

    def _exists(self, table: str, where: str, args: tuple) -> bool:
        return self._one(f"SELECT 1 FROM {table} WHERE {where}", args) is not None

    def _write(self, query: str, args: tuple, what: str) -> int:
        """Run an INSERT/UPDATE; a duplicate key is a ConflictError naming ``what`` (checked
        before writing: writers are serialised, and a failed statement would abort the
        transaction), the number of rows changed otherwise."""
        try:
            return self._count(query, args)
        except psycopg.errors.UniqueViolation:
            raise ConflictError(f"{what} already exists") from None

    def _stale(self, table: str, where: str, args: tuple, what: str, read: int) -> None:
        """Raise PreconditionFailed for an update that matched no row because the stored
        version is no longer ``read``."""
        row = self._one(f"SELECT version FROM {table} WHERE {where}", args)
        current = None if row is None else int(row["version"])
        now = "is deleted" if current is None else f"is at version {current}"
        raise PreconditionFailed(f"{what} changed meanwhile: it {now}, not version {read} "
                                 "as read", current=current)

    # projects -------------------------------------------------------------------------
    @staticmethod
    def _project(row: Row) -> Project:
        return Project(id=row["id"], name=row["name"], description=row["description"],
                       scene=row["scene"], crs=row["crs"], vertical=row["vertical"],
                       geoid=row["geoid"], source_crs=row["source_crs"],
                       sigma_px=row["sigma_px"], settings_rev=row["settings_rev"],
                       created_at=row["created_at"], updated_at=row["updated_at"],
                       scene_version=row["scene_version"])

    def list_projects(self) -> list[Project]:
        return [self._project(r) for r in self._all("SELECT * FROM projects ORDER BY created_at, id")]

    def get_project(self, pid: str) -> Project | None:
        row = self._one("SELECT * FROM projects WHERE id = %s", (pid,))
        return None if row is None else self._project(row)

    def _views(self, statements: list[sql.Composed]) -> None:
        for s in statements:
            self.con.execute(s)

    def insert_project(self, p: Project) -> None:
        if self._exists("projects", "id = %s", (p.id,)):
            raise ConflictError(f"project '{p.id}' already exists")
        p.created_at = p.updated_at = now_iso()
        self._write(
            "INSERT INTO projects (id, name, description, scene, crs, vertical, geoid, source_crs,"
            " sigma_px, settings_rev, created_at, updated_at, scene_version)"
            " VALUES (%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s)",
            (p.id, p.name, p.description, p.scene, p.crs, p.vertical, p.geoid, p.source_crs,
             p.sigma_px, p.settings_rev, p.created_at, p.updated_at, p.scene_version),
            f"project '{p.id}'",
        )
        self._views(create_views(p.id, p.crs))

    def update_project(self, p: Project) -> None:
        old = self._one("SELECT crs FROM projects WHERE id = %s", (p.id,))
        p.updated_at = now_iso()
        self._count(
            "UPDATE projects SET name=%s, description=%s, scene=%s, crs=%s, vertical=%s,"
            " geoid=%s, source_crs=%s, sigma_px=%s, settings_rev=%s, updated_at=%s,"
            " scene_version=%s WHERE id=%s",
            (p.name, p.description, p.scene, p.crs, p.vertical, p.geoid, p.source_crs,
             p.sigma_px, p.settings_rev, p.updated_at, p.scene_version, p.id),
        )
        if old is not None and old["crs"] != p.crs:  # the views' SRID follows the CRS
            self._views(create_views(p.id, p.crs))

    def delete_project(self, pid: str) -> bool:
        self._views(drop_views(pid))
        return self._count("DELETE FROM projects WHERE id = %s", (pid,)) > 0

    # points ---------------------------------------------------------------------------
    @staticmethod
    def _point(row: Row) -> PointRecord:
        return PointRecord(project_id=row["project_id"], id=row["id"], seq=row["seq"],
                           code=row["code"], description=row["description"],
                           rays=row["rays"], excluded=row["excluded"], result=row["result"],
                           error=row["error"], solved_rev=row["solved_rev"],
                           created_at=row["created_at"], updated_at=row["updated_at"],
                           frame=row["frame"], version=row["version"],
                           measured_by=row["measured_by"])

    def list_points(self, pid: str, results: bool = True) -> list[PointRecord]:
        cols = "*" if results else ("project_id, id, seq, code, description, rays, excluded, "
                                    "NULL::json AS result, error, solved_rev, created_at,"
                                    " updated_at, frame, version, measured_by")
        rows = self._all(f"SELECT {cols} FROM points WHERE project_id = %s ORDER BY seq", (pid,))
        return [self._point(r) for r in rows]

    def count_point_records(self, pid: str, where: PointFilter | None = None) -> int:
        cond, args = _point_where(pid, where)
        row = self.con.execute(sql.SQL("SELECT COUNT(*) AS n FROM points WHERE {}").format(cond),
                               nul_free(args)).fetchone()
        return 0 if row is None else int(row["n"])

    def page_point_records(self, pid: str, where: PointFilter | None = None, offset: int = 0,
                           limit: int | None = None) -> list[PointRow]:
        cond, args = _point_where(pid, where)
        # the result as text, parsed here: json keeps its numbers exactly as written
        rows = self.con.execute(
            sql.SQL("SELECT id, updated_at, result::text AS result, measured_by,"
                    " json_array_length(rays) AS n, (SELECT count(*) FROM"
                    " json_array_elements(rays) e WHERE e->>'auto' = 'true') AS auto"
                    " FROM points WHERE {} ORDER BY seq LIMIT %s OFFSET %s").format(cond),
            nul_free([*args, limit, offset])).fetchall()
        out = []
        for r in rows:
            result = orjson.loads(r["result"])
            auto = int(r["auto"])
            out.append(PointRow(r["id"], {k: result.get(k) for k in RECORD_KEYS},
                                r["updated_at"], {"measured_by": r["measured_by"],
                                                  "n_rays_clicked": int(r["n"]) - auto,
                                                  "n_rays_auto": auto}))
        return out

    def get_point(self, pid: str, point_id: str) -> PointRecord | None:
        row = self._one("SELECT * FROM points WHERE project_id = %s AND id = %s", (pid, point_id))
        return None if row is None else self._point(row)

    def point_ids(self, pid: str) -> list[str]:
        rows = self._all("SELECT id FROM points WHERE project_id = %s ORDER BY seq", (pid,))
        return [r["id"] for r in rows]

    def insert_point(self, p: PointRecord) -> None:
        p.created_at = p.updated_at = now_iso()
        p.version = 1
        # one statement (the hot path of every measured point): the next seq (writers are
        # serialised), and no row when the id is taken
        row = self._one(
            "INSERT INTO points (project_id, id, seq, code, description, rays, excluded, result,"
            " error, solved_rev, created_at, updated_at, frame, version, measured_by)"
            " SELECT %s, %s, COALESCE(MAX(seq), 0) + 1, %s, %s, %s, %s, %s, %s, %s, %s, %s, %s,"
            " 1, %s"
            " FROM points WHERE project_id = %s"
            " ON CONFLICT (project_id, id) DO NOTHING RETURNING seq",
            (p.project_id, p.id, p.code, p.description, json_text(p.rays),
             json_text(p.excluded), None if p.result is None else json_text(p.result),
             p.error, p.solved_rev,
             p.created_at, p.updated_at, None if p.frame is None else json_text(p.frame),
             p.measured_by, p.project_id),
        )
        if row is None:
            raise ConflictError(f"point '{p.id}' already exists")
        p.seq = int(row["seq"])

    def update_point(self, p: PointRecord, old_id: str | None = None) -> None:
        key = (p.project_id, old_id or p.id)
        if p.id != key[1] and self._exists("points", "project_id = %s AND id = %s",
                                           (p.project_id, p.id)):
            raise ConflictError(f"point '{p.id}' already exists")
        p.updated_at = now_iso()
        n = self._write(
            "UPDATE points SET id=%s, code=%s, description=%s, rays=%s, excluded=%s, result=%s,"
            " error=%s, solved_rev=%s, updated_at=%s, frame=%s, measured_by=%s,"
            " version=version+1 WHERE project_id=%s AND id=%s AND version=%s",
            (p.id, p.code, p.description, json_text(p.rays), json_text(p.excluded),
             None if p.result is None else json_text(p.result),
             p.error, p.solved_rev,
             p.updated_at, None if p.frame is None else json_text(p.frame), p.measured_by,
             *key, p.version),
            f"point '{p.id}'",
        )
        if n == 0:
            self._stale("points", "project_id=%s AND id=%s", key, f"point '{key[1]}'", p.version)
        p.version += 1

    def update_results(self, points: Iterable[PointRecord]) -> None:
        with self.con.cursor() as cur:
            cur.executemany(
                b"UPDATE points SET result=%s, error=%s, solved_rev=%s, frame=%s, updated_at=%s,"
                b" version=version+1 WHERE project_id=%s AND id=%s",
                (nul_free(row) for row in result_rows(points, now_iso(), json_text)))

    def delete_point(self, pid: str, point_id: str) -> bool:
        return self._count("DELETE FROM points WHERE project_id = %s AND id = %s",
                           (pid, point_id)) > 0

    # lines and polygons ---------------------------------------------------------------
    @staticmethod
    def _feature(row: Row) -> FeatureRecord:
        return FeatureRecord(project_id=row["project_id"], kind=row["kind"], id=row["id"],
                             seq=row["seq"], point_ids=row["point_ids"],
                             code=row["code"], description=row["description"],
                             created_at=row["created_at"], updated_at=row["updated_at"],
                             version=row["version"])

    def list_features(self, pid: str, kind: str) -> list[FeatureRecord]:
        rows = self._all("SELECT * FROM features WHERE project_id = %s AND kind = %s"
                         " ORDER BY seq", (pid, kind))
        return [self._feature(r) for r in rows]

    def get_feature(self, pid: str, kind: str, fid: str) -> FeatureRecord | None:
        row = self._one("SELECT * FROM features WHERE project_id = %s AND kind = %s AND id = %s",
                        (pid, kind, fid))
        return None if row is None else self._feature(row)

    def insert_feature(self, f: FeatureRecord) -> None:
        if self._exists("features", "project_id = %s AND kind = %s AND id = %s",
                        (f.project_id, f.kind, f.id)):
            raise ConflictError(f"{f.kind} '{f.id}' already exists")
        f.created_at = f.updated_at = now_iso()
        f.version = 1
        row = self._one("SELECT COALESCE(MAX(seq), 0) + 1 AS n FROM features"
                        " WHERE project_id = %s AND kind = %s", (f.project_id, f.kind))
        f.seq = 1 if row is None else int(row["n"])
        self._write(
            "INSERT INTO features (project_id, kind, id, seq, point_ids, code, description,"
            " created_at, updated_at, version) VALUES (%s,%s,%s,%s,%s,%s,%s,%s,%s,1)",
            (f.project_id, f.kind, f.id, f.seq, json_text(f.point_ids), f.code, f.description,
             f.created_at, f.updated_at),
            f"{f.kind} '{f.id}'",
        )

    def update_feature(self, f: FeatureRecord, old_id: str | None = None) -> None:
        key = (f.project_id, f.kind, old_id or f.id)
        if f.id != key[2] and self._exists("features", "project_id = %s AND kind = %s AND id = %s",
                                           (f.project_id, f.kind, f.id)):
            raise ConflictError(f"{f.kind} '{f.id}' already exists")
        f.updated_at = now_iso()
        n = self._write(
            "UPDATE features SET id=%s, point_ids=%s, code=%s, description=%s, updated_at=%s,"
            " version=version+1 WHERE project_id=%s AND kind=%s AND id=%s AND version=%s",
            (f.id, json_text(f.point_ids), f.code, f.description, f.updated_at, *key, f.version),
            f"{f.kind} '{f.id}'",
        )
        if n == 0:
            self._stale("features", "project_id=%s AND kind=%s AND id=%s", key,
                        f"{f.kind} '{key[2]}'", f.version)
        f.version += 1

    def delete_feature(self, pid: str, kind: str, fid: str) -> bool:
        return self._count("DELETE FROM features WHERE project_id = %s AND kind = %s AND id = %s",
                           (pid, kind, fid)) > 0

    # buildings ------------------------------------------------------------------------
    @staticmethod
    def _building(row: Row) -> BuildingRecord:
        return BuildingRecord(project_id=row["project_id"], id=row["id"], seq=row["seq"],
                              spec=row["spec"], created_at=row["created_at"],
                              updated_at=row["updated_at"], version=row["version"])

    def list_buildings(self, pid: str) -> list[BuildingRecord]:
        rows = self._all("SELECT * FROM buildings WHERE project_id = %s ORDER BY seq", (pid,))
        return [self._building(r) for r in rows]

    def get_building(self, pid: str, bid: str) -> BuildingRecord | None:
        row = self._one("SELECT * FROM buildings WHERE project_id = %s AND id = %s", (pid, bid))
        return None if row is None else self._building(row)

    def insert_building(self, b: BuildingRecord) -> None:
        if self._exists("buildings", "project_id = %s AND id = %s", (b.project_id, b.id)):
            raise ConflictError(f"building '{b.id}' already exists")
        b.created_at = b.updated_at = now_iso()
        b.version = 1
        row = self._one("SELECT COALESCE(MAX(seq), 0) + 1 AS n FROM buildings"
                        " WHERE project_id = %s", (b.project_id,))
        b.seq = 1 if row is None else int(row["n"])
        self._write(
            "INSERT INTO buildings (project_id, id, seq, spec, created_at, updated_at, version)"
            " VALUES (%s,%s,%s,%s,%s,%s,1)",
            (b.project_id, b.id, b.seq, json_text(b.spec), b.created_at, b.updated_at),
            f"building '{b.id}'",
        )

    def update_building(self, b: BuildingRecord, old_id: str | None = None) -> None:
        key = (b.project_id, old_id or b.id)
        if b.id != key[1] and self._exists("buildings", "project_id = %s AND id = %s",
                                           (b.project_id, b.id)):
            raise ConflictError(f"building '{b.id}' already exists")
        b.updated_at = now_iso()
        n = self._write(
            "UPDATE buildings SET id=%s, spec=%s, updated_at=%s, version=version+1"
            " WHERE project_id=%s AND id=%s AND version=%s",
            (b.id, json_text(b.spec), b.updated_at, *key, b.version), f"building '{b.id}'")
        if n == 0:
            self._stale("buildings", "project_id=%s AND id=%s", key, f"building '{key[1]}'",
                        b.version)
        b.version += 1

    def delete_building(self, pid: str, bid: str) -> bool:
        return self._count("DELETE FROM buildings WHERE project_id = %s AND id = %s",
                           (pid, bid)) > 0

    def keeps_building_surfaces(self) -> bool:
        return True

    def buildings_without_surfaces(self) -> list[tuple[str, str]]:
        rows = self._all("SELECT b.project_id, b.id FROM buildings b WHERE NOT EXISTS"
                         " (SELECT 1 FROM building_surfaces s WHERE s.project_id = b.project_id"
                         " AND s.building_id = b.id) ORDER BY b.project_id, b.seq")
        return [(r["project_id"], r["id"]) for r in rows]

    def set_building_surfaces(self, pid: str, bid: str,
                              surfaces: Sequence[BuildingSurface]) -> None:
        self._count("DELETE FROM building_surfaces WHERE project_id = %s AND building_id = %s",
                    (pid, bid))
        if not surfaces:
            return
        with self.con.cursor() as cur:
            cur.executemany(
                b"INSERT INTO building_surfaces (project_id, building_id, surface_index, attrs,"
                b" wkb) VALUES (%s, %s, %s, %s, ST_AsBinary(ST_GeomFromText(%s)))",
                [nul_free((pid, bid, f.surface_index, json_text(f.values), f.wkt()))
                 for f in surfaces])

    # check points ---------------------------------------------------------------------
    def list_check_points(self, pid: str) -> list[CheckPointRecord]:
        rows = self._all("SELECT * FROM check_points WHERE project_id = %s ORDER BY id", (pid,))
        return [CheckPointRecord(project_id=r["project_id"], id=r["id"], x=r["x"], y=r["y"],
                                 z=r["z"], crs=r["crs"], role=r["role"], source=r["source"],
                                 created_at=r["created_at"], sigma_h=r["sigma_h"],
                                 sigma_v=r["sigma_v"], description=r["description"])
                for r in rows]

    def upsert_check_points(self, records: list[CheckPointRecord]) -> None:
        t = now_iso()
        with self.con.cursor() as cur:
            cur.executemany(
                b"INSERT INTO check_points (project_id, id, x, y, z, crs, role, source,"
                b" created_at, sigma_h, sigma_v, description)"
                b" VALUES (%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s)"
                b" ON CONFLICT (project_id, id) DO UPDATE SET x=excluded.x, y=excluded.y,"
                b" z=excluded.z, crs=excluded.crs, role=excluded.role, source=excluded.source,"
                b" created_at=excluded.created_at, sigma_h=excluded.sigma_h,"
                b" sigma_v=excluded.sigma_v, description=excluded.description",
                [nul_free((c.project_id, c.id, c.x, c.y, c.z, c.crs, c.role, c.source, t,
                           c.sigma_h, c.sigma_v, c.description)) for c in records],
            )

    def delete_check_point(self, pid: str, cid: str) -> bool:
        return self._count("DELETE FROM check_points WHERE project_id = %s AND id = %s",
                           (pid, cid)) > 0

    def delete_all_check_points(self, pid: str) -> int:
        return self._count("DELETE FROM check_points WHERE project_id = %s", (pid,))

    # users ----------------------------------------------------------------------------
    @staticmethod
    def _user(r: Row) -> UserRecord:
        return UserRecord(name=r["name"], role=r["role"], token_hash=r["token_hash"],
                          created_at=r["created_at"])

    def list_users(self) -> list[UserRecord]:
        return [self._user(r) for r in self._all("SELECT * FROM users ORDER BY name")]

    def insert_user(self, u: UserRecord) -> None:
        if self._exists("users", "name = %s", (u.name,)):
            raise ConflictError(f"user '{u.name}' already exists")
        u.created_at = now_iso()
        self._write("INSERT INTO users (name, role, token_hash, created_at)"
                    " VALUES (%s, %s, %s, %s)", (u.name, u.role, u.token_hash, u.created_at),
                    f"user '{u.name}'")

    def delete_user(self, name: str) -> bool:
        return self._count("DELETE FROM users WHERE name = %s", (name,)) > 0

    def user_by_token_hash(self, token_hash: str) -> UserRecord | None:
        row = self._one("SELECT * FROM users WHERE token_hash = %s", (token_hash,))
        return None if row is None else self._user(row)

    # the audit trail ------------------------------------------------------------------
    def append_audit(self, e: AuditEntry) -> None:
        e.at = now_iso()
        row = self._one(
            "INSERT INTO audit (project_id, at, actor, action, kind, item, before, after)"
            " VALUES (%s, %s, %s, %s, %s, %s, %s, %s) RETURNING seq",
            (e.project_id, e.at, e.actor, e.action, e.kind, e.item,
             None if e.before is None else json_text(e.before),
             None if e.after is None else json_text(e.after)))
        e.seq = 0 if row is None else int(row["seq"])

    def list_audit(self, pid: str, item: str | None = None, offset: int = 0,
                   limit: int | None = None, newest_first: bool = True) -> list[AuditEntry]:
        cond, args = ("project_id = %s", [pid]) if item is None else \
            ("project_id = %s AND item = %s", [pid, item])
        order = "DESC" if newest_first else "ASC"
        rows = self._all(f"SELECT * FROM audit WHERE {cond} ORDER BY seq {order}"
                         " LIMIT %s OFFSET %s", (*args, limit, offset))
        return [AuditEntry(project_id=r["project_id"], actor=r["actor"], action=r["action"],
                           kind=r["kind"], item=r["item"], before=r["before"],
                           after=r["after"], at=r["at"], seq=int(r["seq"])) for r in rows]

    def count_audit(self, pid: str, item: str | None = None) -> dict[str, int]:
        cond, args = ("project_id = %s", (pid,)) if item is None else \
            ("project_id = %s AND item = %s", (pid, item))
        rows = self._all(f"SELECT action, COUNT(*) AS n FROM audit WHERE {cond}"
                         " GROUP BY action ORDER BY action", args)
        return {r["action"]: int(r["n"]) for r in rows}


def _configure(con: psycopg.Connection[Any]) -> None:
    set_json_loads(orjson.loads, con)


class PostgresStore(Store):
    """Projects in a PostgreSQL database with PostGIS, given by a libpq URL
    ``postgresql://USER[:PASSWORD]@HOST:PORT/DATABASE``.

    Opening checks the URL, connects (a clear StoreError when the server cannot be reached,
    the login is refused or the database is missing), enables PostGIS (or says that the role
    may not) and migrates the schema.
    """

    def __init__(self, url: str, pool_size: int = POOL_SIZE):
        check_url(url)
        self.url = url
        self._where = safe_url(url)
        self._local = threading.local()
        self._pool_size = pool_size
        self._pool_lock = threading.Lock()
        self._migrate()
        self._current: psycopg_pool.ConnectionPool[psycopg.Connection[Row]] | None = None
        self._pool()  # opened now: a failure is the opener's StoreError

    def _pool(self) -> psycopg_pool.ConnectionPool[psycopg.Connection[Row]]:
        """The connection pool, opened again when the store is used after close()."""
        with self._pool_lock:
            if self._current is None:
                pool: psycopg_pool.ConnectionPool[psycopg.Connection[Row]] = \
                    psycopg_pool.ConnectionPool(
                        self.url, min_size=min(POOL_MIN, self._pool_size),
                        max_size=self._pool_size, open=False,
                        configure=_configure,
                        kwargs={"autocommit": True, "row_factory": dict_row,
                                "connect_timeout": CONNECT_TIMEOUT_S})
                try:
                    pool.open(wait=True, timeout=CONNECT_TIMEOUT_S)
                except psycopg_pool.PoolTimeout as exc:
                    pool.close()
                    raise StoreError(f"{self._where}: cannot open a connection pool: {exc}") \
                        from None
                self._current = pool
            return self._current

    def _connect(self) -> psycopg.Connection[Row]:
        try:
            con = psycopg.connect(self.url, autocommit=True, row_factory=dict_row,
                                  connect_timeout=CONNECT_TIMEOUT_S)
        except psycopg.OperationalError as exc:
            msg = " ".join(str(exc).split())
            raise StoreError(f"cannot connect to PostgreSQL at {self._where}: {msg}") from None
        _configure(con)
        return con

    def _migrate(self) -> None:
        with self._connect() as con:
            try:
                self._enable_postgis(con)
                with con.transaction():
                    con.execute("SELECT pg_advisory_xact_lock(%s)", (MIGRATE_LOCK,))
                    con.execute("CREATE TABLE IF NOT EXISTS gsgeo_schema ("
                                " one BOOLEAN PRIMARY KEY DEFAULT TRUE CHECK (one),"
                                " version INTEGER NOT NULL)")
                    con.execute("INSERT INTO gsgeo_schema (version) VALUES (0)"
                                " ON CONFLICT DO NOTHING")
                row = con.execute("SELECT version FROM gsgeo_schema").fetchone()
                version = 0 if row is None else int(row["version"])
                if version > SCHEMA_VERSION:
                    raise StoreError(
                        f"{self._where}: schema version {version} is newer than this gsgeo "
                        f"understands ({SCHEMA_VERSION}); upgrade gsgeo")
                for v in range(version, SCHEMA_VERSION):
                    with con.transaction():
                        con.execute("SELECT pg_advisory_xact_lock(%s)", (MIGRATE_LOCK,))
                        row = con.execute("SELECT version FROM gsgeo_schema").fetchone()
                        if row is None or int(row["version"]) != v:
                            continue  # another server migrated meanwhile
                        con.execute(MIGRATIONS[v].encode())
                        con.execute("UPDATE gsgeo_schema SET version = %s", (v + 1,))
                self._refresh_views(con)
            except psycopg.Error as exc:
                msg = " ".join(str(exc).split())
                raise StoreError(f"{self._where}: cannot prepare the gsgeo schema: {msg}") \
                    from None

    @staticmethod
    def _refresh_views(con: psycopg.Connection[Row]) -> None:
        """Make every project's views again when the database's were made by an older gsgeo
        (gsgeo.store.pgviews.VIEWS_VERSION), once, under the migration lock."""
        with con.transaction():
            con.execute("SELECT pg_advisory_xact_lock(%s)", (MIGRATE_LOCK,))
            row = con.execute("SELECT views FROM gsgeo_schema").fetchone()
            if row is None or int(row["views"]) >= VIEWS_VERSION:
                return
            for p in con.execute("SELECT id, crs FROM projects ORDER BY id").fetchall():
                for statement in create_views(p["id"], p["crs"]):
                    con.execute(statement)
            con.execute("UPDATE gsgeo_schema SET views = %s", (VIEWS_VERSION,))

    def _enable_postgis(self, con: psycopg.Connection[Row]) -> None:
        if con.execute("SELECT 1 FROM pg_extension WHERE extname = 'postgis'").fetchone():
            return
        try:
            con.execute("CREATE EXTENSION IF NOT EXISTS postgis")
        except psycopg.Error as exc:
            msg = " ".join(str(exc).split())
            raise StoreError(
                f"{self._where}: the database has no PostGIS and this role may not enable it "
                f"({msg}); as a superuser run CREATE EXTENSION postgis in that database "
                "(Debian: apt install postgresql-15-postgis-3)") from None

    @property
    def schema_version(self) -> int:
        with self.transaction(write=False) as tx:
            row = tx.con.execute("SELECT version FROM gsgeo_schema").fetchone()
        return 0 if row is None else int(row["version"])

    def revision(self) -> int | None:
        """The count of committed write transactions (every server's)."""
        try:
            with self._pool().connection() as con:
                row = con.execute("SELECT n FROM gsgeo_revision").fetchone()
        except (psycopg.Error, psycopg_pool.PoolTimeout, StoreError):
            return None
        return None if row is None else int(row["n"])

    @contextmanager
    def transaction(self, write: bool = True) -> Iterator[PostgresTransaction]:
        con: psycopg.Connection[Row] | None = getattr(self._local, "con", None)
        if con is not None:  # nested: part of the enclosing transaction
            yield PostgresTransaction(con)
            return
        pool = self._pool()
        try:
            con = pool.getconn()
        except psycopg_pool.PoolTimeout as exc:
            raise StoreError(f"{self._where}: no connection free ({exc}); try again") from None
        except psycopg.OperationalError as exc:
            raise StoreError(f"{self._where}: {' '.join(str(exc).split())}") from None
        self._local.con = con
        try:
            try:
                # (several statements, no parameters: one round trip)
                con.execute(BEGIN_WRITE if write else b"BEGIN ISOLATION LEVEL REPEATABLE READ"
                                                      b" READ ONLY")
                yield PostgresTransaction(con)
                con.execute(b"UPDATE gsgeo_revision SET n = n + 1; COMMIT" if write
                            else b"COMMIT")
            except BaseException:
                if not con.closed and con.info.transaction_status != \
                        psycopg.pq.TransactionStatus.IDLE:
                    try:
                        con.execute("ROLLBACK")
                    except psycopg.Error:
                        pass
                raise
        except psycopg.OperationalError as exc:
            raise StoreError(f"{self._where}: {' '.join(str(exc).split())}") from None
        finally:
            self._local.con = None
            pool.putconn(con)

    def check_integrity(self) -> list[str]:
        with self.transaction(write=False) as tx:
            rows = tx.con.execute(
                "SELECT f.project_id, f.kind, f.id, e.point_id FROM features f"
                " CROSS JOIN LATERAL json_array_elements_text(f.point_ids) e(point_id)"
                " WHERE NOT EXISTS (SELECT 1 FROM points p WHERE p.project_id = f.project_id"
                " AND p.id = e.point_id)").fetchall()
        return [f"project {r['project_id']}: {r['kind']} {r['id']} names a missing point "
                f"{r['point_id']}" for r in rows]

    def close(self) -> None:
        """Close the pool's connections; the store opens a new pool if it is used again."""
        with self._pool_lock:
            pool, self._current = self._current, None
        if pool is not None:
            pool.close()
