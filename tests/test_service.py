"""gsgeo.service over gsgeo.store: one stored copy of a point's result, an old store read
after the migration, and a ray parsed and checked once from POST .../points to the record."""

from __future__ import annotations

import json
import sqlite3
import warnings

import pytest
from servertools import london_rays

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

import gsgeo.limits
from gsgeo.pointschema import RECORD_KEYS, record_of
from gsgeo.server.app import ServerConfig, create_app
from gsgeo.service import Projects, open_store
from gsgeo.store import DB_NAME
from gsgeo.store.migrations import MIGRATIONS, SCHEMA_VERSION


@pytest.fixture
def svc(tmp_path):
    s = open_store(tmp_path)
    yield Projects(s, tmp_path)
    s.close()


def columns(path) -> set[str]:
    con = sqlite3.connect(path)
    try:
        return {r[1] for r in con.execute("PRAGMA table_info(points)")}
    finally:
        con.close()


def test_a_rename_changes_the_one_stored_copy(svc, tmp_path):
    p = svc.create_project(name="London", crs="EPSG:32630")
    svc.add_point(p.id, {"id": "A", "rays": london_rays(3), "code": "kerb"})
    pt = svc.update_point(p.id, "A", {"id": "B", "code": "wall"})
    assert "record" not in columns(tmp_path / DB_NAME)
    got = svc.get_point(p.id, "B")
    assert got.result["point_id"] == "B" and got.result["code"] == "wall"
    assert got.record == record_of(got.result) == pt.record
    assert list(got.record) == list(RECORD_KEYS) and got.record["point_id"] == "B"


def test_a_store_of_the_old_schema_is_migrated_and_its_points_read(tmp_path):
    con = sqlite3.connect(tmp_path / DB_NAME)
    con.executescript(MIGRATIONS[0])
    con.execute("PRAGMA user_version = 1")
    result = {k: None for k in RECORD_KEYS} | {"point_id": "A", "easting": 1.5, "rays": []}
    con.execute("INSERT INTO projects (id, name, created_at, updated_at) VALUES "
                "('p1', 'One', 't', 't')")
    con.execute("INSERT INTO points (project_id, id, seq, rays, result, record, solved_rev, "
                "created_at, updated_at) VALUES ('p1', 'A', 1, ?, ?, ?, 0, 't', 't')",
                (json.dumps(london_rays(2)), json.dumps(result), json.dumps(record_of(result))))
    con.commit()
    con.close()
    s = open_store(tmp_path)
    try:
        assert s.schema_version == SCHEMA_VERSION
        assert s.check_integrity() == []
        (pt,) = Projects(s, tmp_path).list_points("p1")
    finally:
        s.close()
    assert pt.result == result and pt.record["easting"] == 1.5 and pt.rays == london_rays(2)
    assert "record" not in columns(tmp_path / DB_NAME)


def test_post_point_checks_each_ray_once_and_stores_it_as_given(tmp_path, monkeypatch):
    calls = []
    real = gsgeo.limits.direction_problem

    def counting(d):
        calls.append(1)
        return real(d)

    monkeypatch.setattr(gsgeo.limits, "direction_problem", counting)
    rays = london_rays(3, ifov=1e-3)
    rays[0] |= {"pixel": [10.0, 20.5], "viewport": [800.0, 600.0],
                "model_matrix": [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]}
    app = create_app(ServerConfig(data_dir=tmp_path / "data", allowed_hosts={"testserver"}))
    with TestClient(app) as c:
        assert c.post("/api/projects", json={"name": "L", "id": "l",
                                             "crs": "EPSG:32630"}).status_code == 201
        calls.clear()  # the warm-up solve
        r = c.post("/api/projects/l/points", json={"id": "A", "rays": rays})
        assert r.status_code == 201, r.text
        assert len(calls) == 3  # once per ray, not once per layer
        # stored as given, but for the identity modelMatrix: the same as none, not stored
        # (every ray of a georeferenced scene carries it; reading it back costs, issue 16)
        as_stored = [dict(r) for r in rays]
        del as_stored[0]["model_matrix"]
        assert c.get("/api/projects/l/points/A").json()["rays"] == as_stored
        bad = london_rays(3)
        bad[1]["direction"] = [0, 0, 0]
        r = c.post("/api/projects/l/points", json={"rays": bad})
        assert r.status_code == 422 and r.json()["field"] == "rays[1].direction"
