"""LoD2 buildings through the HTTP API: CRUD, following their points, refusals, exports, OGC.

The project holds the gable house of building_helpers (EPSG:27700, noisy rays); the building
is built from the points' current results on every read, so it follows their changes.
"""

from __future__ import annotations

import json
import warnings
from collections import Counter

import numpy as np
import pyogrio
import pytest
from building_helpers import CRS, GROUND, ROOFS, VOLUME, house_points, house_session, truth
from cityjson_helpers import validate_city_json
from georef_helpers import aim
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from servertools import start_server

from gsgeo.export.tables import BUILDING_TYPES
from gsgeo.georef.control import grid_to_ecef
from gsgeo.measure import SolveSettings
from gsgeo.service import open_projects

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from hypothesis_profiles import examples

from gsgeo.server.app import ServerConfig, create_app

HOUSE = {"id": "B1", "roofs": ROOFS, "ground": GROUND, "attributes": {"function": "shed"}}


@pytest.fixture
def data(tmp_path):
    return tmp_path / "data"


@pytest.fixture
def client(data):
    with TestClient(create_app(ServerConfig(data_dir=data, allowed_hosts={"testserver"}))) as c:
        yield c


@pytest.fixture
def pid(client) -> str:
    r = client.post("/api/projects", json={"name": "house", "id": "h", "crs": CRS})
    assert r.status_code == 201, r.text
    for p in house_points():
        r = client.post("/api/projects/h/points", json=p)
        assert r.status_code == 201, r.text
    return "h"


@pytest.fixture
def house(client, pid) -> dict:
    r = client.post(f"/api/projects/{pid}/buildings", json=HOUSE)
    assert r.status_code == 201, r.text
    return r.json()


def vertex(b: dict, pid: str) -> np.ndarray:
    return np.array(b["vertices"][b["vertex_ids"].index(pid)])


def expect(r, status: int, *words: str) -> dict:
    assert r.status_code == status, r.text
    body = r.json()
    for w in words:
        assert w in body["message"], body
    return body


# CRUD ---------------------------------------------------------------------------------------
def test_create_answers_the_model_with_ecef_vertices(client, pid, house):
    b = house
    assert b["id"] == "B1" and b["error"] is None and b["spec"]["roofs"] == ROOFS
    assert b["measures"]["volume"] == pytest.approx(VOLUME, rel=0.02)
    assert b["measures"]["roof_type"] == "gable"
    kinds = Counter(s["kind"] for s in b["surfaces"])
    assert kinds["RoofSurface"] == 2 and kinds["GroundSurface"] == 1
    for q, true in truth().items():
        assert np.linalg.norm(vertex(b, q) - true) < 0.05
    # vertices_ecef: the grid vertices through the project's CRS path, in the same order
    assert len(b["vertices_ecef"]) == len(b["vertices"])
    back = grid_to_ecef(np.array(b["vertices"]), SolveSettings(crs=CRS))
    np.testing.assert_allclose(b["vertices_ecef"], back, atol=1e-3)
    pts = {p["id"]: p for p in client.get(f"/api/projects/{pid}/points").json()["points"]}
    for q in ("E1", "R2"):  # next to the measured point (the adjustment moves it by mm)
        i = b["vertex_ids"].index(q)
        d = np.subtract(b["vertices_ecef"][i], pts[q]["result"]["point_ecef"])
        assert np.linalg.norm(d) < 0.05


def test_list_get_patch_rename_delete(client, pid, house):
    r = client.get(f"/api/projects/{pid}/buildings")
    assert r.status_code == 200 and [b["id"] for b in r.json()["buildings"]] == ["B1"]
    assert client.get(f"/api/projects/{pid}").json()["counts"]["n_buildings"] == 1
    r = client.get(f"/api/projects/{pid}/buildings/B1")
    assert r.status_code == 200 and r.json()["vertices"] == house["vertices"]
    r = client.patch(f"/api/projects/{pid}/buildings/B1",
                     json={"attributes": {"function": "garage"}, "ground": GROUND - 1.0})
    assert r.status_code == 200, r.text
    b = r.json()
    assert b["spec"]["attributes"] == {"function": "garage"} and b["spec"]["roofs"] == ROOFS
    assert b["measures"]["volume"] == pytest.approx(VOLUME + 96.0, rel=0.02)  # 1 m lower ground
    r = client.patch(f"/api/projects/{pid}/buildings/B1", json={"id": "house-1"})
    assert r.status_code == 200 and r.json()["id"] == "house-1"
    expect(client.get(f"/api/projects/{pid}/buildings/B1"), 404, "B1")
    assert client.delete(f"/api/projects/{pid}/buildings/house-1").status_code == 204
    assert client.get(f"/api/projects/{pid}/buildings").json()["buildings"] == []
    expect(client.delete(f"/api/projects/{pid}/buildings/house-1"), 404, "house-1")


def test_an_id_is_given_when_absent_and_a_taken_one_is_409(client, pid, house):
    body = {k: v for k, v in HOUSE.items() if k != "id"}
    r = client.post(f"/api/projects/{pid}/buildings", json=body)
    assert r.status_code == 201 and r.json()["id"] == "B2"
    expect(client.post(f"/api/projects/{pid}/buildings", json=HOUSE), 409, "'B1'")
    expect(client.patch(f"/api/projects/{pid}/buildings/B2", json={"id": "B1"}), 409, "'B1'")


def test_ground_as_a_measured_point(client, pid):
    g = truth()["E1"] - [0.0, 0.0, 6.0]  # a ground point below the first eave corner
    rng = np.random.default_rng(3)
    x = grid_to_ecef(g[None], SolveSettings(crs=CRS))[0]
    r = client.post(f"/api/projects/{pid}/points",
                    json={"id": "G1", "rays": aim(rng, x, x / np.linalg.norm(x), 30.0)})
    assert r.status_code == 201, r.text
    r = client.post(f"/api/projects/{pid}/buildings", json=HOUSE | {"ground": "G1"})
    assert r.status_code == 201, r.text
    assert r.json()["measures"]["volume"] == pytest.approx(VOLUME, rel=0.02)
    expect(client.delete(f"/api/projects/{pid}/points/G1"), 409, "building 'B1'")


# following the points ---------------------------------------------------------------------
def test_the_building_follows_its_points(client, pid, house):
    before = vertex(house, "R1")
    # new rays for both ridge ends, 0.5 m higher: the ridge (and the volume) follows
    rng = np.random.default_rng(11)
    for q in ("R1", "R2"):
        x = grid_to_ecef((truth()[q] + [0, 0, 0.5])[None], SolveSettings(crs=CRS))[0]
        r = client.patch(f"/api/projects/{pid}/points/{q}",
                         json={"rays": aim(rng, x, x / np.linalg.norm(x), 30.0)})
        assert r.status_code == 200, r.text
    b = client.get(f"/api/projects/{pid}/buildings/B1").json()
    assert vertex(b, "R1")[2] - before[2] == pytest.approx(0.5, abs=0.05)
    assert b["measures"]["volume"] == pytest.approx(VOLUME + 12 * 8 * 0.5 / 2, rel=0.02)
    # a ray excluded re-solves the point, and the building with it
    r = client.patch(f"/api/projects/{pid}/points/E1", json={"exclude_ray": 0})
    assert r.status_code == 200
    e1 = np.array([r.json()["record"][k] for k in ("easting", "northing", "height")])
    b2 = client.get(f"/api/projects/{pid}/buildings/B1").json()
    assert np.linalg.norm(vertex(b2, "E1") - e1) < 0.03
    assert vertex(b2, "E1").tolist() != vertex(b, "E1").tolist()
    # another CRS re-measures every point: the building comes out in it
    r = client.patch(f"/api/projects/{pid}", json={"crs": "EPSG:32631"})
    assert r.status_code == 200, r.text
    b3 = client.get(f"/api/projects/{pid}/buildings/B1").json()
    assert b3["error"] is None and vertex(b3, "E1")[0] < 400_000  # UTM 31N eastings
    assert b3["measures"]["volume"] == pytest.approx(b2["measures"]["volume"], rel=0.01)


def test_a_renamed_point_is_renamed_in_the_building(client, pid, house):
    r = client.patch(f"/api/projects/{pid}/points/E1", json={"id": "E1a"})
    assert r.status_code == 200, r.text
    b = client.get(f"/api/projects/{pid}/buildings/B1").json()
    assert b["spec"]["roofs"][0] == ["E1a", "E2", "R2", "R1"] and b["error"] is None


def test_deleting_a_point_a_building_uses_is_409_naming_it(client, pid, house):
    expect(client.delete(f"/api/projects/{pid}/points/R2"), 409, "building 'B1'", "'R2'")
    assert client.get(f"/api/projects/{pid}/points/R2").status_code == 200
    assert client.delete(f"/api/projects/{pid}/buildings/B1").status_code == 204
    assert client.delete(f"/api/projects/{pid}/points/R2").status_code == 204


def test_a_building_its_points_no_longer_build_says_why(client, pid, house):
    # R1 moved 1 m sideways: the north face is no longer a plane within its sigmas
    rng = np.random.default_rng(5)
    x = grid_to_ecef((truth()["R1"] + [0.0, 0.0, 1.5])[None], SolveSettings(crs=CRS))[0]
    client.patch(f"/api/projects/{pid}/points/R1",
                 json={"rays": aim(rng, x, x / np.linalg.norm(x), 30.0)})
    b = client.get(f"/api/projects/{pid}/buildings/B1")
    assert b.status_code == 200
    body = b.json()
    assert body["error"] and body["spec"]["id"] == "B1"
    r = client.get(f"/api/projects/{pid}/export", params={"format": "gpkg"})
    assert r.status_code == 200 and "building B1" in r.headers["x-gsgeo-skipped"]
    expect(client.get(f"/api/projects/{pid}/export", params={"format": "cityjson"}), 422,
           "no buildings")


# refusals ------------------------------------------------------------------------------------
BAD = [
    (HOUSE | {"roofs": [["E1", "E2", "R2", "X9"], ROOFS[1]]}, 422, ["'X9'", "roofs[0][3]"]),
    (HOUSE | {"roofs": [["E1", "E2"], ROOFS[1]]}, 422, ["roofs[0]", "at least 3"]),
    (HOUSE | {"roofs": [["E1", "E2", "E3", "R1"]]}, 422, ["E"]),  # not planar
    ({"id": "B1", "roofs": ROOFS}, 422, ["ground"]),
    (HOUSE | {"ground": "X9"}, 422, ["'X9'", "ground"]),
    (HOUSE | {"ground": {"dtm": "/etc/passwd"}}, 422, ["ground.dtm"]),
    (HOUSE | {"ground": {"dtm": "../gsgeo.sqlite"}}, 422, ["ground.dtm"]),
    (HOUSE | {"ground": [1, 2]}, 422, ["ground"]),
    (HOUSE | {"ground": {"height": 1.0, "point": "E1"}}, 422, ["ground"]),
    (HOUSE | {"regularise": ["square"]}, 422, ["regularise"]),
    (HOUSE | {"attributes": {"volume": 3}}, 422, ["attributes.volume"]),
    (HOUSE | {"colour": "red"}, 422, ["colour"]),
    (HOUSE | {"roofs": [[f"Q{k}-{j}" for j in range(70)] for k in range(3)]}, 422,
     ["at most 200"]),
    (json.dumps(HOUSE | {"attributes": {"note": "\ud800"}}), 422, ["attributes", "Unicode"]),
    (HOUSE | {"attributes": {"n": 2**70}}, 422, ["attributes", "64 bits"]),
    (HOUSE | {"id": "a/b"}, 422, ["id"]),
    ([1, 2, 3], 422, [""]),
]


@pytest.mark.parametrize(("body", "status", "words"), BAD)
def test_bad_buildings_are_refused_naming_the_problem(client, pid, body, status, words):
    kw = ({"content": body, "headers": {"content-type": "application/json"}}
          if isinstance(body, str) else {"json": body})  # a lone surrogate, escaped
    expect(client.post(f"/api/projects/{pid}/buildings", **kw), status, *words)
    assert client.get(f"/api/projects/{pid}/buildings").json()["buildings"] == []


def test_bad_changes_are_refused_and_nothing_is_written(client, pid, house):
    url = f"/api/projects/{pid}/buildings/B1"
    expect(client.patch(url, json={"ground": None}), 422, "ground")
    expect(client.patch(url, json={"colour": "red"}), 422, "colour")
    expect(client.patch(url, json={"roofs": [["E1", "E2", "X9"]]}), 422, "'X9'")
    assert client.get(url).json()["spec"] == house["spec"]
    expect(client.get(f"/api/projects/{pid}/buildings/nope"), 404, "nope")
    expect(client.get("/api/projects/nope/buildings"), 404, "nope")


def test_a_project_without_a_grid_crs_refuses_buildings(client):
    client.post("/api/projects", json={"name": "bare", "id": "bare"})
    for p in house_points():
        assert client.post("/api/projects/bare/points", json=p).status_code == 201
    expect(client.post("/api/projects/bare/buildings", json=HOUSE), 422, "grid CRS")


def test_a_dtm_in_the_data_directory_is_read(client, pid, data):
    rasterio = pytest.importorskip("rasterio")
    from rasterio.transform import from_origin

    (data / "dtm").mkdir()
    e0, n0 = truth()["E1"][:2]
    with rasterio.open(data / "dtm" / "ground.tif", "w", driver="GTiff", width=60, height=60,
                       count=1, dtype="float32", crs=CRS,
                       transform=from_origin(e0 - 30, n0 + 30, 1.0, 1.0)) as ds:
        ds.write(np.full((1, 60, 60), GROUND, dtype="float32"))
    r = client.post(f"/api/projects/{pid}/buildings", json=HOUSE | {"ground": {"dtm": "ground.tif"}})
    assert r.status_code == 201, r.text
    assert r.json()["measures"]["volume"] == pytest.approx(VOLUME, rel=0.02)


# session, exports ---------------------------------------------------------------------------
def test_the_session_carries_buildings_both_ways(client, pid, house):
    doc = client.get(f"/api/projects/{pid}/session").json()
    assert doc["buildings"] == [house["spec"]]
    client.post("/api/projects", json={"name": "copy", "id": "c", "crs": CRS})
    r = client.post("/api/projects/c/session", json=house_session())
    assert r.status_code == 201 and r.json()["imported"]["buildings"] == 1
    assert client.get("/api/projects/c/buildings/B1").json()["error"] is None
    client.post("/api/projects", json={"name": "bad", "id": "d", "crs": CRS})
    bad = house_session(roofs=[["E1", "E2", "X9"]])
    expect(client.post("/api/projects/d/session", json=bad), 422, "buildings[0]", "'X9'")
    assert client.get("/api/projects/d/points").json()["points"] == []  # all or nothing


def test_export_cityjson(client, pid, house):
    r = client.get(f"/api/projects/{pid}/export", params={"format": "cityjson"})
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("application/city+json")
    doc = json.loads(r.content)
    validate_city_json(doc)
    assert [k for k, v in doc["CityObjects"].items() if v["type"] == "Building"] == ["B1"]
    assert doc["metadata"]["referenceSystem"].endswith("/EPSG/0/27700")


def test_export_geopackage_has_the_buildings_layer(client, pid, house, tmp_path):
    r = client.get(f"/api/projects/{pid}/export", params={"format": "gpkg"})
    assert r.status_code == 200, r.text
    path = tmp_path / "h.gpkg"
    path.write_bytes(r.content)
    df = pyogrio.read_dataframe(path, layer="buildings")
    assert list(df.columns[:-1]) == list(BUILDING_TYPES)
    assert len(df) == len(house["surfaces"])
    assert set(df["building_id"]) == {"B1"}
    assert df["volume"].iloc[0] == pytest.approx(house["measures"]["volume"])
    roof = df[df["surface_type"] == "RoofSurface"].geometry
    assert len(roof) == 2 and all(g.has_z for g in roof)


# OGC API ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def ogc_server(tmp_path_factory):
    data = tmp_path_factory.mktemp("bogc") / "data"
    svc = open_projects(data)
    try:
        svc.create_project(name="house", id="h", crs=CRS)
        svc.create_project(name="empty", id="e", crs=CRS)
        for p in house_points():
            svc.add_point("h", p)
            svc.add_point("e", p)
        svc.add_building("h", HOUSE)
    finally:
        svc.store.close()
    proc, base = start_server(data)
    try:
        yield base
    finally:
        proc.terminate()
        proc.wait(10)


def test_gdal_reads_the_buildings_collection(ogc_server):
    layers = {name for name, _ in pyogrio.list_layers(f"OAPIF:{ogc_server}/ogc")}
    assert "h.buildings" in layers and "e.points" in layers
    assert "e.buildings" not in layers  # only while the project has buildings
    df = pyogrio.read_dataframe(f"OAPIF:{ogc_server}/ogc", layer="h.buildings", CRS=CRS)
    assert list(df.columns[1:-1]) == list(BUILDING_TYPES) and df.columns[0] == "id"
    assert Counter(df["surface_type"])["RoofSurface"] == 2
    assert df["volume"].iloc[0] == pytest.approx(VOLUME, rel=0.02)
    roof = df[df["surface_type"] == "RoofSurface"]
    tops = np.array([c for g in roof.geometry for c in g.exterior.coords])
    assert tops[:, 2].max() == pytest.approx(GROUND + 9.0, abs=0.05)
    c84 = pyogrio.read_dataframe(f"OAPIF:{ogc_server}/ogc", layer="h.buildings",
                                 CRS="OGC:CRS84")
    lon, lat = c84.geometry.iloc[0].exterior.coords[0][:2]
    assert 0.0 < lon < 0.2 and 52.1 < lat < 52.3  # Cambridge


def test_export_cityjson_in_another_crs_rebuilds_from_the_rays(client, pid, house):
    r = client.get(f"/api/projects/{pid}/export",
                   params={"format": "cityjson", "crs": "EPSG:32631"})
    assert r.status_code == 200, r.text
    doc = json.loads(r.content)
    validate_city_json(doc)
    assert doc["metadata"]["referenceSystem"].endswith("/EPSG/0/32631")
    b = doc["CityObjects"]["B1"]["attributes"]
    assert b["volume"] == pytest.approx(VOLUME, rel=0.02)
    assert doc["transform"]["translate"][0] < 400_000  # UTM 31N eastings
    # the project itself stays in its grid
    assert client.get(f"/api/projects/{pid}/buildings/B1").json()["vertices"] == house["vertices"]


def test_formats_without_buildings_do_not_report_them_skipped(client, pid, house):
    rng = np.random.default_rng(5)
    x = grid_to_ecef((truth()["R1"] + [0.0, 0.0, 1.5])[None], SolveSettings(crs=CRS))[0]
    client.patch(f"/api/projects/{pid}/points/R1",
                 json={"rays": aim(rng, x, x / np.linalg.norm(x), 30.0)})
    r = client.get(f"/api/projects/{pid}/export", params={"format": "csv"})
    assert r.status_code == 200 and "x-gsgeo-skipped" not in r.headers


def test_the_building_follows_a_georeference_change_of_its_scene(tmp_path):
    """A scene's georeference applied outside the store (as `gsgeo georef --apply` on a
    session does): the next read re-measures the points, and the building moves with them."""
    from gsgeo.tiles.georefhistory import apply_similarity

    data = tmp_path / "data"
    scene = data / "scenes" / "site"
    scene.mkdir(parents=True)
    x0 = grid_to_ecef(truth()["E1"][None], SolveSettings(crs=CRS))[0]
    root = np.eye(4)
    root[:3, 3] = x0
    (scene / "tileset.json").write_text(json.dumps(
        {"asset": {"version": "1.1"}, "geometricError": 10,
         "root": {"transform": root.T.reshape(-1).tolist(), "geometricError": 10,
                  "boundingVolume": {"box": [0, 0, 0, 20, 0, 0, 0, 20, 0, 0, 0, 20]}}}))
    with TestClient(create_app(ServerConfig(data_dir=data, allowed_hosts={"testserver"}))) as c:
        r = c.post("/api/projects", json={"name": "s", "id": "s", "scene": "site", "crs": CRS})
        assert r.status_code == 201, r.text
        for p in house_points():
            assert c.post("/api/projects/s/points", json=p).status_code == 201
        before = c.post("/api/projects/s/buildings", json=HOUSE).json()
        up = x0 / np.linalg.norm(x0)
        lift = np.eye(4)
        lift[:3, 3] = 2.0 * up  # the whole scene 2 m higher
        apply_similarity(scene, lift, kind="test", frame_covariance=None, summary=None)
        after = c.get("/api/projects/s/buildings/B1").json()
    assert after["error"] is None
    dh = np.array(after["vertices"])[:, 2] - np.array(before["vertices"])[:, 2]
    assert np.allclose(dh[:6], 2.0, atol=0.01)  # the roof vertices
    assert after["measures"]["volume"] == pytest.approx(VOLUME + 96 * 2.0, rel=0.02)


# fuzz: whatever a building names, the answer is a model or a 4xx naming the problem ----------
@pytest.fixture(scope="module")
def fuzz_client(tmp_path_factory):
    data = tmp_path_factory.mktemp("bfuzz") / "data"
    with TestClient(create_app(ServerConfig(data_dir=data, allowed_hosts={"testserver"}))) as c:
        c.post("/api/projects", json={"name": "fuzz", "id": "f", "crs": CRS})
        for p in house_points():
            assert c.post("/api/projects/f/points", json=p).status_code == 201
        yield c


IDS = ["E1", "E2", "E3", "E4", "R1", "R2", "X9"]


@settings(max_examples=examples(60), deadline=None, suppress_health_check=list(HealthCheck))
@given(roofs=st.lists(st.lists(st.sampled_from(IDS), min_size=0, max_size=6), min_size=0,
                      max_size=4),
       ground=st.one_of(st.floats(allow_nan=False, allow_infinity=False),
                        st.sampled_from(IDS),
                        st.fixed_dictionaries({"height": st.floats(-1e3, 1e3),
                                               "sigma": st.floats(0, 1e300)}),
                        st.just({"dtm": "none.tif"})),
       regularise=st.lists(st.sampled_from(["horizontal_eaves", "rectangular"]), max_size=2,
                           unique=True))
def test_any_building_is_a_model_or_a_named_refusal(fuzz_client, roofs, ground, regularise):
    body = {"id": "F", "roofs": roofs, "ground": ground, "regularise": regularise}
    r = fuzz_client.post("/api/projects/f/buildings", json=body)
    assert r.status_code in (201, 422), r.text
    if r.status_code == 201:
        assert fuzz_client.delete("/api/projects/f/buildings/F").status_code == 204
    else:
        assert r.json()["message"]
