"""PostgreSQL schema, as numbered migrations (the version is the one row of
``gsgeo_schema``).

Append a migration to change the schema; never edit one that has shipped. Each migration runs
in one transaction together with the bump of the version, under an advisory lock, so several
servers starting at once migrate once. JSON columns are ``json`` (the text as written, key
order kept, so records read back exactly as from SQLite); queries cast to ``jsonb`` where
they look inside. Times are ISO 8601 text, as in SQLite.
"""

from __future__ import annotations

MIGRATIONS: list[str] = [
    # 1: the schema of SQLite's migrations 1-5 in one step, plus the `version` of every point,
    # line, polygon and building (optimistic concurrency) and a commit counter for revision()
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
        sigma_px DOUBLE PRECISION NOT NULL DEFAULT 1.0 CHECK (sigma_px > 0),
        settings_rev INTEGER NOT NULL DEFAULT 0,
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL,
        scene_version INTEGER
    );
    CREATE TABLE points (
        project_id TEXT NOT NULL REFERENCES projects(id) ON DELETE CASCADE,
        id TEXT NOT NULL,
        seq INTEGER NOT NULL,
        code TEXT NOT NULL DEFAULT '',
        description TEXT NOT NULL DEFAULT '',
        rays JSON NOT NULL CHECK (json_typeof(rays) = 'array' AND json_array_length(rays) >= 2),
        excluded JSON NOT NULL DEFAULT '[]',
        result JSON,
        error TEXT,
        solved_rev INTEGER NOT NULL DEFAULT -1,
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL,
        frame JSON,
        version INTEGER NOT NULL DEFAULT 1,
        PRIMARY KEY (project_id, id),
        CHECK (result IS NOT NULL OR error IS NOT NULL)
    );
    CREATE INDEX points_seq ON points(project_id, seq);
    CREATE TABLE features (
        project_id TEXT NOT NULL REFERENCES projects(id) ON DELETE CASCADE,
        kind TEXT NOT NULL CHECK (kind IN ('line', 'polygon')),
        id TEXT NOT NULL,
        seq INTEGER NOT NULL,
        point_ids JSON NOT NULL,
        code TEXT NOT NULL DEFAULT '',
        description TEXT NOT NULL DEFAULT '',
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL,
        version INTEGER NOT NULL DEFAULT 1,
        PRIMARY KEY (project_id, kind, id)
    );
    CREATE TABLE buildings (
        project_id TEXT NOT NULL REFERENCES projects(id) ON DELETE CASCADE,
        id TEXT NOT NULL,
        seq INTEGER NOT NULL,
        spec JSON NOT NULL,
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL,
        version INTEGER NOT NULL DEFAULT 1,
        PRIMARY KEY (project_id, id)
    );
    CREATE TABLE check_points (
        project_id TEXT NOT NULL REFERENCES projects(id) ON DELETE CASCADE,
        id TEXT NOT NULL,
        x DOUBLE PRECISION NOT NULL,
        y DOUBLE PRECISION NOT NULL,
        z DOUBLE PRECISION,
        crs TEXT NOT NULL,
        role TEXT NOT NULL DEFAULT 'check' CHECK (role IN ('check', 'control')),
        source TEXT NOT NULL DEFAULT '',
        created_at TEXT NOT NULL,
        sigma_h DOUBLE PRECISION CHECK (sigma_h IS NULL OR sigma_h > 0),
        sigma_v DOUBLE PRECISION CHECK (sigma_v IS NULL OR sigma_v > 0),
        PRIMARY KEY (project_id, id)
    );
    CREATE TABLE gsgeo_revision (
        one BOOLEAN PRIMARY KEY DEFAULT TRUE CHECK (one),
        n BIGINT NOT NULL
    );
    INSERT INTO gsgeo_revision (n) VALUES (0);
    """,
    # 2: accounts and the audit trail (as SQLite's migration 7): users with a role and the
    # SHA-256 of their token; per project an append-only list of changes, kept when the
    # project is deleted; each point names who measured it
    """
    CREATE TABLE users (
        name TEXT PRIMARY KEY,
        role TEXT NOT NULL CHECK (role IN ('admin', 'surveyor', 'viewer')),
        token_hash TEXT NOT NULL UNIQUE,
        created_at TEXT NOT NULL
    );
    CREATE TABLE audit (
        seq BIGSERIAL PRIMARY KEY,
        project_id TEXT NOT NULL,
        at TEXT NOT NULL,
        actor TEXT NOT NULL,
        action TEXT NOT NULL,
        kind TEXT NOT NULL,
        item TEXT,
        before JSON,
        after JSON
    );
    CREATE INDEX audit_project ON audit(project_id, seq);
    ALTER TABLE points ADD COLUMN measured_by TEXT;
    """,
    # 3: the surfaces of built buildings, kept for the PostGIS buildings layer (rewritten by
    # the service with every change that can move a building; they go with their building;
    # as WKB, not a geometry column, so that only the typed per-project views are layers),
    # and the version of the per-project views (gsgeo.store.pgviews.VIEWS_VERSION), so that
    # views made by an older gsgeo are made again on start
    """
    CREATE TABLE building_surfaces (
        fid BIGSERIAL PRIMARY KEY,
        project_id TEXT NOT NULL,
        building_id TEXT NOT NULL,
        surface_index INTEGER NOT NULL,
        attrs JSON NOT NULL,
        wkb BYTEA NOT NULL,
        UNIQUE (project_id, building_id, surface_index),
        FOREIGN KEY (project_id, building_id) REFERENCES buildings(project_id, id)
            ON DELETE CASCADE ON UPDATE CASCADE
    );
    ALTER TABLE gsgeo_schema ADD COLUMN views INTEGER NOT NULL DEFAULT 0;
    """,
    # 4: a text read as a timestamptz, NULL where it names none: a text of an instant's form
    # may still be out of range (month 13), and a failed cast would make a whole filter or
    # view fail (callers first check the form, gsgeo.store.base.INSTANT)
    """
    CREATE FUNCTION gsgeo_timestamptz(t TEXT) RETURNS timestamptz
    LANGUAGE plpgsql STABLE AS $$
    BEGIN
        RETURN t::timestamptz;
    EXCEPTION WHEN others THEN
        RETURN NULL;
    END
    $$;
    """,
    # 5: a check or control point's description as given (what and where the mark is)
    """
    ALTER TABLE check_points ADD COLUMN description TEXT NOT NULL DEFAULT '';
    """,
]

SCHEMA_VERSION = len(MIGRATIONS)
