"""SQLite schema, as numbered migrations (the schema version is ``PRAGMA user_version``).

Append a migration to change the schema; never edit one that has shipped. Each migration
runs in its own transaction together with the bump of ``user_version``.
"""

from __future__ import annotations

MIGRATIONS: list[str] = [
    # 1: projects, points (rays as session-JSON, results as JSON), lines/polygons, check points
    """
    CREATE TABLE projects (
        id TEXT PRIMARY KEY,
        name TEXT NOT NULL,
        description TEXT NOT NULL DEFAULT '',
        scene TEXT,
        crs TEXT,
        vertical TEXT,
        geoid TEXT,
        source_crs TEXT NOT NULL DEFAULT 'EPSG:4978',
        sigma_px REAL NOT NULL DEFAULT 1.0 CHECK (sigma_px > 0),
        settings_rev INTEGER NOT NULL DEFAULT 0,
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL
    );
    CREATE TABLE points (
        project_id TEXT NOT NULL REFERENCES projects(id) ON DELETE CASCADE,
        id TEXT NOT NULL,
        seq INTEGER NOT NULL,
        code TEXT NOT NULL DEFAULT '',
        description TEXT NOT NULL DEFAULT '',
        rays TEXT NOT NULL CHECK (json_valid(rays) AND json_array_length(rays) >= 2),
        excluded TEXT NOT NULL DEFAULT '[]' CHECK (json_valid(excluded)),
        result TEXT CHECK (result IS NULL OR json_valid(result)),
        record TEXT CHECK (record IS NULL OR json_valid(record)),
        error TEXT,
        solved_rev INTEGER NOT NULL DEFAULT -1,
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL,
        PRIMARY KEY (project_id, id),
        CHECK ((result IS NULL) = (record IS NULL)),
        CHECK (result IS NOT NULL OR error IS NOT NULL)
    );
    CREATE INDEX points_seq ON points(project_id, seq);
    CREATE TABLE features (
        project_id TEXT NOT NULL REFERENCES projects(id) ON DELETE CASCADE,
        kind TEXT NOT NULL CHECK (kind IN ('line', 'polygon')),
        id TEXT NOT NULL,
        seq INTEGER NOT NULL,
        point_ids TEXT NOT NULL CHECK (json_valid(point_ids)),
        code TEXT NOT NULL DEFAULT '',
        description TEXT NOT NULL DEFAULT '',
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL,
        PRIMARY KEY (project_id, kind, id)
    );
    CREATE TABLE check_points (
        project_id TEXT NOT NULL REFERENCES projects(id) ON DELETE CASCADE,
        id TEXT NOT NULL,
        x REAL NOT NULL,
        y REAL NOT NULL,
        z REAL,
        crs TEXT NOT NULL,
        role TEXT NOT NULL DEFAULT 'check' CHECK (role IN ('check', 'control')),
        source TEXT NOT NULL DEFAULT '',
        created_at TEXT NOT NULL,
        PRIMARY KEY (project_id, id)
    );
    """,
    # 2: one record per point: the point-schema row is derived from `result` when read (it
    # was a second copy a rename had to keep in step); the table is rebuilt without `record`
    # because its CHECK constraints name the column
    """
    CREATE TABLE points_v2 (
        project_id TEXT NOT NULL REFERENCES projects(id) ON DELETE CASCADE,
        id TEXT NOT NULL,
        seq INTEGER NOT NULL,
        code TEXT NOT NULL DEFAULT '',
        description TEXT NOT NULL DEFAULT '',
        rays TEXT NOT NULL CHECK (json_valid(rays) AND json_array_length(rays) >= 2),
        excluded TEXT NOT NULL DEFAULT '[]' CHECK (json_valid(excluded)),
        result TEXT CHECK (result IS NULL OR json_valid(result)),
        error TEXT,
        solved_rev INTEGER NOT NULL DEFAULT -1,
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL,
        PRIMARY KEY (project_id, id),
        CHECK (result IS NOT NULL OR error IS NOT NULL)
    );
    INSERT INTO points_v2 (project_id, id, seq, code, description, rays, excluded, result,
                           error, solved_rev, created_at, updated_at)
        SELECT project_id, id, seq, code, description, rays, excluded, result, error,
               solved_rev, created_at, updated_at FROM points;
    DROP TABLE points;
    ALTER TABLE points_v2 RENAME TO points;
    CREATE INDEX points_seq ON points(project_id, seq);
    """,
    # 3: ray provenance (the scene georeference a point's rays were taken under, JSON
    # {"version", "root_transform"}; NULL: the scene's frame as it was before any change) and
    # the stated precision of control and check points (metres, 1 sigma; NULL: not stated)
    """
    ALTER TABLE points ADD COLUMN frame TEXT CHECK (frame IS NULL OR json_valid(frame));
    ALTER TABLE check_points ADD COLUMN sigma_h REAL CHECK (sigma_h IS NULL OR sigma_h > 0);
    ALTER TABLE check_points ADD COLUMN sigma_v REAL CHECK (sigma_v IS NULL OR sigma_v > 0);
    """,
    # 4: the scene georeference version a project's points were last measured in (NULL: not
    # known), so that a change made without the store (a session's gsgeo georef --apply, a
    # crash between tileset.json and the store) is caught up on the project's next read
    """
    ALTER TABLE projects ADD COLUMN scene_version INTEGER;
    """,
    # 5: LoD2 buildings: the session-JSON form of each (roof faces as point ids, ground,
    # attributes); its model is derived from the points' current results when read, so it
    # follows every re-measure of them and is never stored beside them
    """
    CREATE TABLE buildings (
        project_id TEXT NOT NULL REFERENCES projects(id) ON DELETE CASCADE,
        id TEXT NOT NULL,
        seq INTEGER NOT NULL,
        spec TEXT NOT NULL CHECK (json_valid(spec)),
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL,
        PRIMARY KEY (project_id, id)
    );
    """,
    # 6: optimistic concurrency: each point, line/polygon and building has a version, 1 when
    # inserted and +1 on every update of it (re-measures included); an update names the
    # version it read and changes nothing when the stored one differs (the API's ETag and
    # If-Match). Existing rows start at 1.
    """
    ALTER TABLE points ADD COLUMN version INTEGER NOT NULL DEFAULT 1 CHECK (version >= 1);
    ALTER TABLE features ADD COLUMN version INTEGER NOT NULL DEFAULT 1 CHECK (version >= 1);
    ALTER TABLE buildings ADD COLUMN version INTEGER NOT NULL DEFAULT 1 CHECK (version >= 1);
    """,
    # 7: accounts and the audit trail: users with a role and the SHA-256 of their token (never
    # the token); per project an append-only list of changes (who, when, what, before/after
    # as JSON), kept when the project is deleted; each point names who measured it
    """
    CREATE TABLE users (
        name TEXT PRIMARY KEY,
        role TEXT NOT NULL CHECK (role IN ('admin', 'surveyor', 'viewer')),
        token_hash TEXT NOT NULL UNIQUE,
        created_at TEXT NOT NULL
    );
    CREATE TABLE audit (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        project_id TEXT NOT NULL,
        at TEXT NOT NULL,
        actor TEXT NOT NULL,
        action TEXT NOT NULL,
        kind TEXT NOT NULL,
        item TEXT,
        before TEXT CHECK (before IS NULL OR json_valid(before)),
        after TEXT CHECK (after IS NULL OR json_valid(after))
    );
    CREATE INDEX audit_project ON audit(project_id, seq);
    ALTER TABLE points ADD COLUMN measured_by TEXT;
    """,
    # 8: a check or control point's description as given (what and where the mark is: "PK
    # nail in kerb"), shown where the viewer lists and draws the point
    """
    ALTER TABLE check_points ADD COLUMN description TEXT NOT NULL DEFAULT '';
    """,
]

SCHEMA_VERSION = len(MIGRATIONS)
