"""POST /api/projects/{pid}/locate: points the viewer shows (rendered ECEF, under the tileset's
modelMatrix) in the project's grid, as the cursor's coordinates use it. Expected values from
pyproj directly (ETRS89 / UTM 30N's E, N and WGS 84 ellipsoidal height near London)."""

from __future__ import annotations

import warnings

import numpy as np
import pyproj
from servertools import LONDON

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.server.app import ServerConfig, create_app

TO_ECEF = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
UTM30 = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:32630", always_xy=True)


def test_points_come_back_in_the_grid_and_bad_input_is_4xx(tmp_path):
    with TestClient(create_app(ServerConfig(data_dir=tmp_path / "data",
                                            allowed_hosts={"testserver"}))) as c:
        assert c.post("/api/projects", json={"name": "G", "id": "g", "crs": "EPSG:32630"}
                      ).status_code == 201
        assert c.post("/api/projects", json={"name": "W", "id": "w"}).status_code == 201
        lon, lat, h = LONDON[0], LONDON[1], 40.0
        ecef = np.array(TO_ECEF.transform(lon, lat, h))
        e, n = UTM30.transform(lon, lat)
        r = c.post("/api/projects/g/locate", json={"points": [ecef.tolist()]})
        assert r.status_code == 200, r.text
        body = r.json()
        assert body["crs"] == "EPSG:32630"
        got = body["points"][0]
        assert abs(got["easting"] - e) < 1e-3 and abs(got["northing"] - n) < 1e-3
        assert abs(got["height"] - h) < 1e-3 and abs(got["h_wgs84"] - h) < 1e-3

        # under a modelMatrix (the scene shifted 100 m in x for the viewer): undone first
        shift = np.eye(4)
        shift[0, 3] = 100.0
        m16 = shift.T.reshape(-1).tolist()
        r = c.post("/api/projects/g/locate", json={"points": [(ecef + [100.0, 0, 0]).tolist()],
                                                   "model_matrix": m16})
        assert r.status_code == 200, r.text
        assert abs(r.json()["points"][0]["easting"] - e) < 1e-3

        # no grid CRS: WGS 84 only
        r = c.post("/api/projects/w/locate", json={"points": [ecef.tolist()]})
        assert r.status_code == 200, r.text
        w = r.json()["points"][0]
        assert "easting" not in w and abs(w["lon"] - lon) < 1e-9 and abs(w["lat"] - lat) < 1e-9

        # bad input: named, never a 500
        assert c.post("/api/projects/nope/locate", json={"points": [ecef.tolist()]}).status_code == 404
        for bad in ({"points": []}, {"points": [[1.0, 2.0]]}, {"points": [[1e12, 0.0, 0.0]]},
                    {"points": [ecef.tolist()], "model_matrix": [0.0] * 16},
                    {"points": [ecef.tolist()], "extra": 1}):
            r = c.post("/api/projects/g/locate", json=bad)
            assert 400 <= r.status_code < 500, (bad, r.status_code, r.text)
            assert r.json().get("message"), r.text


def test_check_points_come_with_their_ecef(tmp_path):
    """GET .../checkpoints gives each check or control point its ECEF (the viewer draws the
    unmeasured ones there): pyproj's EPSG:4979 -> EPSG:4978 for a point given in WGS 84, the
    same through the grid for one given in ETRS89 / UTM 30N with an ellipsoidal height (the
    project's default vertical), null for a point without a height."""
    with TestClient(create_app(ServerConfig(data_dir=tmp_path / "data",
                                            allowed_hosts={"testserver"}))) as c:
        assert c.post("/api/projects", json={"name": "G", "id": "g", "crs": "EPSG:32630"}
                      ).status_code == 201
        lon, lat, h = LONDON[0], LONDON[1], 40.0
        e, n = UTM30.transform(lon, lat)
        r = c.post("/api/projects/g/checkpoints", json={"crs": "EPSG:4979", "role": "control",
                                                        "points": [{"id": "C1", "x": lon, "y": lat, "z": h}]})
        assert r.status_code == 201, r.text
        r = c.post("/api/projects/g/checkpoints", json={"crs": "EPSG:32630", "points": [
            {"id": "K1", "x": e, "y": n, "z": h}, {"id": "K2", "x": e, "y": n}]})
        assert r.status_code == 201, r.text
        got = {p["id"]: p for p in c.get("/api/projects/g/checkpoints").json()["check_points"]}
        want = np.array(TO_ECEF.transform(lon, lat, h))
        assert np.abs(np.array(got["C1"]["ecef"]) - want).max() < 1e-6
        assert np.abs(np.array(got["K1"]["ecef"]) - want).max() < 1e-3
        assert got["K2"]["ecef"] is None
        assert (got["C1"]["role"], got["K1"]["role"]) == ("control", "check")


def test_check_points_keep_their_description(tmp_path):
    """A check point's description (what and where the mark is) is read from a CSV column
    `description` (or desc, remark, note) and a GeoJSON property of that name, given in JSON,
    stored on SQLite, listed, and served in the OGC API's check points; longer than 300
    characters is a 422 naming the field."""
    from gsgeo.service.checkpoints import read_check_points

    csv_rows, _ = read_check_points(b"id,easting,northing,height,Description\n"
                                    b"K1,1.0,2.0,3.0,PK nail in kerb\nK2,4.0,5.0,,\n", "csv")
    assert [(r.id, r.description) for r in csv_rows] == [("K1", "PK nail in kerb"), ("K2", "")]
    gj = (b'{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": '
          b'{"id": "C1", "remark": "trig pillar"}, "geometry": {"type": "Point", '
          b'"coordinates": [1.0, 2.0, 3.0]}}]}')
    assert [r.description for r in read_check_points(gj, "geojson")[0]] == ["trig pillar"]
    with TestClient(create_app(ServerConfig(data_dir=tmp_path / "data",
                                            allowed_hosts={"testserver"}))) as c:
        assert c.post("/api/projects", json={"name": "G", "id": "g", "crs": "EPSG:32630"}
                      ).status_code == 201
        r = c.post("/api/projects/g/checkpoints", json={"crs": "EPSG:32630", "points": [
            {"id": "K1", "x": 699000.0, "y": 5710000.0, "z": 50.0, "description": "PK nail in kerb"},
            {"id": "K2", "x": 699010.0, "y": 5710000.0}]})
        assert r.status_code == 201, r.text
        listed = c.get("/api/projects/g/checkpoints").json()["check_points"]
        got = {p["id"]: p["description"] for p in listed}
        assert got == {"K1": "PK nail in kerb", "K2": ""}
        r = c.post("/api/projects/g/checkpoints", json={"crs": "EPSG:32630", "points": [
            {"id": "K3", "x": 1.0, "y": 2.0, "description": "x" * 301}]})
        assert r.status_code == 422 and "description" in r.text, r.text
        # and in the OGC API's check-points collection
        r = c.get("/ogc/collections/g.check_points/items", params={"f": "json"})
        assert r.status_code == 200, r.text
        props = {f["properties"]["point_id"]: f["properties"]["description"]
                 for f in r.json()["features"]}
        assert props == {"K1": "PK nail in kerb", "K2": ""}
