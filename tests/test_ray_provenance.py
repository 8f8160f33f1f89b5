"""How each ray was aimed ("auto": matched automatically, else clicked; "score": the match
score) and who measured a point (measured_by): accepted by every route that takes rays, kept
with the stored ray on both backends, returned as given, and counted per point in the
exports (GeoPackage, GeoJSON, CSV), the session JSON, the PostGIS view and the survey report."""

from __future__ import annotations

import csv
import json
import warnings

import pyogrio
import pytest
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)
from servertools import london_rays

from gsgeo.cli import main
from gsgeo.pointschema import EXPORT_KEYS, PROVENANCE_KEYS
from gsgeo.report import render
from gsgeo.service import Projects
from gsgeo.service.reporting import report_data
from gsgeo.store import open_store

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.server.app import ServerConfig, create_app


def aimed(auto: list[bool | None], scores: list[float | None] | None = None) -> list[dict]:
    """London rays with these auto flags (None: the member left out) and scores."""
    rays = london_rays(len(auto))
    for r, a, s in zip(rays, auto, scores or [None] * len(auto), strict=True):
        if a is not None:
            r["auto"] = a
        if s is not None:
            r["score"] = s
    return rays


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request) -> str | None:
    if request.param == "sqlite":
        return None
    cluster = request.getfixturevalue("pg_cluster")
    return cluster.url(cluster.new_database())


@pytest.fixture
def client(tmp_path, store_url):
    app = create_app(ServerConfig(data_dir=tmp_path / "data", allowed_hosts={"testserver"},
                                  store_url=store_url))
    with TestClient(app) as c:
        r = c.post("/api/projects", json={"name": "p", "id": "p", "crs": "EPSG:27700"})
        assert r.status_code == 201, r.text
        yield c


def test_rays_keep_auto_and_score_through_every_route(client):
    rays = aimed([None, False, True, True], [None, None, 0.93, 0.71])
    r = client.post("/api/intersect", json={"rays": rays, "crs": "EPSG:27700"})
    assert r.status_code == 200, r.text
    got = [{k: ray.get(k) for k in ("auto", "score")} for ray in r.json()["rays"]]
    assert got == [{"auto": None, "score": None}, {"auto": False, "score": None},
                   {"auto": True, "score": 0.93}, {"auto": True, "score": 0.71}]

    r = client.post("/api/projects/p/points", json={"id": "A", "rays": rays})
    assert r.status_code == 201, r.text
    assert r.json()["rays"] == rays  # as given, stored
    r = client.get("/api/projects/p/points/A")
    assert r.json()["rays"] == rays and r.json()["measured_by"] == "local"

    patched = aimed([True, None, True], [0.5, None, 0.6])
    r = client.patch("/api/projects/p/points/A", json={"rays": patched})
    assert r.status_code == 200, r.text
    assert client.get("/api/projects/p/points/A").json()["rays"] == patched

    # the session JSON carries them (and who measured each point) both ways
    session = client.get("/api/projects/p/session").json()
    assert session["points"][0]["rays"] == patched
    assert session["points"][0]["measured_by"] == "local"
    client.post("/api/projects", json={"name": "q", "id": "q", "crs": "EPSG:27700"})
    r = client.post("/api/projects/q/session", json=session)
    assert r.status_code == 201, r.text
    assert client.get("/api/projects/q/points/A").json()["rays"] == patched


@pytest.mark.parametrize(("member", "value", "where"), [
    ("auto", "yes", "rays[1].auto"), ("auto", 1, "rays[1].auto"),
    ("score", "high", "rays[1].score"), ("score", [1], "rays[1].score")])
def test_bad_provenance_is_refused_naming_the_member(client, member, value, where):
    rays = london_rays(3)
    rays[1][member] = value
    for url in ("/api/intersect", "/api/projects/p/points"):
        r = client.post(url, json={"rays": rays, "crs": "EPSG:27700"} if "intersect" in url
                        else {"rays": rays})
        assert r.status_code == 422, r.text
        assert member in r.text and "1" in r.text
    r = client.post("/api/projects/p/session", json={"points": [{"id": "S", "rays": rays}]})
    assert r.status_code == 422 and where in r.text, r.text
    assert client.get("/api/projects/p/points").json()["points"] == []


def test_exports_count_clicked_and_automatic_rays_and_name_who_measured(client, tmp_path):
    for pid, auto in (("A", [False, True, True]), ("B", [None, None, None, None])):
        r = client.post("/api/projects/p/points", json={"id": pid, "rays": aimed(auto)})
        assert r.status_code == 201, r.text
    want = {"A": ("local", 1, 2), "B": ("local", 4, 0)}

    r = client.get("/api/projects/p/export", params={"format": "csv"})
    assert r.status_code == 200, r.text
    rows = list(csv.DictReader(r.text.splitlines()))
    assert list(rows[0])[-3:] == list(PROVENANCE_KEYS)
    assert {row["point_id"]: (row["measured_by"], int(row["n_rays_clicked"]),
                              int(row["n_rays_auto"])) for row in rows} == want

    r = client.get("/api/projects/p/export", params={"format": "geojson"})
    feats = [f for f in r.json()["features"] if f["properties"]["layer"] == "points"]
    assert {f["properties"]["point_id"]: tuple(f["properties"][k] for k in PROVENANCE_KEYS)
            for f in feats} == want

    # the OGC API's points say the same, paged and one by one
    feats = client.get("/ogc/collections/p.points/items").json()["features"]
    assert {f["id"]: tuple(f["properties"][k] for k in PROVENANCE_KEYS) for f in feats} == want
    one = client.get("/ogc/collections/p.points/items/A").json()["properties"]
    assert tuple(one[k] for k in PROVENANCE_KEYS) == want["A"]

    r = client.get("/api/projects/p/export", params={"format": "gpkg"})
    (tmp_path / "p.gpkg").write_bytes(r.content)
    df = pyogrio.read_dataframe(tmp_path / "p.gpkg", layer="points")
    assert list(df.columns[:-1]) == list(EXPORT_KEYS)
    assert {row.point_id: (row.measured_by, row.n_rays_clicked, row.n_rays_auto)
            for row in df.itertuples()} == want


def test_the_report_says_how_each_point_was_aimed(tmp_path):
    with open_store(tmp_path) as store:
        svc = Projects(store, tmp_path)
        svc.create_project(name="p", id="p", crs="EPSG:27700")
        svc.add_point("p", {"id": "A", "rays": aimed([True, False, True, None])})
        svc.add_point("p", {"id": "B", "rays": aimed([False, False, True])})
        data = report_data(svc, "p")
        html = render(data, "html").decode()
    assert [(r["n_rays_clicked"], r["n_rays_auto"]) for r in data["points"]] == [(2, 2), (2, 1)]
    assert "clicked / auto" in html and ">2 / 2<" in html and ">2 / 1<" in html


def test_solve_exports_a_sessions_provenance(tmp_path):
    session = {"crs": "EPSG:27700", "points": [{"id": "A", "rays": aimed([True, False, None])}]}
    path = tmp_path / "s.json"
    path.write_text(json.dumps(session))
    assert main(["solve", str(path), "-o", str(tmp_path / "out.csv")]) == 0
    row = next(csv.DictReader((tmp_path / "out.csv").read_text().splitlines()))
    assert (row["measured_by"], row["n_rays_clicked"], row["n_rays_auto"]) == ("", "2", "1")


def test_the_postgis_points_view_has_the_provenance_columns(request, tmp_path):
    cluster = request.getfixturevalue("pg_cluster")
    db = cluster.new_database()
    store = open_store(tmp_path, cluster.url(db))
    try:
        svc = Projects(store, tmp_path)
        svc.create_project(name="p", id="p", crs="EPSG:27700")
        svc.add_point("p", {"id": "A", "rays": aimed([True, False, True, None])})
        rows = cluster.sql(db, "SELECT measured_by, n_rays_clicked, n_rays_auto"
                               " FROM gsgeo_p_points")
        assert rows == [("local", 2, 2)]
        types = dict(cluster.sql(db, "SELECT column_name, data_type FROM"
                                     " information_schema.columns WHERE table_name ="
                                     " 'gsgeo_p_points'"))
        assert types["n_rays_auto"] == "integer" and types["measured_by"] == "text"
    finally:
        store.close()
