"""gsgeo.store on a real SQLite file and on a real PostgreSQL + PostGIS database (the
``backend`` parameter; the cluster is tests/pgcluster.py's): schema, transactions, solving,
recomputation, crashes. What only one backend has (SQLite's file, PostgreSQL's views and
servers) is tested here for SQLite and in tests/test_store_postgres.py for PostgreSQL."""

from __future__ import annotations

import json
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time

import numpy as np
import pyproj
import pytest
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)
from servertools import LONDON, REPO, ecef_of, london_rays, rays_at

from gsgeo.errors import CRSError, GeometryError, InputError
from gsgeo.service import Projects
from gsgeo.store import (
    DB_NAME,
    CheckPointRecord,
    ConflictError,
    FeatureRecord,
    NotFoundError,
    PointRecord,
    Project,
    StoreError,
    open_store,
)
from gsgeo.store.migrations import SCHEMA_VERSION

UTM30 = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:32630", always_xy=True)
UTM31 = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:32631", always_xy=True)


try:
    import psycopg

    INTEGRITY_ERRORS: tuple[type[Exception], ...] = (sqlite3.IntegrityError, psycopg.IntegrityError)
except ImportError:  # the PostgreSQL runs skip, naming what is missing (tests/pgcluster.py)
    INTEGRITY_ERRORS = (sqlite3.IntegrityError,)


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request) -> str | None:
    """None: the SQLite file of the test's data directory; else the URL of a fresh database
    (with PostGIS) on the session's PostgreSQL cluster."""
    if request.param == "sqlite":
        return None
    cluster = request.getfixturevalue("pg_cluster")
    return cluster.url(cluster.new_database())


@pytest.fixture
def store(tmp_path, store_url):
    s = open_store(tmp_path, store_url)
    yield s
    s.close()


@pytest.fixture
def svc(store, tmp_path):
    return Projects(store, tmp_path)


def test_new_store_is_wal_with_current_schema(tmp_path):
    store = open_store(tmp_path)
    try:
        assert (tmp_path / DB_NAME).is_file()
        assert store.schema_version == SCHEMA_VERSION
        con = sqlite3.connect(tmp_path / DB_NAME)
        assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        assert {"projects", "points", "features", "check_points"} <= tables
        con.close()
        assert store.check_integrity() == []
    finally:
        store.close()


def test_newer_schema_is_refused(tmp_path):
    s = open_store(tmp_path)
    s.close()
    con = sqlite3.connect(tmp_path / DB_NAME)
    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    con.commit()
    con.close()
    with pytest.raises(StoreError, match="newer"):
        open_store(tmp_path)


def test_not_a_database_is_a_clear_error(tmp_path):
    (tmp_path / DB_NAME).write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(StoreError, match="cannot open"):
        open_store(tmp_path)


def test_records_round_trip_across_restart(tmp_path, store_url):
    rays = london_rays(3)
    s = open_store(tmp_path, store_url)
    with s.transaction() as tx:
        tx.insert_project(Project(id="p1", name="One", crs="EPSG:32630", sigma_px=0.7))
        tx.insert_point(PointRecord(project_id="p1", id="A", rays=rays, code="c", excluded=[2],
                                    result={"x": 1.5}, record={"easting": 1.0}, solved_rev=0))
        tx.insert_point(PointRecord(project_id="p1", id="B", rays=rays, error="bad", solved_rev=0))
        tx.insert_feature(FeatureRecord(project_id="p1", kind="line", id="L1", point_ids=["A", "B"]))
        tx.upsert_check_points([CheckPointRecord(project_id="p1", id="A", x=1, y=2, z=None,
                                                 crs="EPSG:27700")])
    s.close()
    s = open_store(tmp_path, store_url)
    with s.transaction(write=False) as tx:
        p = tx.get_project("p1")
        pts = tx.list_points("p1")
        lines = tx.list_features("p1", "line")
        cps = tx.list_check_points("p1")
    s.close()
    assert (p.name, p.crs, p.sigma_px) == ("One", "EPSG:32630", 0.7)
    assert [q.id for q in pts] == ["A", "B"] and [q.seq for q in pts] == [1, 2]
    assert pts[0].rays == rays and pts[0].excluded == [2] and pts[0].result == {"x": 1.5}
    assert pts[1].result is None and pts[1].error == "bad"
    assert lines[0].point_ids == ["A", "B"]
    assert (cps[0].x, cps[0].y, cps[0].z, cps[0].crs) == (1, 2, None, "EPSG:27700")


def test_failed_transaction_leaves_nothing(store):
    with pytest.raises(RuntimeError), store.transaction() as tx:
        tx.insert_project(Project(id="p1", name="One"))
        tx.insert_point(PointRecord(project_id="p1", id="A", rays=london_rays(2), error="x"))
        raise RuntimeError("crash in the middle")
    with store.transaction(write=False) as tx:
        assert tx.list_projects() == []
        assert tx.list_points("p1") == []


def test_schema_refuses_half_points(store):
    """The table itself rejects a point with rays but neither a result nor an error."""
    with store.transaction() as tx:
        tx.insert_project(Project(id="p1", name="One"))
    with pytest.raises(INTEGRITY_ERRORS), store.transaction() as tx:
        tx.insert_point(PointRecord(project_id="p1", id="A", rays=london_rays(2)))
    with pytest.raises(INTEGRITY_ERRORS), store.transaction() as tx:
        tx.insert_point(PointRecord(project_id="p1", id="A", rays=london_rays(2)[:1], error="x"))


def test_point_is_solved_in_the_project_grid(svc):
    p = svc.create_project(name="London", crs="EPSG:32630")
    pt = svc.add_point(p.id, {"rays": london_rays(4), "code": "kerb"})
    e, n = UTM30.transform(LONDON[0], LONDON[1])
    rec = pt.record
    assert pt.id == "P1" and rec["point_id"] == "P1" and rec["code"] == "kerb"
    assert rec["crs"] == "EPSG:32630"
    assert rec["easting"] == pytest.approx(e, abs=1e-4)
    assert rec["northing"] == pytest.approx(n, abs=1e-4)
    assert rec["height"] == pytest.approx(LONDON[2], abs=1e-4)
    assert rec["n_rays"] == 4 and pt.solved_rev == p.settings_rev
    assert svc.add_point(p.id, {"rays": london_rays(3)}).id == "P2"


def test_changing_crs_resolves_every_point_from_rays(svc):
    p = svc.create_project(name="London", crs="EPSG:32630")
    targets = [(LONDON[0] + 0.001 * k, LONDON[1], 40.0 + k) for k in range(5)]
    for k, t in enumerate(targets):
        svc.add_point(p.id, {"id": f"T{k}", "rays": rays_at(ecef_of(*t), 3)})
    p2 = svc.update_project(p.id, {"crs": "EPSG:32631"})
    assert p2.settings_rev == p.settings_rev + 1
    for k, t in enumerate(targets):
        pt = svc.get_point(p.id, f"T{k}")
        e, n = UTM31.transform(t[0], t[1])
        assert pt.record["crs"] == "EPSG:32631" and pt.solved_rev == p2.settings_rev
        assert pt.record["easting"] == pytest.approx(e, abs=1e-4)
        assert pt.record["northing"] == pytest.approx(n, abs=1e-4)
    # a bad CRS changes nothing
    with pytest.raises(CRSError, match="crs"):
        svc.update_project(p.id, {"crs": "EPSG:999999"})
    assert svc.get_project(p.id).crs == "EPSG:32631"
    assert svc.get_point(p.id, "T0").record["crs"] == "EPSG:32631"


def test_sigma_px_change_rescales_the_angular_covariance(svc):
    """Angular model: the covariance is a-priori, so it scales with sigma_px squared."""
    p = svc.create_project(name="A", crs="EPSG:32630", sigma_px=1.0)
    svc.add_point(p.id, {"id": "A", "rays": london_rays(5, ifov=1e-3)})
    before = svc.get_point(p.id, "A").record["cov_ee"]
    svc.update_project(p.id, {"sigma_px": 2.0})
    after = svc.get_point(p.id, "A").record["cov_ee"]
    assert after == pytest.approx(4.0 * before, rel=1e-9)


def test_unsolvable_rays_are_refused_and_not_stored(svc):
    p = svc.create_project(name="A", crs="EPSG:32630")
    x = ecef_of(*LONDON)
    parallel = [{"origin": (x + [0, 0, 10 * k]).tolist(), "direction": [1.0, 0.0, 0.0]}
                for k in range(3)]
    with pytest.raises(GeometryError):
        svc.add_point(p.id, {"rays": parallel})
    with pytest.raises(InputError, match=r"rays\[1\].direction"):
        svc.add_point(p.id, {"rays": [london_rays(2)[0], {"origin": [0, 0, 0],
                                                           "direction": [0, 0, 0]}]})
    assert svc.list_points(p.id) == []


def test_exclude_and_restore_a_ray(svc):
    p = svc.create_project(name="A", crs="EPSG:32630")
    rays = london_rays(4)
    rays[2]["direction"] = (np.array(rays[2]["direction"]) + [0.02, 0, 0]).tolist()  # blunder
    pt = svc.add_point(p.id, {"id": "A", "rays": rays})
    e, _ = UTM30.transform(LONDON[0], LONDON[1])
    e_blunder = pt.record["easting"]
    off_before = abs(e_blunder - e)
    pt = svc.update_point(p.id, "A", {"exclude_ray": 2})
    assert pt.excluded == [2] and pt.record["n_rays"] == 3
    assert abs(pt.record["easting"] - e) < 1e-4 < off_before
    assert [r["excluded"] for r in pt.result["rays"]] == [False, False, True, False]
    with pytest.raises(InputError, match="at least two rays"):
        svc.update_point(p.id, "A", {"excluded": [0, 1, 2]})
    assert svc.get_point(p.id, "A").excluded == [2]
    with pytest.raises(InputError, match="out of range"):
        svc.update_point(p.id, "A", {"exclude_ray": 7})
    pt = svc.update_point(p.id, "A", {"restore_ray": 2})
    assert pt.excluded == [] and pt.record["n_rays"] == 4
    assert pt.record["easting"] == pytest.approx(e_blunder, abs=1e-9)


def test_rename_carries_into_lines_and_delete_is_guarded(svc):
    p = svc.create_project(name="A", crs="EPSG:32630")
    for k in range(3):
        svc.add_point(p.id, {"id": f"P{k}", "rays": rays_at(ecef_of(LONDON[0] + 1e-4 * k,
                                                                      LONDON[1], 50), 3)})
    svc.add_feature(p.id, "line", {"id": "L", "points": ["P0", "P1", "P2"]})
    pt = svc.update_point(p.id, "P1", {"id": "Q1", "code": "wall"})
    assert pt.record["point_id"] == "Q1" and pt.record["code"] == "wall"
    f, _ = svc.get_feature(p.id, "line", "L")
    assert f.point_ids == ["P0", "Q1", "P2"]
    with pytest.raises(ConflictError, match="line 'L'"):
        svc.delete_point(p.id, "Q1")
    with pytest.raises(ConflictError, match="already exists"):
        svc.update_point(p.id, "P0", {"id": "P2"})
    svc.delete_feature(p.id, "line", "L")
    svc.delete_point(p.id, "Q1")
    with pytest.raises(NotFoundError):
        svc.get_point(p.id, "Q1")


def test_features_need_existing_points(svc):
    p = svc.create_project(name="A", crs="EPSG:32630")
    svc.add_point(p.id, {"id": "A", "rays": london_rays(3)})
    with pytest.raises(InputError, match=r"points\[1\]: point 'B' does not exist"):
        svc.add_feature(p.id, "line", {"points": ["A", "B"]})
    with pytest.raises(InputError, match="at least 3 points"):
        svc.add_feature(p.id, "polygon", {"points": ["A", "A"]})


def test_deleting_a_project_deletes_everything_in_it(svc, store):
    p = svc.create_project(name="A", crs="EPSG:32630")
    svc.add_point(p.id, {"id": "A", "rays": london_rays(3)})
    svc.delete_project(p.id)
    with store.transaction(write=False) as tx:
        assert tx.list_points(p.id) == []
    with pytest.raises(NotFoundError):
        svc.delete_project(p.id)


WRITER = textwrap.dedent("""
    import sys
    sys.path.insert(0, {tests!r})
    from servertools import ecef_of, rays_at, LONDON
    from gsgeo.service import Projects, open_store
    svc = Projects(open_store({data!r}, {url!r}))
    pid = svc.create_project(name="crash", id="crash", crs="EPSG:32630").id
    crs = ["EPSG:32630", "EPSG:32631"]
    i = 0
    while True:
        svc.add_point(pid, {{"id": f"P{{i}}", "rays": rays_at(ecef_of(LONDON[0] + 1e-5 * i,
                                                               LONDON[1], 50), 3)}})
        print(i, flush=True)
        if i % 7 == 6:  # a big transaction: every point re-solved
            svc.update_project(pid, {{"crs": crs[(i // 7) % 2]}})
        i += 1
""")


def test_kill_9_in_the_middle_of_writes_leaves_a_consistent_store(tmp_path, store_url):
    data = tmp_path / "data"
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITER.format(tests=str(REPO / "tests"), data=str(data),
                                             url=store_url)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    acknowledged = -1
    t0 = time.monotonic()
    while acknowledged < 40 and time.monotonic() - t0 < 120:
        line = proc.stdout.readline()
        if not line:
            break
        acknowledged = int(line)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert acknowledged >= 40, proc.stderr.read()
    s = open_store(data, store_url)
    try:
        assert s.check_integrity() == []
        with s.transaction(write=False) as tx:
            p = tx.get_project("crash")
            pts = tx.list_points("crash")
    finally:
        s.close()
    ids = {q.id for q in pts}
    assert {f"P{i}" for i in range(acknowledged + 1)} <= ids  # nothing acknowledged is lost
    for q in pts:  # no half-written point, no point left with other settings than its project
        assert len(q.rays) == 3 and q.error is None
        assert q.solved_rev == p.settings_rev
        assert q.record["crs"] == p.crs and q.record["n_rays"] == 3
        assert json.loads(json.dumps(q.result))["point_id"] == q.id


def test_a_new_migration_upgrades_an_existing_store_in_place(tmp_path, monkeypatch):
    """Opening a store of an older schema applies the missing migrations and keeps the data."""
    import gsgeo.store.sqlite as sq

    s = open_store(tmp_path)
    with s.transaction() as tx:
        tx.insert_project(Project(id="p1", name="One"))
    s.close()
    extra = "ALTER TABLE projects ADD COLUMN colour TEXT NOT NULL DEFAULT 'red'"
    monkeypatch.setattr(sq, "MIGRATIONS", [*sq.MIGRATIONS, extra])
    monkeypatch.setattr(sq, "SCHEMA_VERSION", SCHEMA_VERSION + 1)
    s = open_store(tmp_path)
    try:
        assert s.schema_version == SCHEMA_VERSION + 1
        with s.transaction(write=False) as tx:
            assert tx.get_project("p1").name == "One"
            assert tx.con.execute("SELECT colour FROM projects").fetchone()[0] == "red"
    finally:
        s.close()
    # a failing migration leaves the store at the old version, unharmed
    monkeypatch.setattr(sq, "MIGRATIONS", [*sq.MIGRATIONS, "CREATE TABLE broken (x"])
    monkeypatch.setattr(sq, "SCHEMA_VERSION", SCHEMA_VERSION + 2)
    with pytest.raises(StoreError):
        open_store(tmp_path)
    con = sqlite3.connect(tmp_path / DB_NAME)
    assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION + 1
    con.close()


def test_update_results_writes_the_measured_state_only(store):
    with store.transaction() as tx:
        tx.insert_project(Project(id="p", name="p"))
        tx.insert_point(PointRecord(project_id="p", id="A", rays=[{"origin": [1, 2, 3],
                                    "direction": [0, 0, 1]}] * 2, code="c", error="e"))
    with store.transaction() as tx:
        pt = tx.list_points("p", results=False)[0]
        pt.code = "changed in memory only"
        pt.result, pt.error, pt.solved_rev = {"point_id": "A", "x": float("nan")}, None, 7
        pt.frame = {"version": 2, "root_transform": [1.0] * 16}
        tx.update_results([pt])
    with store.transaction(write=False) as tx:
        got = tx.get_point("p", "A")
    assert got is not None and got.code == "c" and got.error is None and got.solved_rev == 7
    assert got.result == {"point_id": "A", "x": None}  # non-finite numbers stored as null
    assert got.frame == {"version": 2, "root_transform": [1.0] * 16}
    assert got.rays[0]["origin"] == [1, 2, 3]


def test_a_closed_store_opens_again_when_used(store):
    """As an app's lifespan ends (closing the store) and another begins on the same store."""
    with store.transaction() as tx:
        tx.insert_project(Project(id="p", name="p"))
    store.close()
    with store.transaction(write=False) as tx:
        assert [p.id for p in tx.list_projects()] == ["p"]
    store.close()
    with store.transaction() as tx:
        tx.delete_project("p")
    assert store.revision() is not None


def test_pages_of_point_records_follow_the_filter_reference(store):
    """page_point_records / count_point_records (what the OGC API pages with) give, on each
    backend, exactly the solved points PointFilter.matches passes, in creation order."""
    from datetime import UTC, datetime, timedelta, timezone

    from gsgeo.store.base import PointFilter

    t0 = datetime(2026, 5, 1, 12, 0, tzinfo=UTC)
    with store.transaction() as tx:
        tx.insert_project(Project(id="p", name="p"))
        for k in range(12):
            when = t0 + timedelta(minutes=k)
            stamp = when.astimezone(timezone(timedelta(hours=k % 3))).isoformat(
                timespec="milliseconds")
            stamp = "not a time" if k == 5 else stamp
            result = {"point_id": f"A{k}", "code": "kerb" if k % 2 else "wall",
                      "lon": 179.5 + 0.1 * k - (360 if k > 5 else 0), "lat": 10.0 + k,
                      "easting": 1000.0 * k, "northing": 5e5 + k, "measured_at": stamp}
            tx.insert_point(PointRecord(project_id="p", id=f"A{k}", rays=london_rays(2),
                                        code=result["code"], result=result))
        tx.insert_point(PointRecord(project_id="p", id="unsolved", rays=london_rays(2),
                                    error="no result"))
    filters = [None, PointFilter(code="kerb"), PointFilter(code="none"),
               PointFilter(measured_from=t0 + timedelta(minutes=3)),
               PointFilter(measured_to=t0 + timedelta(minutes=4), code="wall"),
               PointFilter(measured_from=t0 + timedelta(minutes=2, seconds=30),
                           measured_to=t0 + timedelta(minutes=9)),
               PointFilter(box=("easting", "northing", 2500.0, 0.0, 8000.0, 1e6)),
               PointFilter(box=("lon", "lat", 179.0, 10.0, -179.0, 30.0)),  # over the antimeridian
               PointFilter(box=("lon", "lat", 179.0, 10.0, -179.0, 30.0), code="kerb",
                           measured_from=t0)]
    with store.transaction(write=False) as tx:
        everything = [p for p in tx.list_points("p") if p.record is not None]
        for f in filters:
            want = [p.id for p in everything if (f or PointFilter()).matches(p.record)]
            rows = tx.page_point_records("p", f)
            assert [r.id for r in rows] == want, f
            assert tx.count_point_records("p", f) == len(want), f
            assert [r.id for r in tx.page_point_records("p", f, offset=1, limit=2)] == want[1:3]
            assert all(r.record == everything[int(r.id[1:])].record for r in rows)
    assert len(everything) == 12
