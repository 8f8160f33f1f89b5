"""The audit trail: a scripted session through the API leaves every change listed exactly
once, with its user, action, item and before/after values; refused changes leave nothing;
the trail pages, filters by item and outlives its project. On SQLite and on PostgreSQL."""

from __future__ import annotations

import pytest
import test_georef_api
from fastapi.testclient import TestClient
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)
from servertools import london_rays

from gsgeo.server.app import ServerConfig, create_app
from gsgeo.service import Projects, accounts
from gsgeo.service.audit import acting_as
from gsgeo.store import open_store


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request) -> str | None:
    if request.param == "sqlite":
        return None
    cluster = request.getfixturevalue("pg_cluster")
    return cluster.url(cluster.new_database())


#: A scene with measured control (DATA, loopback client, project "loc"), as test_georef_api's.
site = test_georef_api.site


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


@pytest.fixture
def session(tmp_path, store_url):
    """(client off loopback, surveyor's headers, admin's headers, viewer's headers)."""
    with open_store(tmp_path / "data", store_url) as s:
        sam = accounts.add_user(s, "sam", "surveyor")
        ada = accounts.add_user(s, "ada", "admin")
        vic = accounts.add_user(s, "vic", "viewer")
    app = create_app(ServerConfig(data_dir=tmp_path / "data", store_url=store_url,
                                  host="0.0.0.0", token="tok", allowed_hosts=None))
    with TestClient(app) as c:
        yield c, bearer(sam), bearer(ada), bearer(vic)


def test_a_scripted_session_is_listed_once_per_change(session):
    c, sam, ada, vic = session
    r = c.post("/api/projects", json={"name": "Site", "crs": "EPSG:32630"}, headers=sam)
    pid = r.json()["id"]
    base = f"/api/projects/{pid}"
    assert c.post(f"{base}/points", json={"id": "P1", "rays": london_rays()},
                  headers=sam).status_code == 201
    assert c.post(f"{base}/points", json={"id": "P2", "rays": london_rays(5)},
                  headers=ada).status_code == 201
    assert c.patch(f"{base}/points/P1", json={"code": "KERB"}, headers=sam).status_code == 200
    assert c.patch(f"{base}/points/P1", json={"exclude_ray": 0}, headers=sam).status_code == 200
    r = c.post(f"{base}/checkpoints", headers=ada, json={
        "crs": "EPSG:32630", "role": "control",
        "points": [{"id": "GCP1", "x": 699000.0, "y": 5710000.0, "z": 30.0}]})
    assert r.status_code == 201, r.text
    assert c.delete(f"{base}/points/P2", headers=ada).status_code == 204
    assert c.patch(base, json={"sigma_px": 2.0}, headers=sam).status_code == 200
    # refused changes leave no entry: a viewer's, a duplicate id, a stale If-Match
    assert c.patch(f"{base}/points/P1", json={"code": "X"}, headers=vic).status_code == 403
    assert c.post(f"{base}/points", json={"id": "P1", "rays": london_rays()},
                  headers=sam).status_code == 409
    assert c.patch(f"{base}/points/P1", json={"code": "X"},
                   headers=sam | {"If-Match": '"1"'}).status_code == 412

    page = c.get(f"{base}/audit", params={"order": "oldest"}, headers=vic).json()
    got = [(e["user"], e["action"], e["kind"], e["item"]) for e in page["entries"]]
    assert got == [
        ("sam", "created", "project", None),
        ("sam", "created", "point", "P1"),
        ("ada", "created", "point", "P2"),
        ("sam", "changed", "point", "P1"),
        ("sam", "ray excluded", "point", "P1"),
        ("ada", "control points imported", "check point", None),
        ("ada", "deleted", "point", "P2"),
        ("sam", "changed", "settings", None),
    ]
    e = page["entries"]
    assert e[0]["before"] is None and e[0]["after"]["crs"] == "EPSG:32630"
    assert e[1]["after"]["rays"] == 4 and e[1]["after"]["easting"] is not None
    assert e[3]["before"] == {"code": ""} and e[3]["after"] == {"code": "KERB"}
    assert e[4]["before"]["excluded"] == [] and e[4]["after"]["excluded"] == [0]
    assert (e[4]["before"]["n_rays"], e[4]["after"]["n_rays"]) == (4, 3)  # re-solved
    assert e[5]["after"]["ids"] == ["GCP1"] and e[5]["after"]["role"] == "control"
    assert e[6]["before"]["id"] == "P2" and e[6]["after"] is None
    assert e[7]["before"] == {"sigma_px": 1.0} and e[7]["after"] == {"sigma_px": 2.0}
    assert all(x["at"].endswith("Z") for x in e)
    assert page["total"] == 8 and page["counts"]["created"] == 3
    # newest first by default; pages; one item's entries
    newest = c.get(f"{base}/audit", params={"limit": 2, "offset": 1}, headers=vic).json()
    assert [x["action"] for x in newest["entries"]] == ["deleted", "control points imported"]
    p1 = c.get(f"{base}/audit", params={"item": "P1"}, headers=vic).json()
    assert [x["action"] for x in p1["entries"]] == ["ray excluded", "changed", "created"]
    assert p1["total"] == 3
    # who measured each point
    assert c.get(f"{base}/points/P1", headers=vic).json()["measured_by"] == "sam"


def test_the_trail_outlives_its_project_and_an_unknown_one_is_404(session):
    c, sam, ada, vic = session
    pid = c.post("/api/projects", json={"name": "Gone"}, headers=sam).json()["id"]
    assert c.delete(f"/api/projects/{pid}", headers=ada).status_code == 204
    entries = c.get(f"/api/projects/{pid}/audit", headers=vic).json()["entries"]
    assert [(x["user"], x["action"]) for x in entries] == [("ada", "deleted"), ("sam", "created")]
    r = c.get("/api/projects/never-was/audit", headers=vic)
    assert r.status_code == 404 and "never-was" in r.json()["message"]
    assert c.get(f"/api/projects/{pid}/audit", params={"limit": 0},
                 headers=vic).status_code == 422


def test_lines_and_check_point_deletes_are_recorded_in_the_service(tmp_path, store_url):
    with open_store(tmp_path / "data", store_url) as s:
        svc = Projects(s, tmp_path / "data")
        with acting_as("olga"):
            p = svc.create_project(name="S", crs="EPSG:32630")
            svc.add_point(p.id, {"id": "A", "rays": london_rays()})
            svc.add_point(p.id, {"id": "B", "rays": london_rays(5)})
            svc.add_feature(p.id, "line", {"id": "L1", "points": ["A", "B"]})
            svc.update_feature(p.id, "line", "L1", {"code": "FENCE"})
            svc.delete_feature(p.id, "line", "L1")
        svc.update_point(p.id, "B", {"rays": london_rays(6)})  # no actor set: "local"
        with s.transaction(write=False) as tx:
            trail = tx.list_audit(p.id, newest_first=False)
            counts = tx.count_audit(p.id)
        assert [(e.actor, e.action, e.kind, e.item) for e in trail][3:] == [
            ("olga", "created", "line", "L1"), ("olga", "changed", "line", "L1"),
            ("olga", "deleted", "line", "L1"), ("local", "changed", "point", "B")]
        assert trail[4].before == {"code": ""} and trail[4].after == {"code": "FENCE"}
        assert trail[6].after["rays"] == 6
        assert counts == {"changed": 2, "created": 4, "deleted": 1}
        assert svc.get_point(p.id, "B").measured_by == "local"  # new rays: a new measurer
        assert svc.get_point(p.id, "A").measured_by == "olga"


def test_the_report_lists_the_latest_changes_and_counts_per_action(tmp_path, monkeypatch):
    from gsgeo.report.content import build_report
    from gsgeo.report.html import render_html
    from gsgeo.service import reporting

    monkeypatch.setattr(reporting, "AUDIT_ROWS", 2)
    with open_store(tmp_path / "data") as s:
        svc = Projects(s, tmp_path / "data")
        with acting_as("<b>mallory</b>"):
            p = svc.create_project(name="R", crs="EPSG:32630")
            for i in range(3):
                svc.add_point(p.id, {"id": f"Q{i}", "rays": london_rays()})
            svc.update_point(p.id, "Q0", {"code": "TREE"})
        data = reporting.report_data(svc, p.id)
    assert data["audit"]["total"] == 5 and len(data["audit"]["entries"]) == 2
    assert data["audit"]["counts"] == {"changed": 1, "created": 4}
    report = build_report(data)
    section = report.sections[-1]
    assert section.title == "Audit trail (5)"
    counts, latest = section.blocks
    assert counts.rows == [["changed", "1"], ["created", "4"]]
    assert [r[2:4] for r in latest.rows] == [["changed", "point Q0"], ["created", "point Q2"]]
    assert "The latest 2 of 5" in latest.caption
    html = render_html(report)
    assert "Audit trail (5)" in html and "&lt;b&gt;mallory" in html and "<b>mallory" not in html


def test_georeference_and_undo_are_recorded_with_the_projects_they_re_solve(site):
    """The scene of test_georef_api's site (loopback: the local operator) and a second
    project on the same scene: apply and undo are entries of the project that made them; the
    other project's points, re-solved by them, get a "re-solved" entry each time; a preview
    and a refused undo leave none."""
    c, _data, _ = site
    rays = c.get("/api/projects/loc/points/G0").json()["rays"]
    assert c.post("/api/projects", json={"name": "o", "id": "other", "scene": "loc",
                                         "crs": "EPSG:27700"}).status_code == 201
    assert c.post("/api/projects/other/points", json={"id": "X", "rays": rays}).status_code == 201
    assert c.post("/api/projects/loc/georeference", json={}).status_code == 200  # a preview
    assert c.post("/api/projects/loc/georeference", json={"apply": True}).status_code == 200
    assert c.post("/api/projects/loc/georeference/undo").status_code == 200
    assert c.post("/api/projects/loc/georeference/undo").status_code == 422
    loc = c.get("/api/projects/loc/audit", params={"item": "loc"}).json()["entries"]
    assert [(e["user"], e["action"], e["kind"]) for e in loc] == [
        ("local", "georeference undone", "scene"), ("local", "georeferenced", "scene")]
    applied = loc[1]
    assert applied["before"]["version"] == 0 and applied["after"]["version"] == 1
    assert applied["after"]["remeasured_points"] == 7 and len(applied["after"][
        "root_transform"]) == 16
    assert loc[0]["after"]["version"] == 2
    other = c.get("/api/projects/other/audit").json()["entries"]
    assert [(e["action"], e["item"]) for e in other] == [
        ("re-solved", "loc"), ("re-solved", "loc"), ("created", "X"), ("created", None)]
    assert other[1]["after"] == {"version": 1, "remeasured_points": 1, "by_project": "loc"}
