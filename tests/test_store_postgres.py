"""What only the PostgreSQL + PostGIS store has: typed PostGIS views in geometry_columns, its
errors (a bad URL, an unreachable server, a database without PostGIS), its migrations, and
several stores ("servers") writing to one database at once. The behaviour both backends share
is tested in tests/test_store.py against each."""

from __future__ import annotations

import threading
import time

import pyproj
import pytest
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)
from servertools import LONDON, ecef_of, london_rays, rays_at

from gsgeo.cli import main
from gsgeo.errors import InputError
from gsgeo.service import Projects
from gsgeo.store import PointRecord, Project, StoreError, open_store
from gsgeo.store.base import PointFilter

BNG = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:27700", always_xy=True)


@pytest.fixture
def cluster(request):
    """The session's cluster (tests/pgcluster.py), started on first use."""
    return request.getfixturevalue("pg_cluster")


@pytest.fixture
def db(cluster) -> str:
    """A fresh database with PostGIS; its name."""
    return cluster.new_database()


@pytest.fixture
def store(cluster, db, tmp_path):
    s = open_store(tmp_path, cluster.url(db))
    yield s
    s.close()


def geometry_columns(cluster, db) -> dict[str, tuple]:
    rows = cluster.sql(db, "SELECT f_table_name, f_geometry_column, type, srid, coord_dimension"
                           " FROM geometry_columns ORDER BY f_table_name")
    return {r[0]: r[1:] for r in rows}


def test_each_project_has_typed_postgis_views_in_its_grid_srid_with_z(cluster, db, store,
                                                                      tmp_path):
    svc = Projects(store, tmp_path)
    p = svc.create_project(name="Survey", id="site-a", crs="EPSG:27700")
    targets = [(LONDON[0] + 1e-4 * k, LONDON[1] + 1e-4 * (k % 2), 40.0 + k) for k in range(4)]
    for k, t in enumerate(targets):
        svc.add_point(p.id, {"id": f"P{k}", "rays": rays_at(ecef_of(*t), 3), "code": "kerb"})
    svc.add_feature(p.id, "line", {"id": "L", "points": ["P0", "P1", "P2"]})
    svc.add_feature(p.id, "polygon", {"id": "G", "points": ["P0", "P1", "P2", "P3"]})

    cols = geometry_columns(cluster, db)
    assert cols == {"gsgeo_site_a_buildings": ("geom", "POLYGON", 27700, 3),
                    "gsgeo_site_a_lines": ("geom", "LINESTRING", 27700, 3),
                    "gsgeo_site_a_points": ("geom", "POINT", 27700, 3),
                    "gsgeo_site_a_polygons": ("geom", "POLYGON", 27700, 3)}
    rows = cluster.sql(db, "SELECT point_id, code, crs, n_rays, easting, northing, height,"
                              " ST_X(geom), ST_Y(geom), ST_Z(geom), ST_SRID(geom),"
                              " measured_at IS NOT NULL FROM gsgeo_site_a_points ORDER BY fid")
    assert [r[0] for r in rows] == ["P0", "P1", "P2", "P3"]
    for r, t in zip(rows, targets, strict=True):
        rec = svc.get_point(p.id, r[0]).record
        assert r[1:4] == ("kerb", "EPSG:27700", 3) and r[10] == 27700 and r[11] is True
        assert r[4:7] == (rec["easting"], rec["northing"], rec["height"])  # exactly as stored
        e, n = BNG.transform(t[0], t[1])  # (pyproj's own pick of the operation: ~1 mm apart)
        assert r[4] == pytest.approx(e, abs=0.01) and r[5] == pytest.approx(n, abs=0.01)
        assert r[6] == pytest.approx(t[2], abs=1e-3)  # no vertical datum: ellipsoidal
        assert (r[7], r[8], r[9]) == (r[4], r[5], r[6])  # the geometry is the record's E, N, H
    line = cluster.sql(db, "SELECT id, ST_NPoints(geom), ST_Z(ST_PointN(geom, 3))"
                              " FROM gsgeo_site_a_lines")
    assert line == [("L", 3, pytest.approx(rows[2][6]))]
    poly = cluster.sql(db, "SELECT id, ST_NPoints(geom), ST_IsClosed(ST_ExteriorRing(geom)),"
                              " ST_Area(geom) > 0 FROM gsgeo_site_a_polygons")
    assert poly == [("G", 5, True, True)]

    # a CRS change re-types the views; a delete drops them
    svc.update_project(p.id, {"crs": "EPSG:32630"})
    assert {v[2] for v in geometry_columns(cluster, db).values()} == {32630}
    e30 = cluster.sql(db, "SELECT ST_X(geom) FROM gsgeo_site_a_points WHERE point_id = 'P0'")
    assert e30[0][0] == pytest.approx(svc.get_point(p.id, "P0").record["easting"], abs=1e-9)
    svc.delete_project(p.id)
    assert geometry_columns(cluster, db) == {}


def test_view_names_keep_projects_apart(cluster, db, store):
    with store.transaction() as tx:
        for pid in ("a-b", "a_b", "A-B"):
            tx.insert_project(Project(id=pid, name=pid, crs="EPSG:27700+5701"))
    names = set(geometry_columns(cluster, db))
    assert len(names) == 12 and "gsgeo_a_b_points" in names
    assert all(len(n) <= 63 and n == n.lower() for n in names)
    assert {v[2] for v in geometry_columns(cluster, db).values()} == {27700}


def test_a_database_without_postgis_is_a_clear_error(cluster, tmp_path):
    name = cluster.new_database(postgis=False)
    cluster.sql("postgres", "CREATE ROLE plain LOGIN")
    try:
        cluster.sql("postgres", f"ALTER DATABASE {name} OWNER TO plain")
        with pytest.raises(StoreError, match=r"no PostGIS and this role may not enable it.*"
                                             r"CREATE EXTENSION postgis"):
            open_store(tmp_path, cluster.url(name, user="plain"))
        assert cluster.sql(name, "SELECT to_regclass('projects')") == [(None,)]
        # the superuser may enable it: the store does so itself
        s = open_store(tmp_path, cluster.url(name))
        s.close()
        assert cluster.sql(name, "SELECT count(*) FROM pg_extension"
                                    " WHERE extname = 'postgis'") == [(1,)]
    finally:
        cluster.sql("postgres", f"DROP DATABASE {name}")
        cluster.sql("postgres", "DROP ROLE plain")


@pytest.mark.parametrize(("url", "message"), [
    ("mysql://u:secret@127.0.0.1/db", "a mysql:// URL is not supported; give postgresql://"),
    ("gsgeo.sqlite", "'gsgeo.sqlite' is not a URL"),
    ("postgresql://u:secret@127.0.0.1:5432", "names no database"),
    ("postgresql://u:secret@127.0.0.1:1/db", "cannot connect to PostgreSQL at "
                                              r"postgresql://u:\*\*\*@127.0.0.1:1/db"),
])
def test_bad_store_urls_are_clear_errors(tmp_path, url, message):
    pytest.importorskip("psycopg", reason="psycopg 3 is not installed (pip install -e .)")
    with pytest.raises(StoreError, match=message) as err:
        open_store(tmp_path, url)
    assert "secret" not in str(err.value)


def test_serve_with_a_bad_store_exits_2_naming_it(tmp_path, capsys, monkeypatch):
    pytest.importorskip("psycopg", reason="psycopg 3 is not installed (pip install -e .)")
    data = str(tmp_path / "data")
    assert main(["serve", "--data", data, "--port", "0", "--store",
                 "mysql://u:secret@h/db"]) == 2
    err = capsys.readouterr().err
    assert "a mysql:// URL is not supported" in err and "Traceback" not in err
    assert "secret" not in err
    monkeypatch.setenv("GSGEO_STORE", "postgresql://u:secret@127.0.0.1:1/db")
    assert main(["serve", "--data", data, "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert "cannot connect to PostgreSQL at postgresql://u:***@127.0.0.1:1/db" in err
    assert "secret" not in err and "Traceback" not in err


def test_newer_schema_is_refused_and_a_new_migration_upgrades_in_place(cluster, db, tmp_path,
                                                                        monkeypatch):
    import gsgeo.store.postgres as pg

    url = cluster.url(db)
    s = open_store(tmp_path, url)
    with s.transaction() as tx:
        tx.insert_project(Project(id="p1", name="One"))
    s.close()
    extra = "ALTER TABLE projects ADD COLUMN colour TEXT NOT NULL DEFAULT 'red'"
    monkeypatch.setattr(pg, "MIGRATIONS", [*pg.MIGRATIONS, extra])
    monkeypatch.setattr(pg, "SCHEMA_VERSION", pg.SCHEMA_VERSION + 1)
    s = open_store(tmp_path, url)
    try:
        assert s.schema_version == pg.SCHEMA_VERSION
        assert cluster.sql(db, "SELECT name, colour FROM projects") == [("One", "red")]
    finally:
        s.close()
    # a failing migration leaves the database at the old version, unharmed
    monkeypatch.setattr(pg, "MIGRATIONS", [*pg.MIGRATIONS, "CREATE TABLE broken (x"])
    monkeypatch.setattr(pg, "SCHEMA_VERSION", pg.SCHEMA_VERSION + 1)
    with pytest.raises(StoreError, match="cannot prepare the gsgeo schema"):
        open_store(tmp_path, url)
    assert cluster.sql(db, "SELECT version FROM gsgeo_schema") == [(pg.SCHEMA_VERSION - 1,)]
    # a database of a newer gsgeo is refused, not written to
    cluster.sql(db, "UPDATE gsgeo_schema SET version = 99")
    with pytest.raises(StoreError, match="newer"):
        open_store(tmp_path, url)


def test_two_servers_on_one_database_lose_no_write(cluster, db, tmp_path):
    """Two stores (as two `gsgeo serve` processes would have) and eight writers: every
    read-decide-write is serialised, so no increment and no point is lost, seqs are unique."""
    url = cluster.url(db)
    stores = [open_store(tmp_path, url), open_store(tmp_path, url)]
    try:
        with stores[0].transaction() as tx:
            tx.insert_project(Project(id="p", name="p", crs="EPSG:27700"))
        rays = london_rays(2)
        errors: list[BaseException] = []

        def writer(w: int) -> None:
            try:
                for i in range(15):
                    with stores[w % 2].transaction() as tx:
                        p = tx.get_project("p")
                        p.settings_rev += 1  # read, decide, write
                        tx.update_project(p)
                        tx.insert_point(PointRecord(project_id="p", id=f"W{w}-{i}", rays=rays,
                                                    error="not solved"))
            except BaseException as exc:  # reported below
                errors.append(exc)

        threads = [threading.Thread(target=writer, args=(w,)) for w in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert errors == []
        with stores[1].transaction(write=False) as tx:
            assert tx.get_project("p").settings_rev == 8 * 15
            pts = tx.list_points("p")
        assert len(pts) == 8 * 15 and sorted(q.seq for q in pts) == list(range(1, 121))
        assert stores[0].revision() == stores[1].revision()
    finally:
        for s in stores:
            s.close()


def test_readers_do_not_wait_for_a_long_write(store):
    with store.transaction() as tx:
        tx.insert_project(Project(id="p", name="before"))
    inside, release = threading.Event(), threading.Event()

    def long_write() -> None:
        with store.transaction() as tx:
            p = tx.get_project("p")
            p.name = "after"
            tx.update_project(p)
            inside.set()
            release.wait(10)

    t = threading.Thread(target=long_write)
    t.start()
    try:
        assert inside.wait(10)
        t0 = time.monotonic()
        with store.transaction(write=False) as tx:
            assert tx.get_project("p").name == "before"  # the last committed state
        assert time.monotonic() - t0 < 1.0
    finally:
        release.set()
        t.join()
    with store.transaction(write=False) as tx:
        assert tx.get_project("p").name == "after"


def test_text_with_a_nul_character_is_refused_naming_it(store, tmp_path):
    """PostgreSQL text cannot hold U+0000: a clear InputError (the API's 422), not an internal
    error, and nothing is written."""
    svc = Projects(store, tmp_path)
    with pytest.raises(InputError, match=r"'a<NUL>b' holds a NUL character"):
        svc.create_project(name="a\x00b", crs="EPSG:27700")
    p = svc.create_project(name="ok", id="ok", crs="EPSG:27700")
    with pytest.raises(InputError, match="NUL character"):
        svc.add_point(p.id, {"id": "A", "rays": london_rays(3), "description": "x\x00"})
    with store.transaction(write=False) as tx:
        assert [q.id for q in tx.list_projects()] == ["ok"] and tx.list_points("ok") == []
        assert tx.count_point_records("ok", PointFilter(code="a\\u0000")) == 0
    with pytest.raises(InputError, match="NUL character"), store.transaction() as tx:
        tx.count_point_records("ok", PointFilter(code="\x00"))


QGIS_READS_LAYER = """
import json, sys
from qgis.core import QgsApplication, QgsVectorLayer, QgsWkbTypes
app = QgsApplication([], False)
app.initQgis()
out = {}
for kind in ("points", "lines", "polygons"):
    # no type or SRID given: QGIS reads them from geometry_columns, as 'Add PostGIS Layers' does
    layer = QgsVectorLayer(sys.argv[1] + f' key=fid table="public"."gsgeo_site_b_{kind}" (geom)',
                           kind, "postgres")
    feats = list(layer.getFeatures()) if layer.isValid() else []
    out[kind] = {"valid": layer.isValid(), "crs": layer.crs().authid(),
                 "type": QgsWkbTypes.displayString(layer.wkbType()), "n": len(feats),
                 "fields": [f.name() for f in layer.fields()],
                 "first": [feats[0]["point_id"], feats[0].geometry().constGet().z()]
                 if kind == "points" and feats else None}
print(json.dumps(out))
app.exitQgis()
"""


def test_qgis_opens_the_views_as_typed_layers_in_the_grid(cluster, db, store, tmp_path):
    """Debian's QGIS (python3-qgis) loads each view through its PostGIS provider, as a GIS
    analyst would: PointZ / LineStringZ / PolygonZ in EPSG:27700 with the record columns."""
    import json
    import os
    import subprocess

    from test_qgis_plugin import QGIS_PYTHON, qgis_missing

    reason = qgis_missing()
    if reason is not None:
        pytest.skip(reason)
    svc = Projects(store, tmp_path)
    p = svc.create_project(name="b", id="site-b", crs="EPSG:27700")
    for k in range(3):
        svc.add_point(p.id, {"id": f"P{k}", "rays": rays_at(ecef_of(LONDON[0] + 1e-4 * k,
                                                                      LONDON[1] + 1e-4 * (k == 2),
                                                                      45.0), 3)})
    svc.add_feature(p.id, "line", {"id": "L", "points": ["P0", "P1"]})
    svc.add_feature(p.id, "polygon", {"id": "G", "points": ["P0", "P1", "P2"]})
    conninfo = f"dbname='{db}' host=127.0.0.1 port={cluster.port} user='postgres'"
    proc = subprocess.run([QGIS_PYTHON, "-c", QGIS_READS_LAYER, conninfo], capture_output=True,
                          text=True, cwd="/", timeout=120,
                          env={**os.environ, "QT_QPA_PLATFORM": "offscreen"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert {k: (v["valid"], v["crs"], v["type"], v["n"]) for k, v in got.items()} == {
        "points": (True, "EPSG:27700", "PointZ", 3), "lines": (True, "EPSG:27700", "LineStringZ", 1),
        "polygons": (True, "EPSG:27700", "PolygonZ", 1)}
    assert {"point_id", "easting", "northing", "height", "sigma_h", "measured_at"} <= \
        set(got["points"]["fields"])
    assert got["points"]["first"] == ["P0", svc.get_point(p.id, "P0").record["height"]]
