"""The one rule for text at the HTTP edge: no text anywhere in a request may hold a NUL
character or an unpaired surrogate (gsgeo.limits.text_problem). Such text is 4xx naming the
problem, never a 500, on every route and on both stores, and nothing is stored.

The routes are walked from the app itself (its OpenAPI paths and the OGC router), so a new
route is covered without being listed here.
"""

from __future__ import annotations

import json
import warnings
from urllib.parse import quote

import pytest
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)
from servertools import london_rays

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.server.app import ServerConfig, create_app
from gsgeo.server.ogc import router as ogc_router


def _api_routes() -> list[tuple[str, str, list[str], list[str], str | None]]:
    """(method, path, path params, query params, body media type) of every API route."""
    app = create_app(ServerConfig(data_dir=__import__("tempfile").mkdtemp()))
    out = []
    for path, ops in app.openapi()["paths"].items():
        for method, op in ops.items():
            params = op.get("parameters", [])
            body = next(iter(op.get("requestBody", {}).get("content", {})), None)
            out.append((method.upper(), path, [p["name"] for p in params if p["in"] == "path"],
                        [p["name"] for p in params if p["in"] == "query"], body))
    for r in ogc_router.routes:
        path = r.path.replace(":path}", "}")
        names = [s[1:-1] for s in path.split("/") if s.startswith("{")]
        out.append(("GET", path, names, ["f", "crs", "bbox", "limit", "datetime", "code"]
                    if path.endswith("/items") else ["f"], None))
    return out


ROUTES = _api_routes()
JSON_ROUTES = [(m, p) for m, p, _, _, body in ROUTES if body == "application/json"]
#: valid values of the path parameters: the fixture project and its items
GOOD = {"pid": "p", "point_id": "P1", "fid": "L1", "bid": "B1", "cid": "C1", "scene": "s",
        "collection_id": "p.points", "feature_id": "P1"}


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def client(request, tmp_path_factory):
    url = None
    if request.param == "postgresql":
        cluster = request.getfixturevalue("pg_cluster")
        url = cluster.url(cluster.new_database())
    app = create_app(ServerConfig(data_dir=tmp_path_factory.mktemp("data"),
                                  allowed_hosts={"testserver"}, store_url=url))
    with TestClient(app, raise_server_exceptions=False) as c:
        assert c.post("/api/projects", json={"name": "p", "id": "p",
                                             "crs": "EPSG:27700"}).status_code == 201
        for k in (1, 2):
            assert c.post("/api/projects/p/points",
                          json={"id": f"P{k}", "rays": london_rays(3 + k)}).status_code == 201
        assert c.post("/api/projects/p/lines", json={"id": "L1", "points": ["P1", "P2"]}
                      ).status_code == 201
        yield c


def stored(c: TestClient) -> tuple:
    pts = c.get("/api/projects/p/points").json()["points"]
    return ([(q["id"], q["code"], q["description"]) for q in pts],
            c.get("/api/projects").json()["projects"][0]["name"],
            c.get("/api/projects/p/checkpoints").json())


def session_with(**point: str) -> str:
    """A valid session document as JSON text whose first point has ``point``'s members; the
    values are JSON text (escapes such as \\ud800 stay escapes)."""
    doc = json.dumps({"points": [{"id": "N1", "rays": london_rays(3)}]})
    extra = "".join(f', "{k}": "{v}"' for k, v in point.items())
    return doc.replace('"id": "N1"', '"id": "N1"' + extra, 1)


@pytest.mark.parametrize(("member", "value", "words"), [
    ("description", "\\ud800", ["U+D800", "Unicode"]),
    ("code", "x\\udfff", ["U+DFFF"]),
    ("code", "a\\u0000b", ["NUL character"]),
    ("description", "\\u00e9t\\u00e9 \\ud83d\\ude00", None),  # a real pair: fine
])
def test_a_session_import_with_bad_text_is_422_and_stores_nothing(client, member, value, words):
    before = stored(client)
    r = client.post("/api/projects/p/session", content=session_with(**{member: value}),
                    headers={"content-type": "application/json"})
    if words is None:
        assert r.status_code == 201, r.text
        pts = client.get("/api/projects/p/points/N1").json()
        assert pts[member] == "\u00e9t\u00e9 \U0001F600"
        assert client.delete("/api/projects/p/points/N1").status_code == 204
        return
    assert r.status_code == 422, r.text
    assert r.json()["field"] == f"points[0].{member}"
    for w in words:
        assert w in r.json()["message"]
    assert stored(client) == before


@pytest.mark.parametrize(("method", "path"), JSON_ROUTES)
def test_every_json_body_with_bad_text_is_422_naming_where(client, method, path):
    url = path.format(**GOOD)
    for text, word in (("\\ud800", "U+D800"), ("a\\u0000", "U+0000")):
        body = '{"x": [1, {"y": "' + text + '"}], "rays": []}'
        r = client.request(method, url, content=body,
                           headers={"content-type": "application/json"})
        assert r.status_code == 422, (url, r.text)
        assert r.json()["field"] == "x[1].y" and word in r.json()["message"], r.text
        # a bad object key is named too
        r = client.request(method, url, content='{"k' + text + '": 1}',
                           headers={"content-type": "application/json"})
        assert r.status_code == 422 and word in r.json()["message"], r.text


@pytest.mark.parametrize(("method", "path", "path_params", "query"),
                         [(m, p, pp, q) for m, p, pp, q, _ in ROUTES])
def test_bad_text_in_the_url_is_never_a_500(client, method, path, path_params, query):
    before = stored(client)
    bad = ["a\x00b", "\udcff"]  # NUL; a lone surrogate (as the URL's invalid UTF-8 arrives)
    cases = [path.format(**(GOOD | {name: quote(b.encode("utf-8", "surrogateescape"))}))
             for name in path_params for b in bad]
    base = path.format(**GOOD)
    cases += [f"{base}?{q}={quote(b.encode('utf-8', 'surrogateescape'))}"
              for q in query for b in bad]
    for url in cases or [base]:
        r = client.request(method, url)
        assert r.status_code < 500, (method, url, r.text)
    if method == "GET":
        assert stored(client) == before


@pytest.mark.parametrize("value", ["a\x00b", "EPSG:27700\x00"])
def test_a_bad_crs_form_field_is_422(client, value):
    before = stored(client)
    r = client.post("/api/projects/p/checkpoints/import", data={"crs": value},
                    files={"file": ("c.csv", b"id,x,y\nC9,530000,180000\n")})
    assert r.status_code == 422, r.text
    assert "NUL" in r.json()["message"]
    assert stored(client) == before


def test_if_match_with_non_ascii_or_bad_text_is_4xx(client):
    for tag in (b'"\xff"', b'"\xe9\x00"', b"W/\x01", b'"9\xa0"'):
        r = client.patch("/api/projects/p/points/P1", json={"code": "k"},
                         headers={"If-Match": tag})
        assert 400 <= r.status_code < 500, (tag, r.text)
    assert client.get("/api/projects/p/points/P1").json()["code"] == ""
