"""gsgeo.store.sqlitebulk: the SQLite store writes many re-measured results in chunks on a
writer thread. What it writes is what a row-by-row UPDATE writes; a failure on either
thread leaves the store as it was; each chunk finds its points by primary key."""

from __future__ import annotations

import sqlite3
import threading

import pytest

from gsgeo.store import DB_NAME, PointRecord, Project, open_store, sqlitebulk
from gsgeo.store.sqlitebulk import CHUNK, update_sql

N = 2 * CHUNK + 37  # two full chunks and a short one
RAYS = [{"origin": [1, 2, 3], "direction": [0, 0, 1]}] * 2


@pytest.fixture
def store(tmp_path):
    s = open_store(tmp_path)
    with s.transaction() as tx:
        tx.insert_project(Project(id="p", name="p"))
        tx.insert_project(Project(id="q", name="q"))
        for i in range(N):
            tx.insert_point(PointRecord(project_id="p", id=f"A{i}", rays=RAYS, error="e"))
        tx.insert_point(PointRecord(project_id="q", id="A0", rays=RAYS, error="untouched"))
    yield s
    s.close()


def _new_state(pts: list[PointRecord]) -> None:
    for i, pt in enumerate(pts):
        if i % 7 == 3:  # a point that fails keeps its reason
            pt.result, pt.error = None, f"reason {i}"
        else:
            pt.result = {"point_id": pt.id, "e": i + 0.25, "n": [i, 1.5 if i == 5 else float("inf")],
                         "big": 2**70 if i == 5 else i, "t": "é\"\\"}
            pt.error = None
        pt.solved_rev = i
        pt.frame = {"version": i % 3, "root_transform": [1.0] * 16}


def test_chunks_write_what_row_by_row_writes(store):
    with store.transaction() as tx:
        pts = tx.list_points("p", results=False)
        versions = [pt.version for pt in pts]
        _new_state(pts)
        tx.update_results(iter(pts))
    with store.transaction(write=False) as tx:
        got = {pt.id: pt for pt in tx.list_points("p")}
        other = tx.get_point("q", "A0")
    assert len(got) == N and other is not None and other.error == "untouched"
    for i, pt in enumerate(pts):
        g = got[pt.id]
        assert g.version == versions[i] + 1 == pt.version
        assert g.solved_rev == i and g.frame == {"version": i % 3, "root_transform": [1.0] * 16}
        assert g.updated_at == pt.updated_at
        if i % 7 == 3:
            assert g.result is None and g.error == f"reason {i}"
        else:
            # non-finite as null; an integer beyond 64 bits as the standard library writes it
            assert g.error is None and g.result == {
                "point_id": pt.id, "e": i + 0.25, "n": [i, 1.5 if i == 5 else None],
                "big": 2**70 if i == 5 else i, "t": "é\"\\"}


def test_a_failing_maker_leaves_the_store_as_it_was(store):
    with store.transaction(write=False) as tx:
        before = [(p.id, p.error, p.version) for p in tx.list_points("p")]

    def failing(pts):
        for i, pt in enumerate(pts):
            if i == CHUNK + 10:  # after a whole chunk went to the writer
                raise RuntimeError("the measurement failed")
            yield pt

    with pytest.raises(RuntimeError, match="measurement failed"):
        with store.transaction() as tx:
            pts = tx.list_points("p", results=False)
            _new_state(pts)
            tx.update_results(failing(pts))
    with store.transaction(write=False) as tx:
        assert [(p.id, p.error, p.version) for p in tx.list_points("p")] == before
    assert not [t for t in threading.enumerate() if t.name == "gsgeo-store-writer"]


def test_a_failing_write_is_raised_and_leaves_the_store_as_it_was(store):
    with store.transaction(write=False) as tx:
        before = [(p.id, p.error, p.version) for p in tx.list_points("p")]
    with pytest.raises(sqlite3.IntegrityError):
        with store.transaction() as tx:
            pts = tx.list_points("p", results=False)
            _new_state(pts)
            pts[CHUNK + 1].result = pts[CHUNK + 1].error = None  # the schema refuses it
            tx.update_results(pts)
    with store.transaction(write=False) as tx:
        assert [(p.id, p.error, p.version) for p in tx.list_points("p")] == before
    assert not [t for t in threading.enumerate() if t.name == "gsgeo-store-writer"]


def test_each_chunk_finds_its_points_by_primary_key(store, tmp_path):
    """Not a scan of the project's points per element (quadratic in the points)."""
    con = sqlite3.connect(tmp_path / DB_NAME)
    plan = [r[3] for r in con.execute("EXPLAIN QUERY PLAN " + update_sql(3), ["x"] * 21)]
    con.close()
    assert any(p.startswith("SEARCH points USING") and "(project_id=? AND id=?)" in p
               for p in plan), plan
    assert not any(p.startswith("SCAN points") for p in plan), plan
    assert sqlitebulk.CHUNK * 7 < 32766  # SQLite's limit on a statement's parameters


def test_a_remeasure_in_blocks_keeps_every_point_and_its_reason(tmp_path, monkeypatch):
    """Blocks of 2 points (gsgeo.service.projects.REMEASURE_BLOCK), chunks of 3 rows: each
    point gets its own new result, in the new grid (pyproj directly), and a point whose
    stored rays cannot be read keeps a reason, wherever it falls between blocks."""
    import pyproj
    from servertools import LONDON, ecef_of, rays_at

    import gsgeo.service.projects as projects
    from gsgeo.service import Projects

    monkeypatch.setattr(projects, "REMEASURE_BLOCK", 2)
    monkeypatch.setattr(sqlitebulk, "CHUNK", 3)
    store = open_store(tmp_path)
    try:
        svc = Projects(store, tmp_path)
        p = svc.create_project(name="L", crs="EPSG:32630")
        targets = [(LONDON[0] + 0.001 * k, LONDON[1], 40.0 + k) for k in range(7)]
        for k, t in enumerate(targets):
            svc.add_point(p.id, {"id": f"T{k}", "rays": rays_at(ecef_of(*t), 3)})
        bad = {"T2", "T3", "T6"}  # a block's end, the next block's start, the last point
        with store.transaction() as tx:
            for pt in tx.list_points(p.id):
                if pt.id in bad:
                    pt.rays = [{"origin": [1, 2, 3], "direction": [0, 0, 0]}] * 2
                    tx.update_point(pt)
        svc.update_project(p.id, {"crs": "EPSG:32631"})
        utm31 = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:32631", always_xy=True)
        for k, t in enumerate(targets):
            pt = svc.get_point(p.id, f"T{k}")
            if pt.id in bad:
                assert pt.result is None and "direction" in (pt.error or "")
                continue
            e, n = utm31.transform(t[0], t[1])
            assert pt.error is None and pt.record["point_id"] == pt.id
            assert pt.record["easting"] == pytest.approx(e, abs=1e-4)
            assert pt.record["northing"] == pytest.approx(n, abs=1e-4)
    finally:
        store.close()
