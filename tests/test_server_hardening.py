"""`gsgeo serve` as an attacker or a careless user meets it, over real HTTP.

Linked scene folders that leave the scenes root, the store's files, files of the web
directory that are not the app, malformed check-point files, body limits chosen by the
route, methods a path does not serve, the token on /scenes, and loopback decided on
resolved addresses.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx
import pytest
import uvicorn
from servertools import REPO, free_port, start_server

from gsgeo.commands.serve import resolve_token
from gsgeo.server.app import ServerConfig, create_app
from gsgeo.server.hosts import is_loopback
from gsgeo.store import DB_NAME

SQLITE_MAGIC = b"SQLite format 3\x00"
TILESET = json.dumps({"asset": {"version": "1.1"}, "root": {"geometricError": 0}})


@contextmanager
def serving(app) -> Iterator[str]:
    """``app`` served by uvicorn on a free loopback port in this process; yields the URL."""
    port = free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port,
                                           log_level="warning", timeout_keep_alive=30))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        assert thread.is_alive() and time.monotonic() < deadline, "uvicorn did not start"
        time.sleep(0.02)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(15)


def make_scene(folder: Path) -> Path:
    (folder / "tiles").mkdir(parents=True)
    (folder / "tileset.json").write_text(TILESET)
    (folder / "tiles" / "0.glb").write_bytes(b"glTF" + bytes(100))
    return folder


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Iterator[tuple[str, Path]]:
    """`gsgeo serve` over a data directory laid out to tempt it: a scene, a linked scene
    folder pointing back at the data directory, one pointing outside the scenes root, and
    hard links to the store's files inside a real scene."""
    tmp = tmp_path_factory.mktemp("hardening")
    data = tmp / "data"
    scene = make_scene(data / "scenes" / "site")
    (data / "scenes" / "escape").symlink_to(data)
    (data / "scenes" / "up").symlink_to(data / "scenes")
    outside = make_scene(tmp / "elsewhere")
    (outside / "secret.txt").write_text("confidential")
    (data / "scenes" / "away").symlink_to(outside)
    proc, base = start_server(data)
    httpx.post(f"{base}/api/projects", json={"name": "p", "id": "p"}).raise_for_status()
    for suffix in ("", "-wal", "-shm"):  # the store exists now: link its files into the scene
        if (data / f"{DB_NAME}{suffix}").exists():
            os.link(data / f"{DB_NAME}{suffix}", scene / f"db{suffix or '-main'}.glb")
    yield base, data
    proc.terminate()
    proc.wait(10)


# 1. linked scene folders and the store's files ---------------------------------------------
@pytest.mark.parametrize("path", [
    f"/scenes/escape/{DB_NAME}",
    f"/scenes/escape/{DB_NAME}-wal",
    "/scenes/escape/scenes/site/tileset.json",
    "/scenes/up/site/tileset.json",
    "/scenes/away/tileset.json",
    "/scenes/away/secret.txt",
    "/scenes/site/db-main.glb",
    "/scenes/site/db-wal.glb",
])
def test_no_link_leads_out_of_the_scenes_root_or_to_the_store(site, path):
    base, _ = site
    r = httpx.get(base + path)
    assert r.status_code == 404, (path, r.status_code)
    assert SQLITE_MAGIC not in r.content and b"confidential" not in r.content


def test_real_scenes_are_served_and_only_they_are_listed(site):
    base, _ = site
    r = httpx.get(f"{base}/scenes/site/tiles/0.glb")
    assert r.status_code == 200 and r.content.startswith(b"glTF")
    names = [s["name"] for s in httpx.get(f"{base}/api/scenes").json()["scenes"]]
    assert names == ["site"]


def test_a_scenes_root_enclosing_the_data_directory_serves_nothing(tmp_path):
    data = tmp_path / "data"
    make_scene(tmp_path / "other")
    data.mkdir()
    (data / "scenes").symlink_to(tmp_path)  # the scenes root would hold the store itself
    with serving(create_app(ServerConfig(data_dir=data))) as base:
        assert httpx.get(f"{base}/scenes/data/{DB_NAME}").status_code == 404
        assert httpx.get(f"{base}/scenes/other/tileset.json").status_code == 404
        assert httpx.get(f"{base}/api/scenes").json()["scenes"] == []


# 6. only the app of the web directory ---------------------------------------------------------
@pytest.mark.parametrize("path", ["/package.json", "/package-lock.json",
                                  "/node_modules/cesium/package.json",
                                  "/node_modules/cesium/Build/Cesium/Cesium.js", "/README.md"])
def test_web_directory_serves_only_the_app(site, path):
    base, _ = site
    assert (REPO / "web" / "package.json").is_file()
    assert httpx.get(base + path).status_code == 404


@pytest.mark.parametrize("path", ["/", "/index.html", "/style.css", "/favicon.svg",
                                  "/js/main.js", "/js/api.js"])
def test_the_app_itself_is_served(site, path):
    base, _ = site
    assert httpx.get(base + path).status_code == 200


# 7. 405 with Allow ----------------------------------------------------------------------------
@pytest.mark.parametrize("method, path, allow", [
    ("GET", "/api/intersect", "POST"),
    ("DELETE", "/api/intersect", "POST"),
    ("PUT", "/api/projects/p", "GET, PATCH, DELETE"),
    ("POST", "/api/projects/p/checkpoints/P1", "DELETE"),
    ("POST", "/", "GET, HEAD"),
    ("DELETE", "/scenes/site/tileset.json", "GET, HEAD"),
])
def test_wrong_method_is_405_with_allow(site, method, path, allow):
    base, _ = site
    r = httpx.request(method, base + path)
    assert r.status_code == 405, (method, path, r.status_code)
    assert r.headers["allow"] == allow
    assert allow in r.json()["message"]


# 2. malformed check-point files: 4xx naming the file, the connection kept ------------------
BAD_FILES = [
    ("huge-field.csv", b"id,x,y\nA,1," + b"9" * 200_000 + b"\n", "longer than"),
    ("deep.geojson", b"[" * 100_000 + b"]" * 100_000, "depth"),
    ("overflow.geojson", b'{"type": "FeatureCollection", "features": [{"type": "Feature", '
                         b'"properties": {"id": "A"}, "geometry": {"type": "Point", '
                         b'"coordinates": [1' + b"0" * 309 + b', 2]}}]}', "number"),
    ("digits.geojson", b'{"type": "Feature", "properties": {"id": 1' + b"0" * 5000
                       + b'}, "geometry": {"type": "Point", "coordinates": [1, 2]}}', "number"),
    ("vrt.gpkg", b"<OGRVRTDataSource><OGRVRTLayer name='x'><SrcDataSource>/etc/passwd"
                 b"</SrcDataSource></OGRVRTLayer></OGRVRTDataSource>", "SQLite"),
]


@pytest.mark.parametrize("name, content, problem", BAD_FILES)
def test_malformed_check_point_files_are_4xx_and_keep_the_connection(site, name, content,
                                                                     problem):
    base, _ = site
    url = f"{base}/api/projects/p/checkpoints"
    with httpx.Client(timeout=30) as h:
        h.post(url, json={"crs": "EPSG:32630", "replace": True,
                          "points": [{"id": "K1", "x": 1, "y": 2, "z": 3}]}).raise_for_status()
        before = h.get(url).json()
        r = h.post(f"{url}/import", files={"file": (name, content)},
                   data={"crs": "EPSG:32630", "replace": "true"})
        assert r.status_code == 422, r.text
        msg = r.json()["message"]
        assert name in msg and problem in msg, msg
        assert r.headers.get("connection", "").lower() != "close"
        after = h.get(url)  # the same keep-alive connection
        assert after.status_code == 200 and after.json() == before


# 3. body limit by route -----------------------------------------------------------------------
def test_body_limit_follows_the_route_not_the_path_suffix(tmp_path):
    cfg = ServerConfig(data_dir=tmp_path / "data", max_body=10_000, max_upload=200_000)
    big_json = json.dumps({"name": "x", "description": "a" * 50_000}).encode()
    with serving(create_app(cfg)) as base, httpx.Client(base_url=base, timeout=30) as h:
        h.post("/api/projects", json={"name": "P", "id": "P"}).raise_for_status()
        # (method, path, status when the body streams without Content-Length: 413 where the
        # route reads it, 405 where no route takes the method and the body is never read)
        for method, path, streamed in [("PATCH", "/api/projects/P/points/import", 413),
                                       ("PATCH", "/api/projects/import", 413),
                                       ("PATCH", "/api/projects/P", 413),
                                       ("PUT", "/api/projects/P/checkpoints/import", 405)]:
            r = h.request(method, path, content=big_json,
                          headers={"content-type": "application/json"})
            assert r.status_code == 413, (method, path, r.status_code)

            def chunks():
                for k in range(0, len(big_json), 4096):
                    yield big_json[k:k + 4096]

            r = h.request(method, path, content=chunks(),
                          headers={"content-type": "application/json"})
            assert r.status_code == streamed, (method, path, "chunked", r.status_code)
        assert h.get("/api/projects/P").json()["description"] == ""
        # the upload route itself takes files over the JSON limit
        rows = "".join(f"C{k},{k}.5,{k}.25\n" for k in range(3000)).encode()
        assert 10_000 < len(rows) < 200_000
        r = h.post("/api/projects/P/checkpoints/import",
                   files={"file": ("many.csv", b"id,x,y\n" + rows)}, data={"crs": "EPSG:32630"})
        assert r.status_code == 201 and r.json()["imported"] == 3000


# an unexpected exception ----------------------------------------------------------------------
def test_unexpected_exception_is_a_logged_500_that_closes_cleanly(tmp_path, caplog):
    app = create_app(ServerConfig(data_dir=tmp_path / "data"))

    def boom() -> None:
        raise RuntimeError("secret detail from deep inside")

    app.add_api_route("/api/boom", boom, methods=["GET"])
    app.router.routes.insert(0, app.router.routes.pop())  # first, before any catch-all route

    with caplog.at_level(logging.ERROR, logger="gsgeo.server"), serving(app) as base, \
            httpx.Client(base_url=base, timeout=30) as h:
        r = h.get("/api/boom")
        assert r.status_code == 500
        assert r.headers["connection"] == "close"
        assert r.headers["content-type"] == "application/json"
        body = r.json()
        assert "RuntimeError" in body["message"] and "secret detail" not in body["message"]
        for _ in range(3):  # the server goes on serving, on a fresh connection
            assert h.get("/api/info").status_code == 200
        assert h.get("/api/boom").status_code == 500
        assert h.get("/api/projects").status_code == 200
    logged = [rec for rec in caplog.records if rec.name == "gsgeo.server" and rec.exc_info]
    assert logged and "secret detail" in str(logged[0].exc_info[1])


# 5. the token on /scenes ----------------------------------------------------------------------
@pytest.fixture
def guarded(tmp_path) -> Iterator[tuple[str, str]]:
    """The app as configured off loopback (any Host, a token), served over HTTP."""
    data = tmp_path / "data"
    make_scene(data / "scenes" / "site")
    cfg = ServerConfig(data_dir=data, host="0.0.0.0", token="s3cret;tok")
    assert cfg.allowed_hosts is None
    with serving(create_app(cfg)) as base:
        yield base, "s3cret;tok"


def test_scenes_need_the_token_off_loopback(guarded):
    base, token = guarded
    tile = f"{base}/scenes/site/tiles/0.glb"
    r = httpx.get(tile)
    assert r.status_code == 401 and "token" in r.json()["message"]
    assert b"glTF" not in r.content
    assert httpx.get(f"{base}/scenes/nope/tileset.json").status_code == 401  # no probing
    assert httpx.get(tile, headers={"Authorization": "Bearer wrong"}).status_code == 401
    assert httpx.get(tile, headers={"Cookie": "gsgeo-token-80=wrong"}).status_code == 401
    assert httpx.get(tile, headers={"Cookie": "other=s3cret%3Btok"}).status_code == 401
    r = httpx.get(tile, headers={"Authorization": f"Bearer {token}"})
    assert r.status_code == 200 and r.content.startswith(b"glTF")
    port = base.rsplit(":", 1)[1]
    r = httpx.get(tile, headers={"Cookie": f"a=b; gsgeo-token-{port}=s3cret%3Btok"})
    assert r.status_code == 200 and r.content.startswith(b"glTF")


def test_api_takes_the_header_and_not_the_cookie(guarded):
    base, token = guarded
    url = f"{base}/api/projects"
    assert httpx.get(url).status_code == 401
    assert httpx.get(url, headers={"Cookie": "gsgeo-token=s3cret%3Btok"}).status_code == 401
    r = httpx.post(url, json={"name": "x"}, headers={"Cookie": "gsgeo-token=s3cret%3Btok"})
    assert r.status_code == 401
    assert httpx.get(url, headers={"Authorization": f"Bearer {token}"}).status_code == 200
    for path in ("/", "/js/api.js", "/style.css"):  # the page loads, then asks for the token
        assert httpx.get(base + path).status_code == 200


def test_viewer_sets_the_scene_cookie_from_the_token():
    """web/js/api.js keeps the token of #token= and sets it as the /scenes cookie."""
    src = (REPO / "web" / "js" / "api.js").read_text()
    assert "SameSite=Strict" in src and "path=/" in src and "document.cookie" in src


def test_live_server_with_a_token_guards_scenes(tmp_path):
    data = tmp_path / "data"
    make_scene(data / "scenes" / "site")
    proc, base = start_server(data, env={"GSGEO_TOKEN": "tok-456"})
    try:
        assert httpx.get(f"{base}/scenes/site/tileset.json").status_code == 401
        port = base.rsplit(":", 1)[1]
        r = httpx.get(f"{base}/scenes/site/tileset.json",
                      headers={"Cookie": f"gsgeo-token-{port}=tok-456"})
        assert r.status_code == 200 and r.json()["asset"]["version"] == "1.1"
    finally:
        proc.terminate()
        proc.wait(10)


# 4. loopback by resolved addresses ----------------------------------------------------------
def fake_resolver(table: dict[str, list[str]]):
    def getaddrinfo(host, *args, **kwargs):
        if host not in table:
            raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")
        return [(socket.AF_INET6 if ":" in a else socket.AF_INET, socket.SOCK_STREAM, 6, "",
                 (a, 0)) for a in table[host]]
    return getaddrinfo


def test_loopback_is_decided_on_resolved_addresses(monkeypatch):
    monkeypatch.setattr(socket, "getaddrinfo", fake_resolver({
        "localhost": ["127.0.0.1", "::1"], "box.lan": ["127.0.1.1"],
        "mixed.example": ["127.0.0.1", "10.1.2.3"], "127.evil.example": ["203.0.113.7"]}))
    assert is_loopback("127.0.0.1") and is_loopback("127.5.6.7") and is_loopback("::1")
    assert is_loopback("[::1]") and is_loopback("localhost") and is_loopback("box.lan")
    assert is_loopback("::ffff:127.0.0.1")
    for host in ("127.evil.example", "mixed.example", "127.nowhere.invalid", "0.0.0.0", "::",
                 "", "10.0.0.1"):
        assert not is_loopback(host), host
        token, generated = resolve_token(host, {})
        assert generated and token, host
    assert resolve_token("localhost", {}) == (None, False)
    assert ServerConfig(data_dir="x", host="127.evil.example").allowed_hosts is None


def test_serve_refuses_a_host_that_does_not_resolve(tmp_path):
    r = subprocess.run([sys.executable, "-m", "gsgeo", "serve", "--data", str(tmp_path / "d"),
                        "--host", "127.evil.invalid"], capture_output=True, text=True,
                       timeout=60, cwd=REPO)
    assert r.returncode == 2, r.stderr
    assert "--host 127.evil.invalid" in r.stderr and "Traceback" not in r.stderr
    assert "token" not in r.stderr.lower()  # refused before anything is announced

