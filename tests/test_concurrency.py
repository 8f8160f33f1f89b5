"""Optimistic concurrency: item versions in the store, ETag / If-Match / 412 in the API."""

from __future__ import annotations

import json
import shutil
import sqlite3
import subprocess
import threading
import warnings
from concurrent.futures import ThreadPoolExecutor

import httpx
import pytest
from building_helpers import CRS, GROUND, ROOFS, house_points
from servertools import REPO, london_rays, start_server

from gsgeo.server.app import ServerConfig, create_app
from gsgeo.store import (
    DB_NAME,
    BuildingRecord,
    FeatureRecord,
    PointRecord,
    PreconditionFailed,
    Project,
    open_store,
)
from gsgeo.store.migrations import MIGRATIONS, SCHEMA_VERSION

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient


@pytest.fixture
def store(tmp_path):
    s = open_store(tmp_path)
    yield s
    s.close()


def stored_items(store) -> None:
    """Project 'p' with point P1, line L1 and building B1, straight into the store."""
    with store.transaction() as tx:
        tx.insert_project(Project(id="p", name="p"))
        tx.insert_point(PointRecord(project_id="p", id="P1", rays=london_rays(3), error="x"))
        tx.insert_feature(FeatureRecord(project_id="p", kind="line", id="L1",
                                        point_ids=["P1", "P1"]))
        tx.insert_building(BuildingRecord(project_id="p", id="B1", spec={"id": "B1"}))


# store ----------------------------------------------------------------------------------------
def test_versions_start_at_one_and_every_update_adds_one(store):
    stored_items(store)
    with store.transaction() as tx:
        pt, f, b = tx.get_point("p", "P1"), tx.get_feature("p", "line", "L1"), \
            tx.get_building("p", "B1")
        assert (pt.version, f.version, b.version) == (1, 1, 1)
        pt.code, f.code, b.spec = "wall", "kerb", {"id": "B1", "attributes": {}}
        tx.update_point(pt)
        tx.update_feature(f)
        tx.update_building(b)
        assert (pt.version, f.version, b.version) == (2, 2, 2)
    with store.transaction() as tx:
        tx.update_results(tx.list_points("p", results=False))  # a re-measure
    with store.transaction(write=False) as tx:
        assert tx.get_point("p", "P1").version == 3
        assert tx.list_points("p", results=False)[0].version == 3
        assert tx.get_feature("p", "line", "L1").version == 2
        assert tx.list_buildings("p")[0].version == 2


@pytest.mark.parametrize("kind", ["point", "line", "building"])
def test_an_update_of_a_stale_copy_is_refused_and_changes_nothing(store, kind):
    stored_items(store)

    def read(tx):
        return {"point": lambda: tx.get_point("p", "P1"),
                "line": lambda: tx.get_feature("p", "line", "L1"),
                "building": lambda: tx.get_building("p", "B1")}[kind]()

    def write(tx, item):
        {"point": tx.update_point, "line": tx.update_feature,
         "building": tx.update_building}[kind](item)

    with store.transaction(write=False) as tx:
        stale = read(tx)
    with store.transaction() as tx:  # another client's change in between
        fresh = read(tx)
        write(tx, fresh)
    if kind == "building":
        stale.spec = {"id": "B1", "attributes": {"lost": True}}
    else:
        stale.code = "lost update"
    with pytest.raises(PreconditionFailed, match=r"changed meanwhile: it is at version 2, "
                                                 r"not version 1") as err:
        with store.transaction() as tx:
            write(tx, stale)
    assert err.value.current == 2
    with store.transaction(write=False) as tx:
        now = read(tx)
    assert now.version == 2
    assert (now.spec == {"id": "B1"}) if kind == "building" else (now.code == "")


def test_migration_6_gives_stored_items_version_1(tmp_path):
    con = sqlite3.connect(tmp_path / DB_NAME)
    for v, script in enumerate(MIGRATIONS[:5]):
        con.executescript(script)
        con.execute(f"PRAGMA user_version = {v + 1}")
    t = "2026-01-01T00:00:00.000Z"
    con.execute("INSERT INTO projects (id, name, created_at, updated_at) VALUES ('p','p',?,?)",
                (t, t))
    con.execute("INSERT INTO points (project_id, id, seq, rays, error, created_at, updated_at)"
                " VALUES ('p','P1',1,'[{},{}]','x',?,?)", (t, t))
    con.execute("INSERT INTO features (project_id, kind, id, seq, point_ids, created_at,"
                " updated_at) VALUES ('p','line','L1',1,'[]',?,?)", (t, t))
    con.execute("INSERT INTO buildings (project_id, id, seq, spec, created_at, updated_at)"
                " VALUES ('p','B1',1,'{}',?,?)", (t, t))
    con.commit()
    con.close()
    s = open_store(tmp_path)
    try:
        assert s.schema_version == SCHEMA_VERSION  # migrated from 5 through 6 (and on)
        with s.transaction(write=False) as tx:
            assert tx.get_point("p", "P1").version == 1
            assert tx.get_feature("p", "line", "L1").version == 1
            assert tx.get_building("p", "B1").version == 1
    finally:
        s.close()


# API ------------------------------------------------------------------------------------------
@pytest.fixture
def client(tmp_path):
    with TestClient(create_app(ServerConfig(data_dir=tmp_path / "data",
                                            allowed_hosts={"testserver"}))) as c:
        yield c


@pytest.fixture
def pid(client) -> str:
    """Project 'h' (EPSG:27700): the house's points, line L1 over two of them, building B1."""
    r = client.post("/api/projects", json={"name": "house", "id": "h", "crs": CRS})
    assert r.status_code == 201, r.text
    for p in house_points():
        r = client.post("/api/projects/h/points", json=p)
        assert r.status_code == 201 and r.headers["ETag"] == '"1"', r.text
    r = client.post("/api/projects/h/lines", json={"id": "L1", "points": ["E1", "E2"]})
    assert r.status_code == 201 and r.headers["ETag"] == '"1"', r.text
    r = client.post("/api/projects/h/buildings",
                    json={"id": "B1", "roofs": ROOFS, "ground": GROUND})
    assert r.status_code == 201 and r.headers["ETag"] == '"1"', r.text
    return "h"


ITEMS = {"point": ("points/E1", {"code": "eaves"}),
         "line": ("lines/L1", {"code": "kerb"}),
         "building": ("buildings/B1", {"attributes": {"function": "shed"}})}


def expect_412(r, what: str, current: int) -> None:
    assert r.status_code == 412, r.text
    msg = r.json()["message"]
    assert f"{what} was changed by someone else" in msg and f"version {current}" in msg, msg
    assert r.headers["ETag"] == f'"{current}"'


@pytest.mark.parametrize("kind", ITEMS)
def test_get_answers_the_version_as_a_strong_etag_and_patch_the_new_one(client, pid, kind):
    path, change = ITEMS[kind]
    r = client.get(f"/api/projects/{pid}/{path}")
    assert r.status_code == 200 and r.headers["ETag"] == '"1"' and r.json()["version"] == 1
    r = client.patch(f"/api/projects/{pid}/{path}", json=change, headers={"If-Match": '"1"'})
    assert r.status_code == 200, r.text
    assert r.headers["ETag"] == '"2"' and r.json()["version"] == 2
    assert client.get(f"/api/projects/{pid}/{path}").headers["ETag"] == '"2"'


@pytest.mark.parametrize("kind", ITEMS)
def test_a_stale_if_match_is_answered_412_and_changes_nothing(client, pid, kind):
    path, change = ITEMS[kind]
    url = f"/api/projects/{pid}/{path}"
    before = client.get(url).json()
    assert client.patch(url, json=change).status_code == 200  # someone else: now version 2
    after = client.get(url).json()
    what = f"{kind} '{path.split('/')[1]}'"
    expect_412(client.patch(url, json=change | {"id": "X9"}, headers={"If-Match": '"1"'}),
               what, 2)
    expect_412(client.delete(url, headers={"If-Match": '"1"'}), what, 2)
    r = client.get(url)
    assert r.status_code == 200 and r.json() == after and after != before


@pytest.mark.parametrize("if_match", ['"7", "1"', "*"])  # a list holding the current one
@pytest.mark.parametrize("kind", ["point", "line", "building"])
def test_a_current_etag_or_star_lets_a_delete_through(client, pid, kind, if_match):
    path, _ = ITEMS[kind]
    url = f"/api/projects/{pid}/{path}"
    if kind == "point":  # a point in use by a line or a building cannot go
        url = f"/api/projects/{pid}/points/X1"
        assert client.post(f"/api/projects/{pid}/points",
                           json={"id": "X1", "rays": house_points()[0]["rays"]}).status_code == 201
    r = client.delete(url, headers={"If-Match": if_match})
    assert r.status_code == 204, r.text
    assert client.get(url).status_code == 404
    assert client.delete(url, headers={"If-Match": "*"}).status_code == 404  # * needs one


def test_star_and_no_if_match_put_no_condition(client, pid):
    url = f"/api/projects/{pid}/points/E1"
    assert client.patch(url, json={"code": "a"}).headers["ETag"] == '"2"'
    r = client.patch(url, json={"code": "b"}, headers={"If-Match": "*"})
    assert r.status_code == 200 and r.headers["ETag"] == '"3"' and r.json()["code"] == "b"


@pytest.mark.parametrize("header", ['W/"1"', '"abc"', '"01"'])
def test_a_tag_that_is_not_a_current_version_never_matches(client, pid, header):
    # If-Match compares strongly: a weak tag never matches, nor a tag not of ours
    r = client.patch(f"/api/projects/{pid}/points/E1", json={"code": "x"},
                     headers={"If-Match": header})
    assert r.status_code == 412, r.text
    assert "it is at version 1, not the version given" in r.json()["message"]


@pytest.mark.parametrize("header", ["1", '"1', "", '"1" "2"', 'x"1"'])
def test_an_if_match_that_is_not_entity_tags_is_answered_422(client, pid, header):
    r = client.patch(f"/api/projects/{pid}/points/E1", json={"code": "x"},
                     headers={"If-Match": header})
    assert r.status_code == 422, r.text
    assert r.json()["field"] == "If-Match" and "If-Match" in r.json()["message"]
    assert client.get(f"/api/projects/{pid}/points/E1").json()["code"] == ""


def test_a_remeasure_is_a_new_version_of_every_point(client, pid):
    """A re-measure (here: another sigma_px) changes each point's result, so a client holding
    the old ETag must reload before changing it."""
    url = f"/api/projects/{pid}/points/E1"
    assert client.get(url).headers["ETag"] == '"1"'
    r = client.patch(f"/api/projects/{pid}", json={"sigma_px": 2.0})
    assert r.status_code == 200, r.text
    got = client.get(url)
    assert got.headers["ETag"] == '"2"' and got.json()["version"] == 2
    assert {p["version"] for p in client.get(f"/api/projects/{pid}/points?summary=true")
            .json()["points"]} == {2}
    expect_412(client.patch(url, json={"code": "late"}, headers={"If-Match": '"1"'}),
               "point 'E1'", 2)
    # the line and building keep their versions: what is stored of them did not change
    assert client.get(f"/api/projects/{pid}/lines/L1").headers["ETag"] == '"1"'
    assert client.get(f"/api/projects/{pid}/buildings/B1").headers["ETag"] == '"1"'


def test_renaming_a_point_is_a_new_version_of_the_line_and_building_using_it(client, pid):
    r = client.patch(f"/api/projects/{pid}/points/E1", json={"id": "C1"},
                     headers={"If-Match": '"1"'})
    assert r.status_code == 200 and r.headers["ETag"] == '"2"', r.text
    assert client.get(f"/api/projects/{pid}/points/C1").headers["ETag"] == '"2"'
    line = client.get(f"/api/projects/{pid}/lines/L1")
    assert line.json()["points"][0] == "C1" and line.headers["ETag"] == '"2"'
    assert client.get(f"/api/projects/{pid}/buildings/B1").headers["ETag"] == '"2"'
    expect_412(client.delete(f"/api/projects/{pid}/lines/L1", headers={"If-Match": '"1"'}),
               "line 'L1'", 2)


# racing clients against a live server --------------------------------------------------------
@pytest.fixture(scope="module")
def live(tmp_path_factory):
    data = tmp_path_factory.mktemp("race")
    proc, base = start_server(data)
    try:
        c = httpx.Client(base_url=base + "/api", timeout=30)
        assert c.post("/projects", json={"name": "race", "id": "r"}).status_code == 201
        r = c.post("/projects/r/points", json={"id": "P1", "rays": london_rays(3)})
        assert r.status_code == 201, r.text
        c.close()
        yield base + "/api/projects/r/points/P1"
    finally:
        proc.kill()
        proc.wait(timeout=10)


def test_two_clients_racing_on_one_point_exactly_one_wins(live):
    def client(name: str, barrier: threading.Barrier) -> tuple[str, int]:
        """Read the point's ETag, wait for the other client to have read it too, change."""
        with httpx.Client(timeout=30) as c:
            tag = c.get(live).headers["ETag"]
            barrier.wait()
            r = c.patch(live, json={"code": name}, headers={"If-Match": tag})
            return name, r.status_code

    for round_ in range(5):
        barrier = threading.Barrier(2)
        with ThreadPoolExecutor(2) as pool:
            outcomes = dict(pool.map(client, [f"a{round_}", f"b{round_}"], [barrier] * 2))
        assert sorted(outcomes.values()) == [200, 412], outcomes
        winner = next(n for n, s in outcomes.items() if s == 200)
        assert httpx.get(live).json()["code"] == winner  # the loser changed nothing


def test_read_modify_write_with_if_match_loses_no_update(live):
    """Four clients add 1 to a counter kept in the point's description, five times each,
    retrying on 412: every increment is there at the end."""
    httpx.patch(live, json={"description": "0"})

    def worker(_: int) -> int:
        retries = 0
        with httpx.Client(timeout=30) as c:
            for _ in range(5):
                while True:
                    r = c.get(live)
                    n = int(r.json()["description"])
                    w = c.patch(live, json={"description": str(n + 1)},
                                headers={"If-Match": r.headers["ETag"]})
                    if w.status_code == 200:
                        break
                    assert w.status_code == 412, w.text
                    retries += 1
        return retries

    with ThreadPoolExecutor(4) as pool:
        list(pool.map(worker, range(4)))
    assert httpx.get(live).json()["description"] == "20"


# the viewer -----------------------------------------------------------------------------------
VIEWER_JS = """
globalThis.location = {hash: "", pathname: "/", search: "", port: "8000", protocol: "http:"};
globalThis.sessionStorage = {getItem: () => null, setItem: () => {}};
globalThis.history = {replaceState: () => {}};
globalThis.document = {cookie: ""};
const sent = [];
const answers = {
  "GET /api/projects/h/points": [200, {points: [{id: "E 1", version: 3}, {id: "E2", version: 1}]}],
  "PATCH /api/projects/h/points/E2": [200, {id: "E2", version: 2}],
  "PATCH /api/projects/h/points/E%201": [412, {message: "point 'E 1' was changed by someone else"}],
};
globalThis.fetch = async (url, init) => {
  sent.push([init.method, url, (init.headers || {})["If-Match"] ?? null]);
  const [status, body] = answers[`${init.method} ${url}`] ?? [204, null];
  return new Response(body === null ? null : JSON.stringify(body), {status});
};
const {api} = await import(process.argv[1]);
await api("GET", "/projects/h/points");
await api("PATCH", "/projects/h/points/E2", {code: "a"});
await api("PATCH", "/projects/h/points/E2", {code: "b"});
let error = null;
try { await api("PATCH", "/projects/h/points/E%201", {code: "c"}); }
catch (e) { error = [e.status, e.message]; }
await api("DELETE", "/projects/h/points/E2");
await api("DELETE", "/projects/h/points/E2");
await api("PATCH", "/projects/h/points/P9", {code: "d"});
console.log(JSON.stringify({sent, error}));
"""


@pytest.mark.skipif(shutil.which("node") is None, reason="Node.js is not installed")
def test_the_viewer_sends_the_version_it_loaded_as_if_match_and_says_412_plainly():
    out = subprocess.run(["node", "--input-type=module", "-e", VIEWER_JS,
                          (REPO / "web" / "js" / "api.js").as_uri()],
                         capture_output=True, text=True, timeout=60, check=True)
    got = json.loads(out.stdout)
    assert got["sent"] == [
        ["GET", "/api/projects/h/points", None],
        ["PATCH", "/api/projects/h/points/E2", '"1"'],   # as listed
        ["PATCH", "/api/projects/h/points/E2", '"2"'],   # as the last PATCH answered
        ["PATCH", "/api/projects/h/points/E%201", '"3"'],
        ["DELETE", "/api/projects/h/points/E2", '"2"'],  # answered 204 (stub)...
        ["DELETE", "/api/projects/h/points/E2", None],   # ...so no longer known
        ["PATCH", "/api/projects/h/points/P9", None],    # never loaded: no condition
    ]
    status, message = got["error"]
    assert status == 412 and message.startswith("Changed by someone else meanwhile: reload")
    assert "point 'E 1' was changed by someone else" in message
