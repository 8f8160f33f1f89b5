"""Roles and what /api/info says about them: a token is required wherever a request without
one is refused (the server's own token, or any server off loopback where users' tokens are
needed), and /api/info names the caller and their role; only an admin may delete a whole
project (a surveyor gets 403 naming the role, and the project stays)."""

from __future__ import annotations

import warnings

import pytest
from servertools import london_rays

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.server.app import ServerConfig, create_app
from gsgeo.service import accounts
from gsgeo.store import open_store


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


@pytest.fixture
def users(tmp_path) -> dict[str, dict[str, str]]:
    with open_store(tmp_path / "data") as s:
        return {role: bearer(accounts.add_user(s, f"{role[:3]}1", role))
                for role in ("admin", "surveyor", "viewer")}


def app(tmp_path, **kw):
    return TestClient(create_app(ServerConfig(data_dir=tmp_path / "data", **kw)))


def test_info_says_a_token_is_needed_off_loopback_and_who_asks(tmp_path, users):
    with app(tmp_path, host="0.0.0.0", allowed_hosts=None) as c:  # accounts, no --token
        assert c.get("/api/info").status_code == 401
        r = c.get("/api/info", headers=users["surveyor"])
        assert r.status_code == 200, r.text
        assert r.json()["token_required"] is True
        assert (r.json()["user"], r.json()["role"]) == ("sur1", "surveyor")
    with app(tmp_path, allowed_hosts={"testserver"}) as c:  # loopback, no token: local
        info = c.get("/api/info").json()
        assert (info["token_required"], info["user"], info["role"]) == (False, "local", "admin")
        info = c.get("/api/info", headers=users["viewer"]).json()
        assert (info["user"], info["role"]) == ("vie1", "viewer")
    with app(tmp_path, token="tok", allowed_hosts={"testserver"}) as c:  # its own token
        assert c.get("/api/info").status_code == 401
        info = c.get("/api/info", headers=bearer("tok")).json()
        assert (info["token_required"], info["user"], info["role"]) == (True, "admin-token",
                                                                        "admin")


def test_only_an_admin_deletes_a_project(tmp_path, users):
    with app(tmp_path, host="0.0.0.0", allowed_hosts=None) as c:
        sur, adm, vie = users["surveyor"], users["admin"], users["viewer"]
        assert c.post("/api/projects", json={"name": "s", "id": "s"}, headers=sur
                      ).status_code == 201
        assert c.post("/api/projects/s/points", json={"id": "A", "rays": london_rays()},
                      headers=sur).status_code == 201
        for who, role in ((sur, "surveyor"), (vie, "viewer")):
            r = c.delete("/api/projects/s", headers=who)
            assert r.status_code == 403 and role in r.json()["message"], r.text
        assert "admin" in c.delete("/api/projects/s/", headers=sur).json()["message"]
        assert c.get("/api/projects/s/points/A", headers=vie).status_code == 200  # still there
        assert c.delete("/api/projects/s/points/A", headers=sur).status_code == 204
        assert c.delete("/api/projects/s", headers=adm).status_code == 204
        assert c.get("/api/projects/s", headers=vie).status_code == 404
