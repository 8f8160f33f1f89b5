"""The JSON API and optimistic concurrency with the projects in PostgreSQL + PostGIS.

The tests of tests/test_server_api.py and tests/test_concurrency.py that take the ``client``
(or, for the store's versions, ``store``) fixture are collected here again, with those
fixtures giving an app (a store) on a fresh database of the session's throw-away cluster
(tests/pgcluster.py): the same requests must give the same answers on both backends.
"""

from __future__ import annotations

import inspect
import warnings

import pytest
import test_concurrency
import test_server_api
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.server.app import ServerConfig, create_app
from gsgeo.store import open_store


def _take(module: object, fixtures: set[str]) -> list[str]:
    """Put the module's tests that use one of ``fixtures`` (and its other fixtures) here."""
    taken = []
    for name, obj in vars(module).items():
        if name.startswith("test_") and callable(obj):
            if fixtures & set(inspect.signature(obj).parameters):
                globals()[f"{name}__{module.__name__}"] = obj  # type: ignore[attr-defined]
                taken.append(name)
    return taken


# fixtures the borrowed tests ask for besides client/store
project = test_server_api.project
pid = test_concurrency.pid

TAKEN = _take(test_server_api, {"client"}) + _take(test_concurrency, {"client", "store"})


@pytest.fixture
def pg_url(request) -> str:
    cluster = request.getfixturevalue("pg_cluster")
    return cluster.url(cluster.new_database())


@pytest.fixture
def client(tmp_path, pg_url):
    app = create_app(ServerConfig(data_dir=tmp_path / "data", allowed_hosts={"testserver"},
                                  store_url=pg_url))
    with TestClient(app) as c:
        yield c


@pytest.fixture
def store(tmp_path, pg_url):
    s = open_store(tmp_path, pg_url)
    yield s
    s.close()


def test_the_borrowed_tests_are_here():
    assert len(TAKEN) > 30 and "test_point_crud" in TAKEN


def test_a_nul_character_is_a_422_not_a_500(client):
    r = client.post("/api/projects", json={"name": "a\u0000b", "crs": "EPSG:27700"})
    assert r.status_code == 422 and "NUL character" in r.json()["message"]
    assert client.get("/api/projects").json()["projects"] == []
