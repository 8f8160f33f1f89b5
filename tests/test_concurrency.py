"""Optimistic concurrency: item versions in the store, ETag / If-Match / 412 in the API."""

from __future__ import annotations

import sqlite3

import pytest
from servertools import london_rays

from gsgeo.store import (
    DB_NAME,
    BuildingRecord,
    FeatureRecord,
    PointRecord,
    PreconditionFailed,
    Project,
    open_store,
)
from gsgeo.store.migrations import MIGRATIONS


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
        assert s.schema_version == 6
        with s.transaction(write=False) as tx:
            assert tx.get_point("p", "P1").version == 1
            assert tx.get_feature("p", "line", "L1").version == 1
            assert tx.get_building("p", "B1").version == 1
    finally:
        s.close()
