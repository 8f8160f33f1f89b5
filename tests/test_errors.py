"""Structured errors: the field a problem is about travels as data (``GsgeoError.field``),
and the API's 422 ``field`` and the CLI's message are read from it, not parsed from text."""

from __future__ import annotations

import copy
import json
import pickle
import warnings

import pytest
from servertools import LONDON, ecef_of, london_rays, rays_at

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.cli import main
from gsgeo.errors import CRSError, GeometryError, InputError, join_field
from gsgeo.server.app import ServerConfig, create_app
from gsgeo.session import parse_point, parse_session


# the error type -------------------------------------------------------------------------------
def test_field_and_problem_are_data_and_str_reads_as_before():
    e = InputError("is a zero vector", field="rays[1].direction")
    assert (e.field, e.problem, str(e)) == ("rays[1].direction", "is a zero vector",
                                            "rays[1].direction: is a zero vector")
    assert str(InputError("no field")) == "no field" and InputError("x").field is None


@pytest.mark.parametrize(("parent", "child", "joined"), [
    ("points[0]", "rays[2].direction", "points[0].rays[2].direction"),
    ("rays", "[1].origin", "rays[1].origin"),
    ("points[0]", None, "points[0]"),
    ("", "id", "id"),
    (None, None, None),
])
def test_join_field(parent, child, joined):
    assert join_field(parent, child) == joined


def test_within_prefixes_the_parent_path_and_keeps_the_type():
    e = GeometryError("rays are parallel", field="rays")
    w = e.within("points[3]")
    assert type(w) is GeometryError and w.field == "points[3].rays"
    assert str(w) == "points[3].rays: rays are parallel"
    assert e.field == "rays"  # the original is unchanged
    assert CRSError("unknown").within("crs").field == "crs"


def test_part_of_and_in_source():
    e = InputError("missing", field="line 3, column x").part_of("file", "'cp.csv'")
    assert e.field == "file" and str(e) == "file: 'cp.csv': line 3, column x: missing"
    s = InputError("expected text", field="points[0].id").in_source("s.json")
    assert (s.source, s.field, str(s)) == ("s.json", "points[0].id",
                                           "s.json: points[0].id: expected text")


def test_field_survives_pickle_and_copy():
    e = InputError("bad", field="rays[0]").in_source("f.json")
    for back in (pickle.loads(pickle.dumps(e)), copy.copy(e), copy.deepcopy(e)):
        assert type(back) is InputError and str(back) == str(e) and back.field == "rays[0]"


# parsing names the field as data --------------------------------------------------------------
def test_session_parsing_carries_the_json_path():
    doc = {"points": [{"id": "P1", "rays": london_rays(2)},
                      {"id": "P2", "rays": [london_rays(2)[0],
                                            {"origin": [1, 2, 3], "direction": [0, 0, 0]}]}]}
    with pytest.raises(InputError) as info:
        parse_session(doc)
    assert info.value.field == "points[1].rays[1].direction"
    assert info.value.problem == "is a zero vector"


def test_a_point_parsed_on_its_own_names_members_alone():
    with pytest.raises(InputError) as info:
        parse_point({"id": "x", "rays": [{"origin": [1, 2, "z"], "direction": [1, 0, 0]}]},
                    field="")
    assert info.value.field == "rays[0].origin[2]"


# the API reads the field from the exception ---------------------------------------------------
@pytest.fixture
def client(tmp_path):
    app = create_app(ServerConfig(data_dir=tmp_path / "data", allowed_hosts={"testserver"}))
    with TestClient(app) as c:
        yield c


@pytest.fixture
def project(client) -> str:
    r = client.post("/api/projects", json={"name": "London", "crs": "EPSG:32630"})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def test_intersect_error_of_the_georeferencing_names_its_ray(client):
    """The model_matrix moves the first ray's origin out of range: the 422 says which ray
    (the message used to start with the point's id, and the field was empty)."""
    mm = [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 1e300, 0, 0, 1.0]
    rays = [dict(r, model_matrix=mm) for r in london_rays(2)]
    r = client.post("/api/intersect", json={"rays": rays})
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["field"] == "rays[0].origin"
    assert body["message"].startswith("rays[0].origin: ") and "out of range" in body["message"]


def test_session_import_of_an_unsolvable_point_names_the_point_as_field(client, project):
    x = ecef_of(*LONDON)
    parallel = [{"origin": (x + [0, 0, 10 * k]).tolist(), "direction": [1.0, 0, 0]}
                for k in range(3)]
    good = rays_at(ecef_of(LONDON[0], LONDON[1], 50.0), 3)
    doc = {"points": [{"id": "C", "rays": good}, {"id": "D", "rays": parallel}]}
    r = client.post(f"/api/projects/{project}/session", json=doc)
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["field"] == "points[1]"
    assert body["message"].startswith("points[1]: point 'D': ") and "parallel" in body["message"]
    assert client.get(f"/api/projects/{project}/points").json()["points"] == []


def test_conflict_and_nested_feature_errors_carry_their_field(client, project):
    pts = {"points": [{"id": "A", "rays": rays_at(ecef_of(*LONDON), 3)}]}
    assert client.post(f"/api/projects/{project}/session", json=pts).status_code == 201
    r = client.post(f"/api/projects/{project}/session", json=pts)
    assert r.status_code == 409 and r.json()["field"] == "points[0].id"
    r = client.post(f"/api/projects/{project}/session",
                    json={"points": [], "lines": [{"id": "M", "points": ["A", "Z"]}]})
    assert r.status_code == 422 and r.json()["field"] == "lines[0].points[1]"


def test_import_and_export_errors_name_their_request_field(client, project):
    """A file that cannot be read is about the field ``file`` (where in the file is in the
    message); an unknown export format is about ``format``."""
    r = client.post(f"/api/projects/{project}/checkpoints/import",
                    files={"file": ("cp.gpkg", b"not:sqlite")}, data={"crs": "EPSG:32630"})
    assert r.status_code == 422 and r.json()["field"] == "file"
    r = client.get(f"/api/projects/{project}/export", params={"format": "x:y"})
    assert r.status_code == 422 and r.json()["field"] == "format"


# the CLI ---------------------------------------------------------------------------------------
def test_cli_names_file_and_json_path(tmp_path, capsys):
    f = tmp_path / "s.json"
    f.write_text(json.dumps({"points": [{"id": "P1", "rays": [
        {"origin": [1, 2, 3], "direction": [1, 0, 0]}, {"origin": [1, 2, 3]}]}]}))
    assert main(["solve", str(f)]) == 2
    err = capsys.readouterr().err
    assert err.strip() == f"gsgeo solve: error: {f}: points[0].rays[1]: missing 'direction'"


def test_an_unparsable_body_is_about_the_field_body(client):
    r = client.post("/api/intersect", content=b'{"rays": "\xff\xfe"}',
                    headers={"content-type": "application/json"})
    assert r.status_code == 422
    assert r.json()["field"] == "body" and r.json()["message"].startswith("body: cannot be parsed")


def test_an_unknown_vertical_crs_is_about_vertical_not_crs(client, project):
    """The field used to be guessed from the word 'vertical' in PROJ's message; an unknown
    vertical code (whose message does not say 'vertical') was blamed on ``crs``."""
    r = client.post("/api/projects", json={"name": "x", "crs": "EPSG:32630",
                                           "vertical": "EPSG:999999"})
    assert r.status_code == 422
    assert r.json()["field"] == "vertical" and r.json()["message"].startswith("vertical: unknown")
    r = client.patch(f"/api/projects/{project}", json={"vertical": "nonsense"})
    assert r.status_code == 422 and r.json()["field"] == "vertical"
    r = client.post("/api/projects", json={"name": "x", "crs": "nonsense", "vertical": "EPSG:5701"})
    assert r.status_code == 422 and r.json()["field"] == "crs"


def test_ifov_on_some_rays_only_names_the_first_ray_without(client):
    rays = london_rays(3, ifov=1e-3)
    del rays[1]["ifov"]
    r = client.post("/api/intersect", json={"rays": rays})
    assert r.status_code == 422
    assert r.json()["field"] == "rays[1].ifov" and "no ifov" in r.json()["message"]
