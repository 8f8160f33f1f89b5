"""Accounts: users with roles and hashed tokens (gsgeo users add|list|remove), and the
server's use of them: off loopback every API call needs a token, a viewer may only read, a
surveyor may write; on loopback without a token requests are the local operator's. Store and
API tests run on SQLite and on PostgreSQL (tests/pgcluster.py)."""

from __future__ import annotations

import sqlite3
import subprocess
import sys

import pytest
from fastapi.testclient import TestClient
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)
from servertools import london_rays

from gsgeo.server.app import ServerConfig, create_app
from gsgeo.service import accounts
from gsgeo.store import DB_NAME, ConflictError, NotFoundError, open_store
from gsgeo.store.accountrecords import UserRecord


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request) -> str | None:
    if request.param == "sqlite":
        return None
    cluster = request.getfixturevalue("pg_cluster")
    return cluster.url(cluster.new_database())


@pytest.fixture
def store(tmp_path, store_url):
    s = open_store(tmp_path / "data", store_url)
    yield s
    s.close()


def gsgeo(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gsgeo", *args], capture_output=True,
                          text=True, timeout=60)


# the CLI -------------------------------------------------------------------------------------
def test_users_add_list_remove_through_the_cli(tmp_path):
    data = str(tmp_path / "data")
    r = gsgeo("users", "add", "alice", "--role", "surveyor", "--data", data)
    assert r.returncode == 0, r.stderr
    token = r.stdout.strip().splitlines()[-1]
    assert token.startswith("gsgeo_") and len(token) > 40
    r = gsgeo("users", "list", "--data", data)
    assert r.returncode == 0 and r.stdout.split("\t")[:2] == ["alice", "surveyor"]
    with open_store(data) as s:
        user = accounts.authenticate(s, token)
        assert user is not None and (user.name, user.role) == ("alice", "surveyor")
    r = gsgeo("users", "remove", "alice", "--data", data)
    assert r.returncode == 0, r.stderr
    assert gsgeo("users", "list", "--data", data).stdout == ""
    with open_store(data) as s:
        assert accounts.authenticate(s, token) is None  # the token stops working


@pytest.mark.parametrize("args, words", [
    (["add", "bob", "--role", "boss"], "invalid choice"),
    (["add", "bad name", "--role", "viewer"], "not valid"),
    (["add", "local", "--role", "admin"], "reserved"),
    (["add", "bob"], "--role"),
    (["remove", "nobody"], "does not exist"),
])
def test_bad_users_input_exits_2_naming_it(tmp_path, args, words):
    data = str(tmp_path / "data")
    assert gsgeo("users", "add", "carol", "--role", "viewer", "--data", data).returncode == 0
    r = gsgeo("users", *args, "--data", data)
    assert r.returncode == 2 and words in r.stderr and "Traceback" not in r.stderr


def test_a_taken_name_or_a_missing_store_exits_2(tmp_path):
    data = str(tmp_path / "data")
    assert gsgeo("users", "add", "dave", "--role", "viewer", "--data", data).returncode == 0
    r = gsgeo("users", "add", "dave", "--role", "admin", "--data", data)
    assert r.returncode == 2 and "already exists" in r.stderr
    r = gsgeo("users", "list", "--data", str(tmp_path / "nowhere"))
    assert r.returncode == 2 and "no project store" in r.stderr
    assert not (tmp_path / "nowhere").exists()


# the store ----------------------------------------------------------------------------------
def test_the_store_keeps_a_hash_of_the_token_never_the_token(store, store_url, tmp_path):
    token = accounts.add_user(store, "erin", "viewer")
    with store.transaction(write=False) as tx:
        (u,) = tx.list_users()
    assert u.token_hash == accounts.token_hash(token) and token not in u.token_hash
    assert u.created_at.endswith("Z")
    if store_url is None:  # nowhere in the file either (WAL included)
        store.close()
        for f in (tmp_path / "data").iterdir():
            assert token.encode() not in f.read_bytes(), f
        con = sqlite3.connect(tmp_path / "data" / DB_NAME)
        assert con.execute("SELECT token_hash FROM users").fetchone()[0] == u.token_hash
        con.close()
    assert accounts.authenticate(store, token).name == "erin"
    assert accounts.authenticate(store, token + "x") is None
    assert accounts.authenticate(store, "") is None


def test_users_are_unique_and_removable(store):
    accounts.add_user(store, "frank", "surveyor")
    with pytest.raises(ConflictError, match="frank"):
        accounts.add_user(store, "frank", "admin")
    with store.transaction() as tx:
        with pytest.raises(ConflictError):
            tx.insert_user(UserRecord("frank", "viewer", "00"))
    accounts.remove_user(store, "frank")
    with pytest.raises(NotFoundError, match="frank"):
        accounts.remove_user(store, "frank")
    assert accounts.list_users(store) == []


# the server ---------------------------------------------------------------------------------
def app_client(tmp_path, store_url, **cfg) -> TestClient:
    cfg.setdefault("allowed_hosts", None)
    return TestClient(create_app(ServerConfig(data_dir=tmp_path / "data", store_url=store_url,
                                              **cfg)))


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def test_off_loopback_every_call_needs_a_token_and_a_viewer_cannot_write(tmp_path, store_url):
    with open_store(tmp_path / "data", store_url) as s:
        viewer = accounts.add_user(s, "vera", "viewer")
        surveyor = accounts.add_user(s, "sam", "surveyor")
    with app_client(tmp_path, store_url, host="0.0.0.0", token="admin-secret") as c:
        assert c.get("/api/projects").status_code == 401
        assert c.get("/api/projects", headers=bearer("gsgeo_wrong")).status_code == 401
        r = c.post("/api/projects", json={"name": "Site", "crs": "EPSG:32630"},
                   headers=bearer(surveyor))
        assert r.status_code == 201, r.text
        pid = r.json()["id"]
        assert c.get("/api/projects", headers=bearer(viewer)).status_code == 200
        r = c.post(f"/api/projects/{pid}/points", json={"rays": london_rays()},
                   headers=bearer(viewer))
        assert r.status_code == 403 and "viewer" in r.json()["message"]
        assert c.delete(f"/api/projects/{pid}", headers=bearer(viewer)).status_code == 403
        # a viewer may still intersect (it stores nothing)
        r = c.post("/api/intersect", json={"rays": london_rays()}, headers=bearer(viewer))
        assert r.status_code == 200, r.text
        r = c.post(f"/api/projects/{pid}/points", json={"rays": london_rays()},
                   headers={"X-Gsgeo-Token": surveyor})
        assert r.status_code == 201 and r.json()["measured_by"] == "sam"
        # the server's own token keeps working, as an admin
        r = c.patch(f"/api/projects/{pid}", json={"name": "Site 2"},
                    headers=bearer("admin-secret"))
        assert r.status_code == 200
        entries = c.get(f"/api/projects/{pid}/audit", headers=bearer(viewer)).json()["entries"]
        assert [e["user"] for e in entries] == ["admin-token", "sam", "sam"]
        assert c.get(f"/api/projects/{pid}/points", headers=bearer(viewer)).status_code == 200


def test_off_loopback_without_a_configured_token_a_user_token_is_still_needed(tmp_path,
                                                                             store_url):
    with open_store(tmp_path / "data", store_url) as s:
        surveyor = accounts.add_user(s, "sue", "surveyor")
    with app_client(tmp_path, store_url, host="0.0.0.0") as c:
        assert c.get("/api/projects").status_code == 401
        assert c.get("/api/projects", headers=bearer(surveyor)).status_code == 200


def test_on_loopback_without_a_token_the_local_operator_acts(tmp_path, store_url):
    with open_store(tmp_path / "data", store_url) as s:
        surveyor = accounts.add_user(s, "tom", "surveyor")
        viewer = accounts.add_user(s, "val", "viewer")
    with app_client(tmp_path, store_url, allowed_hosts={"testserver"}) as c:
        r = c.post("/api/projects", json={"name": "Here", "crs": "EPSG:32630"})
        assert r.status_code == 201
        pid = r.json()["id"]
        r = c.post(f"/api/projects/{pid}/points", json={"rays": london_rays()})
        assert r.status_code == 201 and r.json()["measured_by"] == "local"
        # a user's token on loopback makes the request theirs (and a viewer's read-only)
        r = c.post(f"/api/projects/{pid}/points", json={"rays": london_rays()},
                   headers=bearer(surveyor))
        assert r.status_code == 201 and r.json()["measured_by"] == "tom"
        assert c.delete(f"/api/projects/{pid}", headers=bearer(viewer)).status_code == 403
        users = [e["user"] for e in c.get(f"/api/projects/{pid}/audit").json()["entries"]]
        assert users == ["tom", "local", "local"]


@pytest.mark.parametrize("path", ["/api/projects", "/api/info", "/ogc/collections",
                                  "/scenes/none/tileset.json"])
def test_on_loopback_a_wrong_or_revoked_token_is_refused(tmp_path, store_url, path):
    """A request that presents a token is judged by it, on loopback too (401 when it is not
    valid); without a token it stays the local operator's."""
    with open_store(tmp_path / "data", store_url) as s:
        revoked = accounts.add_user(s, "rita", "surveyor")
        accounts.remove_user(s, "rita")
        kept = accounts.add_user(s, "kim", "viewer")
    with app_client(tmp_path, store_url, allowed_hosts={"testserver"}) as c:
        assert c.get(path).status_code != 401
        for headers in (bearer("gsgeo_wrong"), bearer(revoked), {"X-Gsgeo-Token": "nope"},
                        {"Cookie": "gsgeo-token-80=stale"} if path.startswith("/scenes")
                        else bearer("x")):
            r = c.get(path, headers=headers)
            assert r.status_code == 401, (headers, r.text)
            assert "not valid" in r.json()["message"]
            assert r.headers["www-authenticate"] == "Bearer"
        r = c.post("/api/projects", json={"name": "x"}, headers=bearer(revoked))
        assert r.status_code == 401
        assert c.get("/api/projects").json()["projects"] == []  # nothing was written
        assert c.get("/api/info", headers=bearer(kept)).json()["user"] == "kim"
        assert c.get("/api/info").json()["user"] == "local"
