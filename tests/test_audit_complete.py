"""The audit trail is complete: a session import, a building's creation, change and deletion,
check points deleted one by one and all at once (their values kept), a re-measure of the whole
project, each appear exactly once with their before/after values, and a change that changes
nothing leaves no entry and no new version. Through the API, on SQLite and on PostgreSQL."""

from __future__ import annotations

import warnings

import pytest
from building_helpers import CRS, GROUND, ROOFS, house_points
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.server.app import ServerConfig, create_app

HOUSE = {"id": "B1", "roofs": ROOFS, "ground": GROUND, "attributes": {"function": "shed"}}


@pytest.fixture(params=["sqlite", "postgresql"])
def client(request, tmp_path):
    url = None
    if request.param == "postgresql":
        cluster = request.getfixturevalue("pg_cluster")
        url = cluster.url(cluster.new_database())
    app = create_app(ServerConfig(data_dir=tmp_path / "data", allowed_hosts={"testserver"},
                                  store_url=url))
    with TestClient(app) as c:
        assert c.post("/api/projects", json={"name": "h", "id": "h", "crs": CRS}
                      ).status_code == 201
        yield c


def trail(c) -> list[dict]:
    return c.get("/api/projects/h/audit", params={"order": "oldest", "limit": 1000}
                 ).json()["entries"]


def ok(r, status: int = 200) -> dict:
    assert r.status_code == status, r.text
    return r.json() if r.content else {}


def test_every_change_is_listed_once_with_before_and_after(client):
    c = client
    points = house_points()
    ok(c.post("/api/projects/h/session", json={"points": points, "buildings": [HOUSE]}), 201)
    ok(c.patch("/api/projects/h/buildings/B1", json={"attributes": {"function": "barn"}}))
    ok(c.post("/api/projects/h/buildings", json=HOUSE | {"id": "B2"}), 201)
    ok(c.delete("/api/projects/h/buildings/B2"), 204)
    cps = [{"id": "C1", "x": 545400.0, "y": 258100.0, "z": 60.0},
           {"id": "C2", "x": 545410.0, "y": 258100.0, "z": 60.0}]
    ok(c.post("/api/projects/h/checkpoints", json={"crs": CRS, "points": cps}), 201)
    ok(c.post("/api/projects/h/checkpoints", json={"crs": CRS, "overwrite": ["C2"],
                                                   "points": [cps[1] | {"z": 61.0}]}), 201)
    ok(c.delete("/api/projects/h/checkpoints/C1"), 204)
    ok(c.delete("/api/projects/h/checkpoints"))
    ok(c.post("/api/projects/h/resolve"))

    e = trail(c)[1:]  # after the project's creation
    assert [(x["action"], x["kind"], x["item"]) for x in e] == [
        ("imported", "session", None),
        ("changed", "building", "B1"),
        ("created", "building", "B2"),
        ("deleted", "building", "B2"),
        ("check points imported", "check point", None),
        ("check points imported", "check point", None),
        ("deleted", "check point", "C1"),
        ("deleted", "check point", None),
        ("re-solved", "project", None),
    ]
    imported, changed, created, deleted, cp1, cp2, del1, del_all, resolved = e
    assert imported["before"] is None
    assert imported["after"]["points"] == [p["id"] for p in points]
    assert imported["after"]["buildings"] == ["B1"]
    assert changed["before"] == {"attributes": {"function": "shed"}}
    assert changed["after"] == {"attributes": {"function": "barn"}}
    assert created["before"] is None and created["after"]["roofs"] == ROOFS
    assert deleted["before"]["id"] == "B2" and deleted["after"] is None
    assert cp1["before"] is None and cp1["after"]["ids"] == ["C1", "C2"]
    assert cp2["before"]["points"][0]["id"] == "C2" and cp2["before"]["points"][0]["z"] == 60.0
    assert del1["before"]["id"] == "C1" and del1["before"]["x"] == 545400.0
    assert del_all["before"]["count"] == 1 and del_all["before"]["points"][0]["z"] == 61.0
    assert resolved["before"]["settings_rev"] + 1 == resolved["after"]["settings_rev"]
    assert resolved["after"]["remeasured_points"] == len(points)


def test_a_change_that_changes_nothing_is_no_change(client):
    c = client
    r = ok(c.post("/api/projects/h/points", json=house_points()[0] | {"code": "eaves"}), 201)
    pid, v = r["id"], r["version"]
    ok(c.post("/api/projects/h/points", json=house_points()[1]), 201)
    ok(c.post("/api/projects/h/lines", json={"id": "L1", "points": ["E1", "E2"]}), 201)
    n = len(trail(c))
    r = c.patch(f"/api/projects/h/points/{pid}", json={"code": "eaves", "excluded": []})
    assert r.status_code == 200 and r.json()["version"] == v and r.headers["ETag"] == f'"{v}"'
    r = c.patch("/api/projects/h/lines/L1", json={"points": ["E1", "E2"]})
    assert r.status_code == 200 and r.json()["version"] == 1
    r = c.patch("/api/projects/h", json={"name": "h"})
    assert r.status_code == 200
    for p in house_points()[2:]:
        ok(c.post("/api/projects/h/points", json=p), 201)
    ok(c.post("/api/projects/h/buildings", json=HOUSE), 201)
    n += 5
    r = c.patch("/api/projects/h/buildings/B1", json={"roofs": ROOFS, "ground": GROUND})
    assert r.status_code == 200 and r.json()["version"] == 1 and r.headers["ETag"] == '"1"'
    assert len(trail(c)) == n  # nothing changed: nothing listed
    r = c.patch(f"/api/projects/h/points/{pid}", json={"code": "ridge"})
    assert r.json()["version"] == v + 1 and len(trail(c)) == n + 1
