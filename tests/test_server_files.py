"""Scenes, Cesium and the web client over HTTP: content types, validators, no traversal."""

from __future__ import annotations

import json
import os
import warnings
from email.utils import formatdate

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.server.app import ServerConfig, create_app
from gsgeo.server.files import safe_path


@pytest.fixture
def site(tmp_path):
    data = tmp_path / "data"
    scene = data / "scenes" / "site"
    (scene / "sub").mkdir(parents=True)
    (scene / "tileset.json").write_text(json.dumps({"asset": {"version": "1.1"}, "root": {}}))
    (scene / "sub" / "tile_0.glb").write_bytes(b"glTF" + bytes(range(256)) * 40)
    (scene / "tile.spz").write_bytes(b"\x1f\x8b" + b"x" * 100)
    (data / "secret.txt").write_text("not for the web")
    os.symlink(data / "secret.txt", scene / "escape.json")
    web = tmp_path / "web"
    (web / "node_modules" / "x").mkdir(parents=True)
    (web / "js").mkdir()
    (web / "index.html").write_text("<!doctype html><title>gsgeo</title>")
    (web / "js" / "app.js").write_text("console.log(1)")
    (web / "node_modules" / "x" / "a.js").write_text("x")
    cesium = tmp_path / "cesium"
    (cesium / "Widgets").mkdir(parents=True)
    (cesium / "Cesium.js").write_text("var Cesium = {};")
    (cesium / "Widgets" / "widgets.css").write_text("body{}")
    cfg = ServerConfig(data_dir=data, web_dir=web, cesium_dir=cesium, allowed_hosts={"testserver"})
    with TestClient(create_app(cfg)) as c:
        yield c


@pytest.mark.parametrize("path, ctype", [
    ("/scenes/site/tileset.json", "application/json"),
    ("/scenes/site/sub/tile_0.glb", "model/gltf-binary"),
    ("/scenes/site/tile.spz", "application/octet-stream"),
    ("/cesium/Cesium.js", "text/javascript"),
    ("/cesium/Widgets/widgets.css", "text/css"),
    ("/", "text/html"),
    ("/js/app.js", "text/javascript"),
])
def test_content_types_and_validators(site, path, ctype):
    r = site.get(path)
    assert r.status_code == 200, path
    assert r.headers["content-type"].startswith(ctype)
    assert r.headers["etag"].startswith('"') and r.headers["last-modified"]
    assert r.headers["cache-control"]


def test_tiles_bytes_and_conditional_requests(site):
    r = site.get("/scenes/site/sub/tile_0.glb")
    assert r.content == b"glTF" + bytes(range(256)) * 40
    assert r.headers["cache-control"] == "no-cache"
    etag, lm = r.headers["etag"], r.headers["last-modified"]
    r2 = site.get("/scenes/site/sub/tile_0.glb", headers={"If-None-Match": etag})
    assert r2.status_code == 304 and r2.content == b"" and r2.headers["etag"] == etag
    assert site.get("/scenes/site/sub/tile_0.glb",
                    headers={"If-None-Match": '"other"'}).status_code == 200
    assert site.get("/scenes/site/sub/tile_0.glb",
                    headers={"If-Modified-Since": lm}).status_code == 304
    assert site.get("/scenes/site/sub/tile_0.glb",
                    headers={"If-Modified-Since": formatdate(0, usegmt=True)}).status_code == 200
    h = site.head("/scenes/site/sub/tile_0.glb")
    assert h.status_code == 200 and h.headers["content-length"] == str(4 + 256 * 40)


def test_etag_changes_when_a_scene_is_rebuilt(site, tmp_path):
    path = tmp_path / "data" / "scenes" / "site" / "tileset.json"
    e1 = site.get("/scenes/site/tileset.json").headers["etag"]
    path.write_text(json.dumps({"asset": {"version": "1.1"}, "root": {"x": 1}}))
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    r = site.get("/scenes/site/tileset.json", headers={"If-None-Match": e1})
    assert r.status_code == 200 and r.headers["etag"] != e1 and b'"x"' in r.content


@pytest.mark.parametrize("path", [
    "/scenes/site/../../secret.txt",
    "/scenes/site/%2e%2e/%2e%2e/secret.txt",
    "/scenes/site/..%2f..%2fsecret.txt",
    "/scenes/site/escape.json",  # a symlink out of the scene
    "/scenes/..%2fdata/secret.txt",
    "/scenes/site/",
    "/scenes/site/sub",
    "/scenes/site/nope.glb",
    "/scenes/nope/tileset.json",
    "/scenes/site/%00.json",
    "/cesium/../secret.txt",
    "/node_modules/x/a.js",
    "/gsgeo.sqlite",
])
def test_no_path_traversal(site, path):
    r = site.get(path)
    assert r.status_code in (404, 400), (path, r.status_code)
    assert b"not for the web" not in r.content


def test_safe_path_directly(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "f.json").write_text("{}")
    (tmp_path / "outside").write_text("x")
    root = tmp_path / "a"
    assert safe_path(root, "f.json") == (root / "f.json").resolve()
    for bad in ["../outside", "/etc/passwd", "a/../../outside", "", "f.json/", ".", "x\\..\\y",
                "f.json\x00"]:
        assert safe_path(root, bad) is None, bad


def test_missing_web_client_gives_a_pointer_to_the_api(tmp_path):
    cfg = ServerConfig(data_dir=tmp_path / "d", web_dir=tmp_path / "none",
                       allowed_hosts={"testserver"})
    with TestClient(create_app(cfg)) as c:
        r = c.get("/")
        assert r.status_code == 200 and "/docs" in r.text
        assert c.get("/docs").status_code == 200
        assert c.get("/openapi.json").json()["info"]["title"] == "gsgeo"


def test_real_tileset_is_served(white_sculpture, tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "scenes").symlink_to(white_sculpture.parent)  # scenes kept elsewhere: link the root
    name = white_sculpture.name
    with TestClient(create_app(ServerConfig(data_dir=data, allowed_hosts={"testserver"}))) as c:
        ts = c.get(f"/scenes/{name}/tileset.json")
        assert ts.status_code == 200
        uri = ts.json()["root"]["content"]["uri"]
        r = c.get(f"/scenes/{name}/{uri}")
        assert r.status_code == 200 and r.headers["content-type"] == "model/gltf-binary"
        assert r.content == (white_sculpture / uri).read_bytes()
