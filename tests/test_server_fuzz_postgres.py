"""Schemathesis fuzzes the API of a PostgreSQL-backed server: no request may produce a 500.

As tests/test_server_fuzz.py (bounded random phase; half the cases aimed at a project that
exists), with the projects in a fresh database of the session's throw-away cluster
(tests/pgcluster.py). The OpenAPI schema does not depend on the store, so it is read at
collection from an app on SQLite; the requests go to the PostgreSQL-backed app, made when the
test first runs (so collecting this file starts no cluster).
"""

from __future__ import annotations

import itertools
import tempfile
import warnings
from pathlib import Path

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from hypothesis_profiles import examples
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)
from schemathesis.checks import not_a_server_error, status_code_conformance
from servertools import london_rays

from gsgeo.server.app import ServerConfig, create_app
from gsgeo.service import Projects
from gsgeo.store.records import ConflictError

warnings.filterwarnings("ignore", category=DeprecationWarning)

DATA = Path(tempfile.mkdtemp(prefix="gsgeo-fuzz-pg-"))


class Switch:
    """An ASGI app passing every call to ``target`` (which the test replaces)."""

    def __init__(self, target) -> None:
        self.target = target

    async def __call__(self, scope, receive, send) -> None:
        await self.target(scope, receive, send)


SWITCH = Switch(create_app(ServerConfig(data_dir=DATA / "schema", allowed_hosts={"*"})))
schema = schemathesis.openapi.from_asgi("/openapi.json", SWITCH)
schema.config.phases.coverage.enabled = False
_toggle = itertools.count()


@pytest.fixture(scope="module")
def pg_projects(request) -> Projects:
    cluster = request.getfixturevalue("pg_cluster")
    app = create_app(ServerConfig(data_dir=DATA / "pg", allowed_hosts={"*"},
                                  store_url=cluster.url(cluster.new_database())))
    SWITCH.target = app
    yield app.state.projects
    app.state.store.close()


def ensure_fixture_project(svc: Projects) -> None:
    """The project 'fuzz' with points P1-P3, line L1 and polygon A1."""
    try:
        svc.create_project(name="fuzz", id="fuzz", crs="EPSG:32630")
    except ConflictError:
        pass
    try:
        svc.update_project("fuzz", {"crs": "EPSG:32630", "vertical": None, "geoid": None,
                                    "source_crs": "EPSG:4978", "sigma_px": 1.0})
    except Exception:  # noqa: BLE001 - a fuzzed change may have left it odd; rebuild
        svc.delete_project("fuzz")
        svc.create_project(name="fuzz", id="fuzz", crs="EPSG:32630")
    have = {p.id for p in svc.list_points("fuzz")}
    for k in (1, 2, 3):
        if f"P{k}" not in have:
            svc.add_point("fuzz", {"id": f"P{k}", "rays": london_rays(3 + k)})
    for kind, fid, n in (("line", "L1", 2), ("polygon", "A1", 3)):
        try:
            svc.add_feature("fuzz", kind, {"id": fid, "points": ["P1", "P2", "P3"][:n]})
        except ConflictError:
            pass


@schema.parametrize()
@settings(max_examples=examples(8), deadline=None, suppress_health_check=list(HealthCheck))
def test_postgres_backed_api_never_answers_500(case, pg_projects):
    ensure_fixture_project(pg_projects)
    if case.path_parameters and next(_toggle) % 2 == 0:
        fixed = {"pid": "fuzz", "point_id": "P1", "fid": "L1" if "/lines/" in case.path else "A1",
                 "cid": "P1", "bid": "B1"}
        case.path_parameters = {k: fixed.get(k, v) for k, v in case.path_parameters.items()}
    case.call_and_validate(checks=[not_a_server_error, status_code_conformance])
