"""Stored points (POST /api/projects/{pid}/points) run on a few long-lived, warmed threads
(gsgeo serve --store-threads, default 4) instead of threads FastAPI's pool starts on demand
and ends after 10 s idle (each fresh thread rebuilt its PROJ objects: ~15 ms more); the
request's user still reaches the audit trail; 0 keeps FastAPI's pool; a bad count is exit 2."""

from __future__ import annotations

import threading
import warnings

import pytest
from servertools import london_rays

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.cli import main
from gsgeo.server.app import ServerConfig, create_app
from gsgeo.service import Projects, accounts
from gsgeo.store import open_store


@pytest.mark.parametrize("threads", [4, 0])
def test_stored_points_run_on_the_store_threads(tmp_path, monkeypatch, threads):
    names: list[str] = []
    real = Projects.add_point

    def spy(self, pid, point):
        names.append(threading.current_thread().name)
        return real(self, pid, point)

    monkeypatch.setattr(Projects, "add_point", spy)
    with open_store(tmp_path / "data") as s:
        token = accounts.add_user(s, "sam", "surveyor")
    app = create_app(ServerConfig(data_dir=tmp_path / "data", allowed_hosts={"testserver"},
                                  store_threads=threads))
    with TestClient(app) as c:
        assert c.post("/api/projects", json={"name": "p", "id": "p"}).status_code == 201
        for k in range(12):
            r = c.post("/api/projects/p/points", json={"id": f"P{k}", "rays": london_rays()},
                       headers={"Authorization": f"Bearer {token}"})
            assert r.status_code == 201, r.text
            assert r.json()["measured_by"] == "sam" and r.headers["ETag"] == '"1"'
        r = c.post("/api/projects/p/points", json={"id": "P0", "rays": london_rays()})
        assert r.status_code == 409  # errors come back from the pool as before
        entries = c.get("/api/projects/p/audit", params={"item": "P3"}).json()["entries"]
        assert [(e["user"], e["action"]) for e in entries] == [("sam", "created")]
    on_pool = [n.startswith("gsgeo-store") for n in names]
    assert all(on_pool) if threads else not any(on_pool)
    if threads:
        assert len(set(names)) <= threads


def test_a_bad_store_thread_count_is_exit_2(tmp_path, capsys):
    assert main(["serve", "--data", str(tmp_path), "--store-threads", "65"]) == 2
    assert "--store-threads must be between 0 and 64" in capsys.readouterr().err
