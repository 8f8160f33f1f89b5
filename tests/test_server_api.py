"""The JSON API through FastAPI's TestClient: every endpoint, its results and its errors."""

from __future__ import annotations

import io
import json
import warnings

import numpy as np
import pyproj
import pytest
from servertools import LONDON, ecef_of, london_rays, rays_at

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.server.app import ServerConfig, create_app

UTM30 = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:32630", always_xy=True)


def make_client(data, **cfg) -> TestClient:
    cfg.setdefault("allowed_hosts", {"testserver"})
    return TestClient(create_app(ServerConfig(data_dir=data, **cfg)))


@pytest.fixture
def client(tmp_path):
    with make_client(tmp_path / "data") as c:
        yield c


@pytest.fixture
def project(client) -> str:
    r = client.post("/api/projects", json={"name": "London", "crs": "EPSG:32630"})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def target(k: int) -> tuple[float, float, float]:
    """Targets 10 m apart eastwards-ish around London."""
    return (LONDON[0] + 1.5e-4 * k, LONDON[1] + 0.5e-4 * (k % 2), 45.0 + k)


def add_point(client, pid, k: int, **extra) -> dict:
    r = client.post(f"/api/projects/{pid}/points",
                    json={"id": f"T{k}", "rays": rays_at(ecef_of(*target(k)), 4), **extra})
    assert r.status_code == 201, r.text
    return r.json()


def expect_422(r, field: str) -> dict:
    assert r.status_code == 422, r.text
    body = r.json()
    assert field in body["message"], body
    return body


# info and intersect ---------------------------------------------------------------------------
def test_info(client):
    r = client.get("/api/info")
    assert r.status_code == 200 and r.json()["token_required"] is False


def test_intersect_returns_grid_coordinates(client):
    r = client.post("/api/intersect", json={"rays": london_rays(4), "crs": "EPSG:32630",
                                            "id": "X", "code": "kerb"})
    assert r.status_code == 200, r.text
    out = r.json()
    e, n = UTM30.transform(LONDON[0], LONDON[1])
    assert out["point_id"] == "X" and out["code"] == "kerb" and out["crs"] == "EPSG:32630"
    assert out["easting"] == pytest.approx(e, abs=1e-4)
    assert out["northing"] == pytest.approx(n, abs=1e-4)
    assert out["height"] == pytest.approx(LONDON[2], abs=1e-4)
    assert len(out["rays"]) == 4 and all(r_["excluded"] is False for r_ in out["rays"])
    assert isinstance(out["warnings"], list)


def test_intersect_without_crs_gives_wgs84(client):
    r = client.post("/api/intersect", json={"rays": london_rays(3)})
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["easting"] is None
    assert out["lon"] == pytest.approx(LONDON[0], abs=1e-9)
    assert out["lat"] == pytest.approx(LONDON[1], abs=1e-9)


def test_intersect_angular_model_reports_pixels(client):
    rays = london_rays(5, ifov=1e-3, noise_rad=1e-3, rng=np.random.default_rng(3))
    out = client.post("/api/intersect", json={"rays": rays, "crs": "EPSG:32630",
                                              "sigma_px": 1.0, "exclude": [4]}).json()
    assert out["n_rays"] == 4 and out["rays"][4]["excluded"] is True
    assert all(r_["residual_px"] is not None for r_ in out["rays"])


@pytest.mark.parametrize("body, field", [
    ({"rays": london_rays(1)}, "rays"),
    ({}, "rays"),
    ({"rays": [{"origin": [1, 2], "direction": [1, 0, 0]}] * 2}, "rays[0].origin"),
    ({"rays": [london_rays(2)[0], {"origin": [1, 2, 3]}]}, "rays[1].direction"),
    ({"rays": [london_rays(2)[0], {"origin": [1, 2, 3], "direction": [0, 0, 0]}]},
     "rays[1].direction"),
    ({"rays": [london_rays(2)[0], {"origin": [1, 2, "x"], "direction": [1, 0, 0]}]},
     "rays[1].origin[2]"),
    ({"rays": london_rays(2), "crs": "EPSG:999999"}, "crs"),
    ({"rays": london_rays(2), "crs": "EPSG:4326"}, "crs"),
    ({"rays": london_rays(2), "source_crs": "EPSG:27700"}, "source_crs"),
    ({"rays": london_rays(2), "sigma_px": 0}, "sigma_px"),
    ({"rays": london_rays(3), "exclude": [0, 1]}, "exclude"),
    ({"rays": london_rays(3), "exclude": [5]}, "exclude"),
    ({"rays": london_rays(2), "colour": "red"}, "colour"),
    ({"rays": london_rays(2), "geoid": "../gsgeo.sqlite", "crs": "EPSG:32630"}, "geoid"),
    ({"rays": [dict(r, model_matrix=[1.0] * 16) for r in london_rays(2)]},
     "rays[0].model_matrix"),
])
def test_intersect_malformed_requests_name_the_field(client, body, field):
    expect_422(client.post("/api/intersect", json=body), field)


def test_non_finite_numbers_are_refused(client):
    text = json.dumps({"rays": london_rays(2)}).replace(str(london_rays(2)[0]["origin"][0]),
                                                        "NaN", 1)
    r = client.post("/api/intersect", content=text, headers={"content-type": "application/json"})
    expect_422(r, "rays[0].origin[0]")


def test_parallel_rays_are_a_clear_422(client):
    x = ecef_of(*LONDON)
    rays = [{"origin": (x + [0, 0, 10 * k]).tolist(), "direction": [1.0, 0, 0]} for k in range(3)]
    r = client.post("/api/intersect", json={"rays": rays})
    assert r.status_code == 422 and "parallel" in r.json()["message"]


def test_broken_json_and_wrong_content_type(client):
    r = client.post("/api/intersect", content=b"{bad", headers={"content-type": "application/json"})
    assert r.status_code == 422 and "body" in r.json()["message"]
    r = client.post("/api/intersect", content=json.dumps({"rays": london_rays(2)}),
                    headers={"content-type": "text/plain"})
    assert r.status_code == 422  # a form post from another site cannot pass as JSON


# projects -------------------------------------------------------------------------------------
def test_project_crud(client):
    r = client.post("/api/projects", json={"name": "Site A", "id": "site-a", "crs": "EPSG:32630",
                                           "sigma_px": 0.8})
    assert r.status_code == 201 and r.json()["id"] == "site-a"
    assert client.post("/api/projects", json={"name": "x", "id": "site-a"}).status_code == 409
    assert [p["id"] for p in client.get("/api/projects").json()["projects"]] == ["site-a"]
    got = client.get("/api/projects/site-a").json()
    assert got["sigma_px"] == 0.8 and got["counts"]["n_points"] == 0
    r = client.patch("/api/projects/site-a", json={"name": "Site A2", "description": "d"})
    assert r.status_code == 200 and r.json()["name"] == "Site A2"
    assert r.json()["settings_rev"] == 0  # no solving setting changed
    assert client.delete("/api/projects/site-a").status_code == 204
    assert client.get("/api/projects/site-a").status_code == 404
    assert client.delete("/api/projects/site-a").status_code == 404


@pytest.mark.parametrize("body, field", [
    ({}, "name"),
    ({"name": ""}, "name"),
    ({"name": "x", "id": "../etc"}, "id"),
    ({"name": "x", "crs": "EPSG:999999"}, "crs"),
    ({"name": "x", "crs": "EPSG:32630", "vertical": "EPSG:27700"}, "vertical"),
    ({"name": "x", "vertical": "EPSG:5701"}, "vertical"),
    ({"name": "x", "sigma_px": -1}, "sigma_px"),
    ({"name": "x", "scene": "nope"}, "scene"),
    ({"name": "x", "colour": 1}, "colour"),
])
def test_project_create_errors(client, body, field):
    expect_422(client.post("/api/projects", json=body), field)


def test_project_patch_errors(client, project):
    expect_422(client.patch(f"/api/projects/{project}", json={"name": None}), "name")
    expect_422(client.patch(f"/api/projects/{project}", json={"crs": "nonsense"}), "crs")
    expect_422(client.patch(f"/api/projects/{project}", json={"sigma_px": None}), "sigma_px")
    expect_422(client.patch(f"/api/projects/{project}", json={"foo": 1}), "foo")
    assert client.patch("/api/projects/none", json={"name": "x"}).status_code == 404


def test_crs_change_resolves_points(client, project):
    add_point(client, project, 0)
    r = client.patch(f"/api/projects/{project}", json={"crs": "EPSG:32631"})
    assert r.status_code == 200 and r.json()["settings_rev"] == 1
    rec = client.get(f"/api/projects/{project}/points/T0").json()["record"]
    e, n = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:32631", always_xy=True).transform(
        *target(0)[:2])
    assert rec["crs"] == "EPSG:32631" and rec["easting"] == pytest.approx(e, abs=1e-4)
    r = client.patch(f"/api/projects/{project}", json={"crs": None})
    assert r.status_code == 200
    rec = client.get(f"/api/projects/{project}/points/T0").json()["record"]
    assert rec["easting"] is None and rec["lon"] == pytest.approx(target(0)[0], abs=1e-9)


# points -----------------------------------------------------------------------------------------
def test_point_crud(client, project):
    base = f"/api/projects/{project}/points"
    r = client.post(base, json={"rays": london_rays(3), "code": "tree"})
    assert r.status_code == 201, r.text
    p1 = r.json()
    assert p1["id"] == "P1" and p1["status"] == "solved" and p1["record"]["code"] == "tree"
    assert len(p1["rays"]) == 3 and p1["result"]["n_rays"] == 3
    assert client.post(base, json={"id": "P1", "rays": london_rays(3)}).status_code == 409
    assert client.post(base, json={"rays": london_rays(3)}).json()["id"] == "P2"
    assert [p["id"] for p in client.get(base).json()["points"]] == ["P1", "P2"]
    r = client.patch(f"{base}/P1", json={"id": "Corner 1", "code": "wall", "description": "NE"})
    assert r.status_code == 200 and r.json()["record"]["point_id"] == "Corner 1"
    assert client.get(f"{base}/P1").status_code == 404
    assert client.get(f"{base}/Corner 1").json()["description"] == "NE"
    r = client.patch(f"{base}/Corner 1", json={"exclude_ray": 0})
    assert r.status_code == 200 and r.json()["excluded"] == [0]
    assert r.json()["record"]["n_rays"] == 2
    r = client.patch(f"{base}/Corner 1", json={"restore_ray": 0})
    assert r.json()["excluded"] == [] and r.json()["record"]["n_rays"] == 3
    r = client.patch(f"{base}/Corner 1", json={"rays": london_rays(5)})
    assert r.json()["record"]["n_rays"] == 5
    assert client.delete(f"{base}/Corner 1").status_code == 204
    assert client.delete(f"{base}/Corner 1").status_code == 404
    assert [p["id"] for p in client.get(base).json()["points"]] == ["P2"]


def test_point_errors(client, project):
    base = f"/api/projects/{project}/points"
    add_point(client, project, 0)
    expect_422(client.post(base, json={"rays": london_rays(1)}), "rays")
    expect_422(client.post(base, json={"id": "a/b", "rays": london_rays(2)}), "id")
    expect_422(client.post(base, json={"rays": london_rays(3), "excluded": [0, 1]}), "excluded")
    expect_422(client.patch(f"{base}/T0", json={"exclude_ray": 9}), "exclude_ray")
    expect_422(client.patch(f"{base}/T0", json={"restore_ray": 1}), "restore_ray")
    expect_422(client.patch(f"{base}/T0", json={"excluded": [0, 1, 2]}), "excluded")
    expect_422(client.patch(f"{base}/T0", json={"colour": "red"}), "colour")
    assert client.post("/api/projects/none/points", json={"rays": london_rays(2)}).status_code == 404
    assert client.patch(f"{base}/nope", json={"code": "x"}).status_code == 404
    # nothing of the failed requests was written
    pts = client.get(base).json()["points"]
    assert [p["id"] for p in pts] == ["T0"] and pts[0]["excluded"] == []


# lines and polygons ---------------------------------------------------------------------------
def _square(client, project):
    for k in range(4):
        add_point(client, project, k)


def test_line_and_polygon_crud(client, project):
    _square(client, project)
    r = client.post(f"/api/projects/{project}/lines", json={"points": ["T0", "T1", "T2"]})
    assert r.status_code == 201, r.text
    line = r.json()
    assert line["id"] == "L1" and line["kind"] == "line" and line["points"] == ["T0", "T1", "T2"]
    assert "measures" in line
    r = client.post(f"/api/projects/{project}/polygons",
                    json={"id": "roof", "points": ["T0", "T1", "T2", "T3", "T0"]})
    assert r.status_code == 201 and r.json()["points"] == ["T0", "T1", "T2", "T3"]
    assert [f["id"] for f in client.get(f"/api/projects/{project}/lines").json()["lines"]] == ["L1"]
    assert client.get(f"/api/projects/{project}/polygons/roof").json()["kind"] == "polygon"
    r = client.patch(f"/api/projects/{project}/lines/L1", json={"points": ["T3", "T2"], "code": "k"})
    assert r.status_code == 200 and r.json()["points"] == ["T3", "T2"]
    # renaming a point follows into the features
    client.patch(f"/api/projects/{project}/points/T2", json={"id": "X2"})
    assert client.get(f"/api/projects/{project}/lines/L1").json()["points"] == ["T3", "X2"]
    assert client.get(f"/api/projects/{project}/polygons/roof").json()["points"][2] == "X2"
    r = client.delete(f"/api/projects/{project}/points/X2")
    assert r.status_code == 409 and "roof" in r.json()["message"]
    assert client.delete(f"/api/projects/{project}/lines/L1").status_code == 204
    assert client.delete(f"/api/projects/{project}/polygons/roof").status_code == 204
    assert client.get(f"/api/projects/{project}/polygons/roof").status_code == 404


def test_feature_errors(client, project):
    _square(client, project)
    base = f"/api/projects/{project}"
    expect_422(client.post(f"{base}/lines", json={"points": ["T0"]}), "points")
    expect_422(client.post(f"{base}/lines", json={"points": ["T0", "nope"]}), "points[1]")
    expect_422(client.post(f"{base}/polygons", json={"points": ["T0", "T1"]}), "points")
    expect_422(client.post(f"{base}/lines", json={"points": ["T0", "T0"]}), "points[1]")
    client.post(f"{base}/lines", json={"id": "L", "points": ["T0", "T1"]})
    assert client.post(f"{base}/lines", json={"id": "L", "points": ["T0", "T1"]}).status_code == 409
    expect_422(client.patch(f"{base}/lines/L", json={"points": ["T0", "zz"]}), "points[1]")
    assert client.patch(f"{base}/lines/none", json={"code": "x"}).status_code == 404


# check points and accuracy --------------------------------------------------------------------
def test_check_points_json_and_accuracy_against_hand_computed_statistics(client, project):
    for k in range(4):
        add_point(client, project, k)
    offsets = np.array([[0.01, -0.02, 0.03], [-0.015, 0.005, -0.01], [0.02, 0.01, 0.0],
                        [0.0, -0.01, 0.02]])
    cps = []
    for k in range(4):
        e, n = UTM30.transform(*target(k)[:2])
        cps.append({"id": f"T{k}", "x": e + offsets[k, 0], "y": n + offsets[k, 1],
                    "z": target(k)[2] + offsets[k, 2]})
    cps.append({"id": "unmeasured", "x": 1.0, "y": 2.0})
    r = client.post(f"/api/projects/{project}/checkpoints",
                    json={"crs": "EPSG:32630", "points": cps})
    assert r.status_code == 201 and r.json()["imported"] == 5
    assert len(client.get(f"/api/projects/{project}/checkpoints").json()["check_points"]) == 5
    r = client.get(f"/api/projects/{project}/accuracy")
    assert r.status_code == 200, r.text
    acc = r.json()
    d = -offsets  # measured (exact) minus check
    s = acc["statistics"]
    rmse = np.sqrt((d ** 2).mean(axis=0))
    assert s["RMSE_E"] == pytest.approx(rmse[0], abs=1e-5)
    assert s["RMSE_N"] == pytest.approx(rmse[1], abs=1e-5)
    assert s["RMSE_V"] == pytest.approx(rmse[2], abs=1e-5)
    assert s["RMSE_H"] == pytest.approx(np.hypot(rmse[0], rmse[1]), abs=1e-5)
    assert s["RMSE_3D"] == pytest.approx(np.sqrt((rmse ** 2).sum()), abs=1e-5)
    assert s["ME_E"] == pytest.approx(d[:, 0].mean(), abs=1e-5)
    assert s["SD_N"] == pytest.approx(d[:, 1].std(ddof=1), abs=1e-5)
    assert [p["id"] for p in acc["points"]] == ["T0", "T1", "T2", "T3"]
    assert acc["points"][1]["dE"] == pytest.approx(d[1, 0], abs=1e-5)
    assert acc["points"][1]["dH"] == pytest.approx(d[1, 2], abs=1e-5)
    c = acc["counts"]
    assert (c["check_points"], c["matched"], c["matched_vertical"]) == (5, 4, 4)
    assert c["check_points_not_measured"] == ["unmeasured"]


def test_check_points_in_another_crs_are_transformed(client, project):
    add_point(client, project, 0)
    lon, lat, h = target(0)
    client.post(f"/api/projects/{project}/checkpoints",
                json={"crs": "EPSG:4326", "points": [{"id": "T0", "x": lon, "y": lat, "z": h}]})
    p = client.get(f"/api/projects/{project}/accuracy").json()["points"][0]
    assert abs(p["dE"]) < 1e-4 and abs(p["dN"]) < 1e-4 and abs(p["dH"]) < 1e-4


def _upload(client, project, name, data, **form):
    return client.post(f"/api/projects/{project}/checkpoints/import",
                       files={"file": (name, io.BytesIO(data), "application/octet-stream")},
                       data=form)


def test_check_point_import_csv_geojson_gpkg(client, project, tmp_path):
    add_point(client, project, 0)
    e, n = UTM30.transform(*target(0)[:2])
    h = target(0)[2]
    csv = f"point_id;easting;northing;height\nT0;{e + 0.01};{n};{h}\nB;1;2;\n".encode()
    r = _upload(client, project, "cps.csv", csv, crs="EPSG:32630")
    assert r.status_code == 201, r.text
    assert r.json() == {"imported": 2, "crs": "EPSG:32630", "format": "csv"}
    acc = client.get(f"/api/projects/{project}/accuracy").json()
    assert acc["points"][0]["dE"] == pytest.approx(-0.01, abs=1e-5)

    gj = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"name": "T0"},
         "geometry": {"type": "Point", "coordinates": [target(0)[0], target(0)[1], h + 0.02]}}]}
    r = _upload(client, project, "cps.geojson", json.dumps(gj).encode(), replace="true")
    assert r.status_code == 201 and r.json()["crs"] == "EPSG:4979"
    acc = client.get(f"/api/projects/{project}/accuracy").json()
    assert acc["counts"]["check_points"] == 1
    assert acc["points"][0]["dH"] == pytest.approx(-0.02, abs=1e-5)

    import geopandas as gpd
    from shapely.geometry import Point

    path = tmp_path / "cps.gpkg"
    gpd.GeoDataFrame({"point_id": ["T0"]}, geometry=[Point(e, n - 0.03, h)],
                     crs="EPSG:32630").to_file(path, layer="cps", driver="GPKG")
    r = _upload(client, project, "cps.gpkg", path.read_bytes(), replace="true")
    assert r.status_code == 201 and r.json()["crs"] == "EPSG:32630"
    acc = client.get(f"/api/projects/{project}/accuracy").json()
    assert acc["points"][0]["dN"] == pytest.approx(0.03, abs=1e-5)


def test_check_point_errors(client, project):
    base = f"/api/projects/{project}/checkpoints"
    expect_422(_upload(client, project, "a.csv", b"point_id,easting,northing\nA,1,2\n"), "crs")
    expect_422(_upload(client, project, "a.csv", b"who,what\n1,2\n", crs="EPSG:32630"), "file")
    expect_422(_upload(client, project, "a.csv", b"id,x,y\nA,1,zz\n", crs="EPSG:32630"),
               "line 2")
    expect_422(_upload(client, project, "a.xyz", b"id,x,y\nA,1,2\n", crs="EPSG:32630"), "format")
    expect_422(_upload(client, project, "a.gpkg", b"not a gpkg"), "file")
    expect_422(_upload(client, project, "a.geojson", b"{}"), "file")
    expect_422(_upload(client, project, "a.csv", b"id,x,y\nA,1,2\n", crs="EPSG:0"), "crs")
    expect_422(client.post(base, json={"crs": "EPSG:32630", "points": [
        {"id": "A", "x": 1, "y": 2}, {"id": "A", "x": 1, "y": 2}]}), "duplicate")
    expect_422(client.post(base, json={"crs": "EPSG:32630", "points": [{"id": "A", "x": 1}]}),
               "points[0].y")
    assert client.get(base).json()["check_points"] == []
    client.post(base, json={"crs": "EPSG:32630", "points": [{"id": "A", "x": 1, "y": 2}]})
    assert client.delete(f"{base}/A").status_code == 204
    assert client.delete(f"{base}/A").status_code == 404
    client.post(base, json={"crs": "EPSG:32630", "points": [{"id": "A", "x": 1, "y": 2}]})
    assert client.delete(base).json() == {"deleted": 1}


def test_a_stored_check_point_is_never_replaced_unasked(client, project):
    """A write naming an id already stored is refused (409 naming the ids, nothing stored);
    only ``overwrite`` listing that id replaces it, role and source as that write states."""
    base = f"/api/projects/{project}/checkpoints"
    truth = {"id": "S1", "x": 530000.5, "y": 180000.25, "z": 12.0}
    r = client.post(base, json={"crs": "EPSG:27700", "role": "check",
                                "source": "gsgeo demo ground truth", "points": [truth]})
    assert r.status_code == 201, r.text
    stored = client.get(base).json()["check_points"]
    measured = {"id": "S1", "x": -0.1, "y": 51.5, "z": 60.0}
    # the plugin's write: S1 again as a control point, and a new S2 with it
    r = client.post(base, json={"crs": "EPSG:4979", "role": "control",
                                "points": [measured, {"id": "S2", "x": -0.2, "y": 51.6}]})
    assert r.status_code == 409, r.text
    body = r.json()
    assert body["ids"] == ["S1"] and "S1" in body["message"] and body["field"] == "points"
    assert client.get(base).json()["check_points"] == stored  # S2 not stored either
    # the file import refuses the same way
    r = _upload(client, project, "cp.csv", b"id,x,y,z\nS1,1,2,3\n", crs="EPSG:27700")
    assert r.status_code == 409 and r.json()["ids"] == ["S1"], r.text
    assert client.get(base).json()["check_points"] == stored
    # asked for: S1 replaced with what this write states
    r = client.post(base, json={"crs": "EPSG:4979", "role": "control", "source": "QGIS: pts",
                                "overwrite": ["S1"], "points": [measured]})
    assert r.status_code == 201, r.text
    (now,) = client.get(base).json()["check_points"]
    assert (now["x"], now["y"], now["z"], now["crs"], now["role"], now["source"]) == \
        (-0.1, 51.5, 60.0, "EPSG:4979", "control", "QGIS: pts")
    # the trail names what was replaced, with its old values
    e = client.get(f"/api/projects/{project}/audit").json()["entries"][0]
    assert e["action"] == "control points imported" and e["after"]["overwritten"] == ["S1"]
    (old,) = e["before"]["points"]
    assert (old["x"], old["role"], old["source"]) == (530000.5, "check", "gsgeo demo ground truth")


def test_exported_check_points_say_their_role(client, project, tmp_path):
    import pyogrio

    add_point(client, project, 0)
    e, n = UTM30.transform(*target(0)[:2])
    base = f"/api/projects/{project}/checkpoints"
    client.post(base, json={"crs": "EPSG:32630", "role": "control",
                            "points": [{"id": "T0", "x": e, "y": n, "z": target(0)[2]}]})
    client.post(base, json={"crs": "EPSG:32630", "points": [{"id": "K", "x": e + 5, "y": n}]})
    r = client.get(f"/api/projects/{project}/export?format=gpkg")
    assert r.status_code == 200, r.text
    (tmp_path / "x.gpkg").write_bytes(r.content)
    df = pyogrio.read_dataframe(tmp_path / "x.gpkg", layer="check_points").set_index("point_id")
    assert df.loc["T0", "role"] == "control" and df.loc["K", "role"] == "check"
    doc = client.get(f"/api/projects/{project}/export?format=geojson").json()
    roles = {f["properties"]["point_id"]: f["properties"]["role"] for f in doc["features"]
             if f["properties"].get("layer") == "check_points"}
    assert roles == {"T0": "control", "K": "check"}


def test_accuracy_needs_a_grid(client):
    pid = client.post("/api/projects", json={"name": "no grid"}).json()["id"]
    expect_422(client.get(f"/api/projects/{pid}/accuracy"), "crs")
    assert client.get("/api/projects/none/accuracy").status_code == 404


# session, crs search, scenes ----------------------------------------------------------------
def test_session_document_round_trips_through_gsgeo_session(client, project):
    from gsgeo.session import parse_session

    add_point(client, project, 0)
    add_point(client, project, 1)
    client.post(f"/api/projects/{project}/lines", json={"points": ["T0", "T1"]})
    doc = client.get(f"/api/projects/{project}/session").json()
    s = parse_session(doc)
    assert [p.id for p in s.points] == ["T0", "T1"] and s.crs == "EPSG:32630"
    assert s.lines[0].points == ["T0", "T1"]


def test_crs_search(client):
    r = client.get("/api/crs", params={"q": "british national grid"})
    assert r.status_code == 200
    assert "EPSG:27700" in [h["code"] for h in r.json()["results"]]
    assert client.get("/api/crs", params={"q": ""}).status_code == 422
    assert client.get("/api/crs").status_code == 422
    expect_422(client.get("/api/crs", params={"q": "x", "limit": 0}), "limit")


def test_scenes_lists_georeference(tmp_path):
    data = tmp_path / "data"
    scene = data / "scenes" / "site"
    scene.mkdir(parents=True)
    origin = ecef_of(*LONDON)
    scene.joinpath("tileset.json").write_text(json.dumps({
        "asset": {"version": "1.1"}, "geometricError": 10,
        "root": {"transform": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, *origin, 1],
                 "boundingVolume": {"sphere": [0, 0, 0, 5]}, "geometricError": 1}}))
    (data / "scenes" / "broken").mkdir()
    (data / "scenes" / "broken" / "tileset.json").write_text("{")
    with make_client(data) as c:
        scenes = {s["name"]: s for s in c.get("/api/scenes").json()["scenes"]}
        s = scenes["site"]
        assert s["url"] == "/scenes/site/tileset.json"
        assert s["origin"]["lon"] == pytest.approx(LONDON[0], abs=1e-9)
        assert s["origin"]["lat"] == pytest.approx(LONDON[1], abs=1e-9)
        assert s["origin"]["height"] == pytest.approx(LONDON[2], abs=1e-4)
        assert s["bounds"]["west"] < LONDON[0] < s["bounds"]["east"]
        assert scenes["broken"]["error"]
        r = c.post("/api/projects", json={"name": "x", "scene": "site"})
        assert r.status_code == 201 and r.json()["scene"] == "site"


def test_real_scene_origin(white_sculpture, tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "scenes").symlink_to(white_sculpture.parent)  # scenes kept elsewhere: link the root
    tr = json.loads((white_sculpture / "tileset.json").read_text())["root"]["transform"]
    lon, lat, h = pyproj.Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True).transform(
        *tr[12:15])
    with make_client(data) as c:
        s = c.get("/api/scenes").json()["scenes"][0]
    assert s["origin"]["lon"] == pytest.approx(lon, abs=1e-9)
    assert s["origin"]["lat"] == pytest.approx(lat, abs=1e-9)
    b = s["bounds"]
    assert b["west"] < lon < b["east"] and b["south"] < lat < b["north"]
    from gsgeo.tiles.reader import splat_count

    assert s["splat_count"] == splat_count(white_sculpture / "tileset.json") > 0


# security ------------------------------------------------------------------------------------
def test_token_is_required_on_api_when_configured(tmp_path):
    with make_client(tmp_path / "d", token="s3cret", host="0.0.0.0", allowed_hosts=None) as c:
        r = c.get("/api/projects")
        assert r.status_code == 401 and "token" in r.json()["message"]
        assert c.get("/api/projects", headers={"Authorization": "Bearer wrong"}).status_code == 401
        assert c.get("/api/projects", headers={"Authorization": "Bearer s3cret"}).status_code == 200
        assert c.get("/api/projects", headers={"X-Gsgeo-Token": "s3cret"}).status_code == 200
        assert c.get("/").status_code == 200  # the page itself loads; it then asks for the token


def test_serve_generates_a_token_off_loopback():
    from gsgeo.server.app import ServerConfig as SC
    from gsgeo.server.app import is_loopback

    assert is_loopback("127.0.0.1") and is_loopback("::1") and not is_loopback("0.0.0.0")
    assert SC(data_dir="x", host="0.0.0.0").allowed_hosts is None
    assert "localhost" in SC(data_dir="x").allowed_hosts


def test_cross_origin_and_foreign_hosts_are_refused(client):
    r = client.post("/api/projects", json={"name": "x"}, headers={"Origin": "http://evil.example"})
    assert r.status_code == 403 and "access-control-allow-origin" not in r.headers
    r = client.options("/api/projects", headers={"Origin": "http://evil.example",
                                                  "Access-Control-Request-Method": "POST"})
    assert "access-control-allow-origin" not in r.headers
    r = client.post("/api/projects", json={"name": "x"}, headers={"Origin": "http://testserver"})
    assert r.status_code == 201
    assert client.get("/api/info", headers={"Host": "evil.example:8000"}).status_code == 400


def test_request_size_limits(tmp_path):
    with make_client(tmp_path / "d", max_body=10_000) as c:
        big = {"name": "x", "description": "a" * 20_000}
        r = c.post("/api/projects", json=big)
        assert r.status_code == 413 and "limit" in r.json()["message"]

        def chunks():
            yield b'{"name": "x", "description": "'
            for _ in range(20):
                yield b"a" * 1000
            yield b'"}'

        r = c.post("/api/projects", content=chunks(), headers={"content-type": "application/json"})
        assert r.status_code == 413
        assert c.get("/api/projects").json()["projects"] == []


def test_feature_measures_follow_their_points(client, project):
    """Lengths and areas against the targets projected by pyproj, recomputed when points move."""
    corners = [(0, 0), (20, 0), (20, 10), (0, 10)]  # metres east, north of a base point
    e0, n0 = UTM30.transform(*LONDON[:2])
    inv = pyproj.Transformer.from_crs("EPSG:32630", "EPSG:4979", always_xy=True)
    grid = []
    for k, (de, dn) in enumerate(corners):
        lon, lat = inv.transform(e0 + de, n0 + dn)
        h = 40.0 + k
        grid.append((e0 + de, n0 + dn, h))
        r = client.post(f"/api/projects/{project}/points",
                        json={"id": f"C{k}", "rays": rays_at(ecef_of(lon, lat, h), 4,
                                                              noise_rad=2e-5,
                                                              rng=np.random.default_rng(k))})
        assert r.status_code == 201
    g = np.array(grid)
    line = client.post(f"/api/projects/{project}/lines",
                       json={"points": ["C0", "C1", "C2"]}).json()["measures"]
    assert line["length_2d"] == pytest.approx(30.0, abs=0.01)
    want_3d = np.linalg.norm(g[1] - g[0]) + np.linalg.norm(g[2] - g[1])
    assert line["length_3d"] == pytest.approx(want_3d, abs=0.01)
    assert 0 < line["sigma_length_2d"] < 0.01
    poly = client.post(f"/api/projects/{project}/polygons",
                       json={"points": ["C0", "C1", "C2", "C3"]}).json()["measures"]
    assert poly["area_2d"] == pytest.approx(200.0, abs=0.2)
    assert poly["perimeter_2d"] == pytest.approx(60.0, abs=0.02)
    assert poly["sigma_area_2d"] > 0
    # move C2 ten metres north: the stored line is recomputed on read
    lon, lat = inv.transform(e0 + 20, n0 + 20)
    client.patch(f"/api/projects/{project}/points/C2",
                 json={"rays": rays_at(ecef_of(lon, lat, 42.0), 4)})
    line = client.get(f"/api/projects/{project}/lines/L1").json()["measures"]
    assert line["length_2d"] == pytest.approx(40.0, abs=0.01)
    assert client.get(f"/api/projects/{project}/polygons/A1").json()["measures"]["area_2d"] == \
        pytest.approx(300.0, abs=0.2)


# export ----------------------------------------------------------------------------------------
def _export_project(client, project):
    corners = [(0, 0), (20, 0), (20, 10), (0, 10)]
    e0, n0 = UTM30.transform(*LONDON[:2])
    inv = pyproj.Transformer.from_crs("EPSG:32630", "EPSG:4979", always_xy=True)
    for k, (de, dn) in enumerate(corners):
        lon, lat = inv.transform(e0 + de, n0 + dn)
        client.post(f"/api/projects/{project}/points",
                    json={"id": f"C{k}", "rays": rays_at(ecef_of(lon, lat, 40.0), 4)})
    client.post(f"/api/projects/{project}/lines", json={"id": "L", "points": ["C0", "C1"]})
    client.post(f"/api/projects/{project}/polygons", json={"id": "A", "points": ["C0", "C1",
                                                                                  "C2", "C3"]})
    client.post(f"/api/projects/{project}/polygons", json={"id": "bow", "points": ["C0", "C2",
                                                                                    "C1", "C3"]})
    return e0, n0


def test_export_gpkg(client, project, tmp_path):
    import pyogrio

    e0, n0 = _export_project(client, project)
    r = client.get(f"/api/projects/{project}/export", params={"format": "gpkg"})
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/geopackage+sqlite3"
    assert "attachment" in r.headers["content-disposition"]
    assert "bow" in r.headers["x-gsgeo-skipped"]  # the self-intersecting ring is left out
    path = tmp_path / "out.gpkg"
    path.write_bytes(r.content)
    pts = pyogrio.read_dataframe(path, layer="points")
    assert list(pts["point_id"]) == ["C0", "C1", "C2", "C3"]
    assert pts.crs.to_epsg() == 32630
    assert pts["easting"][1] == pytest.approx(e0 + 20, abs=1e-4)
    lines = pyogrio.read_dataframe(path, layer="lines")
    assert lines["length_2d"][0] == pytest.approx(20.0, abs=1e-3)
    polys = pyogrio.read_dataframe(path, layer="polygons")
    assert list(polys["polygon_id"]) == ["A"]
    assert polys["area_2d"][0] == pytest.approx(200.0, abs=0.01)


def test_export_geojson_and_csv_in_another_crs(client, project):
    _export_project(client, project)
    r = client.get(f"/api/projects/{project}/export", params={"format": "geojson"})
    assert r.status_code == 200 and r.headers["content-type"] == "application/geo+json"
    doc = json.loads(r.content)
    pts = [f for f in doc["features"] if f["properties"].get("point_id") == "C0"]
    assert pts[0]["geometry"]["coordinates"][0] == pytest.approx(LONDON[0], abs=1e-8)
    r = client.get(f"/api/projects/{project}/export", params={"format": "csv", "crs": "EPSG:32631"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    import csv as csvmod

    rows = list(csvmod.DictReader(io.StringIO(r.text)))
    lon, lat = pts[0]["geometry"]["coordinates"][:2]
    e, n = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:32631", always_xy=True).transform(lon, lat)
    assert rows[0]["point_id"] == "C0" and rows[0]["crs"] == "EPSG:32631"
    assert float(rows[0]["easting"]) == pytest.approx(e, abs=1e-4)
    # the stored project is untouched by an export in another CRS
    assert client.get(f"/api/projects/{project}/points/C0").json()["record"]["crs"] == "EPSG:32630"


def test_export_errors(client, project):
    base = f"/api/projects/{project}/export"
    expect_422(client.get(base), "no solved points")
    add_point(client, project, 0)
    expect_422(client.get(base, params={"format": "xls"}), "format")
    expect_422(client.get(base, params={"crs": "EPSG:999999"}), "crs")
    assert client.get("/api/projects/none/export").status_code == 404
    pid = client.post("/api/projects", json={"name": "no grid"}).json()["id"]
    client.post(f"/api/projects/{pid}/points", json={"rays": london_rays(3)})
    expect_422(client.get(f"/api/projects/{pid}/export"), "crs")
    assert client.get(f"/api/projects/{pid}/export",
                      params={"crs": "EPSG:32630", "format": "csv"}).status_code == 200


def test_session_import_is_all_or_nothing(client, project):
    doc = {"crs": "EPSG:27700", "sigma_px": 3.0,  # the project's settings win
           "points": [{"id": "A", "rays": rays_at(ecef_of(*target(0)), 3)},
                      {"id": "B", "code": "x", "rays": rays_at(ecef_of(*target(1)), 4)}],
           "lines": [{"id": "L", "points": ["A", "B"]}]}
    r = client.post(f"/api/projects/{project}/session", json=doc)
    assert r.status_code == 201, r.text
    assert r.json()["imported"] == {"points": 2, "lines": 1, "polygons": 0}
    pts = client.get(f"/api/projects/{project}/points", params={"summary": True}).json()["points"]
    assert [p["id"] for p in pts] == ["A", "B"] and "rays" not in pts[0]
    assert pts[1]["record"]["crs"] == "EPSG:32630" and pts[1]["code"] == "x"
    # a clash or a bad point refuses everything
    x = ecef_of(*LONDON)
    bad = {"points": [{"id": "C", "rays": rays_at(ecef_of(*target(2)), 3)},
                      {"id": "D", "rays": [{"origin": (x + [0, 0, 10 * k]).tolist(),
                                            "direction": [1.0, 0, 0]} for k in range(3)]}]}
    r = client.post(f"/api/projects/{project}/session", json=bad)
    assert r.status_code == 422 and "points[1]" in r.json()["message"]
    r = client.post(f"/api/projects/{project}/session", json={"points": doc["points"][:1]})
    assert r.status_code == 409 and "points[0].id" in r.json()["message"]
    expect_422(client.post(f"/api/projects/{project}/session",
                           json={"points": [{"id": "E", "rays": [{"origin": [1, 2, 3]}]}]}),
               "points[0].rays[0]")
    expect_422(client.post(f"/api/projects/{project}/session",
                           json={"points": [], "lines": [{"id": "M", "points": ["A", "Z"]}]}),
               "lines[0].points[1]")
    assert [p["id"] for p in client.get(f"/api/projects/{project}/points").json()["points"]] == \
        ["A", "B"]


def test_project_with_a_geoid_grid_from_the_data_directory(tmp_path):
    """A geoid named by a project is a file in DATA/geoids; heights become H = h - N."""
    import rasterio
    from rasterio.transform import from_origin

    data = tmp_path / "data"
    (data / "geoids").mkdir(parents=True)
    with rasterio.open(data / "geoids" / "flat47.tif", "w", driver="GTiff", width=40, height=40,
                       count=1, dtype="float32", crs="EPSG:4326",
                       transform=from_origin(-2.0, 53.0, 0.1, 0.1)) as ds:
        ds.write(np.full((1, 40, 40), 47.0, dtype="float32"))
    (tmp_path / "outside.tif").write_bytes(b"x")
    with make_client(data) as c:
        expect_422(c.post("/api/projects", json={"name": "g", "crs": "EPSG:32630",
                                                 "geoid": "nope.tif"}), "geoid")
        expect_422(c.post("/api/projects", json={"name": "g", "crs": "EPSG:32630",
                                                 "geoid": "../../outside.tif"}), "geoid")
        pid = c.post("/api/projects", json={"name": "g", "crs": "EPSG:32630"}).json()["id"]
        c.post(f"/api/projects/{pid}/points", json={"id": "A", "rays": london_rays(4)})
        r = c.patch(f"/api/projects/{pid}", json={"geoid": "flat47.tif"})
        assert r.status_code == 200, r.text
        rec = c.get(f"/api/projects/{pid}/points/A").json()["record"]
        assert rec["height_type"] == "orthometric"
        assert rec["height"] == pytest.approx(LONDON[2] - 47.0, abs=1e-3)
        assert rec["h_wgs84"] == pytest.approx(LONDON[2], abs=1e-3)


def test_geographic_check_points_take_the_measured_points_path(client):
    """WGS 84 check points into OSGB36 go through the same datum operation as the points:
    the exact target compares at zero, whatever operation PROJ would pick on its own."""
    pid = client.post("/api/projects", json={"name": "gb", "crs": "EPSG:27700"}).json()["id"]
    client.post(f"/api/projects/{pid}/points", json={"id": "A", "rays": london_rays(4)})
    client.post(f"/api/projects/{pid}/points",
                json={"id": "B", "rays": rays_at(ecef_of(*target(3)), 4)})
    client.post(f"/api/projects/{pid}/checkpoints", json={"crs": "EPSG:4979", "points": [
        {"id": "A", "x": LONDON[0], "y": LONDON[1], "z": LONDON[2]}]})
    client.post(f"/api/projects/{pid}/checkpoints", json={"crs": "EPSG:4326", "points": [
        {"id": "B", "x": target(3)[0], "y": target(3)[1]}]})
    client.post(f"/api/projects/{pid}/points",
                json={"id": "C", "rays": rays_at(ecef_of(*target(5)), 4)})
    x = ecef_of(*target(5))
    client.post(f"/api/projects/{pid}/checkpoints", json={"crs": "EPSG:4978", "points": [
        {"id": "C", "x": x[0], "y": x[1], "z": x[2]}]})
    acc = client.get(f"/api/projects/{pid}/accuracy").json()
    pts = {p["id"]: p for p in acc["points"]}
    assert abs(pts["A"]["dE"]) < 1e-4 and abs(pts["A"]["dN"]) < 1e-4
    assert abs(pts["A"]["dH"]) < 1e-4
    assert abs(pts["B"]["dE"]) < 1e-4 and pts["B"]["dH"] is None
    assert abs(pts["C"]["dN"]) < 1e-4 and abs(pts["C"]["dH"]) < 1e-4
    assert acc["counts"]["matched"] == 3 and acc["counts"]["matched_vertical"] == 2


def test_resolve_recomputes_from_rays(client, project):
    add_point(client, project, 0)
    before = client.get(f"/api/projects/{project}/points/T0").json()["record"]
    r = client.post(f"/api/projects/{project}/resolve")
    assert r.status_code == 200 and r.json()["settings_rev"] == 1
    assert r.json()["counts"]["n_points"] == 1 and r.json()["counts"]["n_failed"] == 0
    after = client.get(f"/api/projects/{project}/points/T0").json()["record"]
    assert after["easting"] == before["easting"]
    assert client.post("/api/projects/none/resolve").status_code == 404
