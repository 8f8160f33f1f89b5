"""Scenes whose tiles lie on a static host (``gsgeo serve --scenes URL``, ``--scene-url``): the
URLs are checked at start (exit 2 naming the problem), /api/scenes says where each scene's
tiles are, and /scenes/<name>/tileset.json (the georeference, from DATA) names its tiles by
absolute URLs on that host. The browser test with nginx is tests/e2e/test_static_scenes.py."""

from __future__ import annotations

import json
import shutil
import subprocess
import warnings

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.cli import main
from gsgeo.errors import InputError
from gsgeo.server.app import ServerConfig, app_from_env, config_to_env, create_app
from gsgeo.server.scenehosts import absolute_uris, folder_url, scene_hosts
from tests.conftest import REPO

TILESET = {
    "asset": {"version": "1.1"},
    "schemaUri": "meta/schema.json",
    "geometricError": 10.0,
    "root": {
        "transform": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 3978668.0, -8332.9, 4968398.2, 1],
        "boundingVolume": {"box": [0, 0, 0, 5, 0, 0, 0, 5, 0, 0, 0, 1]},
        "geometricError": 1.0, "refine": "ADD",
        "content": {"uri": "tiles/0.glb"},
        "children": [
            {"boundingVolume": {"box": [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1]},
             "geometricError": 0.0, "contents": [{"uri": "tiles/a%20b.glb"},
                                                 {"uri": "https://cdn.example/x.glb"}]},
            {"boundingVolume": {"box": [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1]},
             "geometricError": 0.0, "content": {"uri": "{level}/{x}/{y}.glb"},
             "implicitTiling": {"subdivisionScheme": "QUADTREE", "subtreeLevels": 2,
                                "availableLevels": 2,
                                "subtrees": {"uri": "subtrees/{level}/{x}/{y}.subtree"}}},
            {"boundingVolume": {"box": [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1]},
             "geometricError": 0.0, "content": {"url": "../old/sub/tileset.json"}},
            {"boundingVolume": {"box": [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1]},
             "geometricError": 0.0, "content": {"uri": "data:model/gltf-binary;base64,Z2xURg=="}},
        ],
    },
    "extras": {"gsgeo": {"georef": {"version": 3}}, "uri": "left/as/is"},
}

BASE = "http://static.example:8080/scenes"


@pytest.mark.parametrize("url, words", [
    ("ftp://static.example/scenes/", "http:// or https://"),
    ("static.example/scenes", "http:// or https://"),
    ("http:///scenes/", "names no host"),
    ("http://user:secret@static.example/", "user name or password"),
    ("http://static.example:99999/", "port"),
    ("http://static.example/scenes/?sig=1", "query or fragment"),
    ("http://static.example/scenes/#x", "query or fragment"),
    ("http://static.example/my scenes/", "space or control"),
    ("", "empty"),
])
def test_bad_scenes_url_exits_2_naming_it(tmp_path, capsys, url, words):
    code = main(["serve", "--data", str(tmp_path / "data"), "--port", "0", "--scenes", url])
    err = capsys.readouterr().err
    assert code == 2
    assert "--scenes" in err and words in err
    assert "Traceback" not in err
    assert not (tmp_path / "data").exists()  # refused before anything was created


@pytest.mark.parametrize("arg, words", [
    ("box", "NAME=URL"),
    ("=http://h/", "NAME=URL"),
    ("../box=http://h/", "is not a scene name"),
    ("box=ftp://h/", "http:// or https://"),
])
def test_bad_scene_url_exits_2_naming_it(tmp_path, capsys, arg, words):
    code = main(["serve", "--data", str(tmp_path / "data"), "--port", "0", "--scene-url", arg])
    err = capsys.readouterr().err
    assert code == 2
    assert "--scene-url" in err and words in err


def test_folder_url_ends_with_a_slash():
    assert folder_url(BASE, "--scenes") == BASE + "/"
    assert folder_url(BASE + "/", "--scenes") == BASE + "/"
    assert folder_url("HTTPS://h", "--scenes") == "HTTPS://h/"
    hosts = scene_hosts(BASE, {"one": "https://bucket.example/one"})
    assert hosts.folder("box") == BASE + "/box/"
    assert hosts.folder("one") == "https://bucket.example/one/"
    assert scene_hosts(None, {"one": "https://b.example/x/"}).folder("box") is None
    with pytest.raises(InputError):
        scene_hosts("nope")


def test_relative_uris_resolved_against_the_scene_folder():
    out = absolute_uris(TILESET, BASE + "/box/")
    root = out["root"]
    assert out["schemaUri"] == BASE + "/box/meta/schema.json"
    assert root["content"]["uri"] == BASE + "/box/tiles/0.glb"
    kids = root["children"]
    assert [c["uri"] for c in kids[0]["contents"]] == [BASE + "/box/tiles/a%20b.glb",
                                                       "https://cdn.example/x.glb"]
    assert kids[1]["content"]["uri"] == BASE + "/box/{level}/{x}/{y}.glb"
    assert kids[1]["implicitTiling"]["subtrees"]["uri"] == \
        BASE + "/box/subtrees/{level}/{x}/{y}.subtree"
    assert kids[2]["content"]["url"] == BASE + "/old/sub/tileset.json"
    assert kids[3]["content"]["uri"].startswith("data:model/gltf-binary;base64,")
    assert out["extras"] == TILESET["extras"]  # the application's own: untouched
    assert root["transform"] == TILESET["root"]["transform"]  # the georeference as stored
    assert TILESET["root"]["content"]["uri"] == "tiles/0.glb"  # the input is not changed


def make_site(tmp_path):
    """DATA with scenes box (a tile kept locally too) and one; their tileset.json is TILESET
    without the external tileset, which the server would read from DATA."""
    doc = json.loads(json.dumps(TILESET))
    del doc["root"]["children"][2]
    data = tmp_path / "data"
    for name in ("box", "one"):
        (data / "scenes" / name).mkdir(parents=True)
        (data / "scenes" / name / "tileset.json").write_text(json.dumps(doc))
    (data / "scenes" / "box" / "tiles").mkdir()
    (data / "scenes" / "box" / "tiles" / "0.glb").write_bytes(b"glTF" + bytes(100))
    return data


def client(data, **kw) -> TestClient:
    cfg = ServerConfig(data_dir=data, allowed_hosts={"testserver"}, **kw)
    return TestClient(create_app(cfg))


def test_tileset_names_tiles_on_the_static_host(tmp_path):
    data = make_site(tmp_path)
    with client(data, scenes_url=BASE, scene_urls={"one": "https://bucket.example/one"}) as c:
        scenes = {s["name"]: s for s in c.get("/api/scenes").json()["scenes"]}
        assert scenes["box"]["tiles_url"] == BASE + "/box/"
        assert scenes["one"]["tiles_url"] == "https://bucket.example/one/"
        assert scenes["box"]["url"] == "/scenes/box/tileset.json"  # from this server
        assert scenes["box"]["origin"] is not None  # read from DATA's tileset.json
        r = c.get("/scenes/box/tileset.json")
        assert r.status_code == 200 and r.headers["content-type"] == "application/json"
        doc = r.json()
        assert doc["root"]["content"]["uri"] == BASE + "/box/tiles/0.glb"
        assert doc["root"]["transform"] == TILESET["root"]["transform"]
        one = c.get("/scenes/one/tileset.json").json()
        assert one["root"]["content"]["uri"] == "https://bucket.example/one/tiles/0.glb"
        etag = r.headers["etag"]
        assert c.get("/scenes/box/tileset.json", headers={"If-None-Match": etag}).status_code \
            == 304
        head = c.head("/scenes/box/tileset.json")
        assert head.status_code == 200 and int(head.headers["content-length"]) == len(r.content)
        # a changed tileset.json (a georeference applied) is served changed
        changed = json.loads(json.dumps(TILESET))
        changed["root"]["transform"][12] += 1.0
        (data / "scenes" / "box" / "tileset.json").write_text(json.dumps(changed, indent=1))
        r2 = c.get("/scenes/box/tileset.json", headers={"If-None-Match": etag})
        assert r2.status_code == 200 and r2.json()["root"]["transform"][12] == \
            TILESET["root"]["transform"][12] + 1.0
        assert c.get("/scenes/nope/tileset.json").status_code == 404


def test_without_scenes_url_nothing_changes(tmp_path):
    data = make_site(tmp_path)
    with client(data) as c:
        scenes = c.get("/api/scenes").json()["scenes"]
        assert [s["tiles_url"] for s in scenes] == [None, None]
        r = c.get("/scenes/box/tileset.json")
        assert r.content == (data / "scenes" / "box" / "tileset.json").read_bytes()
        assert c.get("/scenes/box/tiles/0.glb").status_code == 200


def test_unreadable_tileset_is_a_422_not_a_500(tmp_path):
    data = make_site(tmp_path)
    (data / "scenes" / "box" / "tileset.json").write_text("[1, 2")
    (data / "scenes" / "one" / "tileset.json").write_text("[" * 100_000 + "]" * 100_000)
    with client(data, scenes_url=BASE) as c:
        for name in ("box", "one"):
            r = c.get(f"/scenes/{name}/tileset.json")
            assert r.status_code == 422, r.text
            assert "tileset.json" in r.json()["message"]
        listed = {s["name"]: s for s in c.get("/api/scenes").json()["scenes"]}
        assert "cannot be read" in listed["one"]["error"]  # was a 500 (RecursionError)


def test_worker_processes_get_the_scene_hosts(tmp_path, monkeypatch):
    data = make_site(tmp_path)
    cfg = ServerConfig(data_dir=data, allowed_hosts={"testserver"}, scenes_url=BASE,
                       scene_urls={"one": "https://bucket.example/one/"})
    monkeypatch.setenv("GSGEO_SERVE_CONFIG", config_to_env(cfg))
    with TestClient(app_from_env()) as c:
        scenes = {s["name"]: s["tiles_url"] for s in c.get("/api/scenes").json()["scenes"]}
    assert scenes == {"box": BASE + "/box/", "one": "https://bucket.example/one/"}


@pytest.mark.skipif(shutil.which("node") is None, reason="Node.js is not installed")
def test_viewer_message_for_a_failed_tile():
    """web/js/scenehost.js: a refused tile from the static host (no status: what a missing CORS
    header looks like) names the host and the header; a 404 names the status and the tile."""
    src = (f"import {{ tileFailureText as t }} from '{(REPO / 'web/js/scenehost.js').as_uri()}';\n"
           "const page = 'http://127.0.0.1:8000';\n"
           "console.log(JSON.stringify([\n"
           "  t('box', 'http://s.example:81/scenes/box/', {url: 'http://s.example:81/scenes/box/"
           "tiles/0.glb', message: 'Request has failed.'}, page),\n"
           "  t('box', 'http://s.example:81/scenes/box/', {url: 'http://s.example:81/scenes/box/"
           "tiles/0.glb', message: 'Request has failed. Status Code: 404'}, page),\n"
           "  t('box', null, {url: '/scenes/box/tiles/0.glb', message: 'Request has failed.'}, page),"
           "\n]));")
    out = subprocess.run(["node", "--input-type=module", "-e", src], capture_output=True,
                         text=True, check=True, timeout=60)
    cors, missing, local = json.loads(out.stdout)
    assert "http://s.example:81" in cors and "CORS" in cors
    assert "Access-Control-Allow-Origin: http://127.0.0.1:8000" in cors
    assert "HTTP 404" in missing and "tiles/0.glb" in missing and "CORS" not in missing
    assert local == "A tile of 'box' failed to load: Request has failed."
