"""OGC API parameters are read strictly: numbers are ASCII decimal numbers (no Unicode digits,
underscores, blanks, nan or inf), an empty crs names no CRS, CRS84 longitudes lie within
±180; every refusal is 400 with OGC's exception body. HEAD answers as GET does."""

from __future__ import annotations

import warnings

import pytest
from test_ogc_api import make_project

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.server.app import ServerConfig, create_app

ITEMS = "/ogc/collections/t.points/items"


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    data = tmp_path_factory.mktemp("data")
    make_project(data, n=3)
    with TestClient(create_app(ServerConfig(data_dir=data, allowed_hosts={"testserver"}))) as c:
        yield c


@pytest.mark.parametrize("query", [
    "limit=\u0661\u0660", "limit=1_000", "limit= 10", "limit=10 ", "limit=+5", "limit=",
    "offset=\u0660", "offset=1_0", "offset=0x1",
    "crs=", "crs=%20", "bbox-crs=&bbox=-1,51,1,52",
    "bbox=-181,51,1,52", "bbox=-1,51,180.5,52", "bbox=-1,51,1,\u0665\u0662",
    "bbox=-1,51,1,5_2", "bbox=-1,51,1,nan", "bbox=-1,51,1,inf", "bbox=-1,51,1,1e999",
    "bbox=-1, 51,1,52", "bbox=-1,51,1,52,", "bbox=-1,-91,1,52",
])
def test_a_bad_parameter_is_400_with_the_ogc_exception_body(client, query):
    r = client.get(f"{ITEMS}?{query}")
    assert r.status_code == 400, (query, r.text)
    body = r.json()
    assert body["code"] == "InvalidParameterValue" and body["description"], body


@pytest.mark.parametrize(("query", "n"), [
    ("limit=2", 2), ("limit=02", 2), ("offset=1", 2), ("bbox=-1,51,1,52", 3),
    ("bbox=-1.0e0,5.1E1,.5,52.", 3), ("bbox=179,51,-179,52", 0),  # across the antimeridian
])
def test_good_numbers_still_work(client, query, n):
    r = client.get(f"{ITEMS}?{query}")
    assert r.status_code == 200, r.text
    assert r.json()["numberReturned"] == n


@pytest.mark.parametrize("path", ["/ogc", "/ogc/conformance", "/ogc/collections", "/ogc/api",
                                  "/ogc/collections/t.points", ITEMS, ITEMS + "/P1",
                                  "/ogc/collections/t.points/queryables"])
def test_head_answers_like_get(client, path):
    get, head = client.get(path), client.head(path)
    assert get.status_code == 200, get.text
    assert head.status_code == 200 and head.content == b""
    assert head.headers["content-type"] == get.headers["content-type"]
    assert head.headers.get("etag") == get.headers.get("etag")
