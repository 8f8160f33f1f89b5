"""The PostGIS layers GIS clients read straight from the database: each project's buildings
(one typed PolygonZ per surface, in the project's SRID, following every change of their
points) and the points' provenance columns (measured_by, rays clicked and matched). QGIS-free:
geometry_columns and PostGIS functions say what QGIS would see."""

from __future__ import annotations

import json

import numpy as np
import pytest
from building_helpers import CRS, GROUND, ROOFS, house_points
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)

from gsgeo.pointschema import BUILDING_TYPES
from gsgeo.service import Projects
from gsgeo.service.exporting import export_project
from gsgeo.store import open_store
from gsgeo.store.pgviews import VIEWS_VERSION

HOUSE = {"id": "B1", "roofs": ROOFS, "ground": GROUND, "attributes": {"function": "shed"}}


@pytest.fixture
def cluster(request):
    """The session's cluster (tests/pgcluster.py), started on first use."""
    return request.getfixturevalue("pg_cluster")


@pytest.fixture
def db(cluster) -> str:
    return cluster.new_database()


@pytest.fixture
def svc(cluster, db, tmp_path):
    store = open_store(tmp_path, cluster.url(db))
    yield Projects(store, tmp_path)
    store.close()


@pytest.fixture
def house(svc) -> str:
    svc.create_project(name="house", id="h", crs=CRS)
    for p in house_points():
        svc.add_point("h", p)
    svc.add_building("h", HOUSE)
    return "h"


def layer_vertices(cluster, db, view: str = "gsgeo_h_buildings") -> np.ndarray:
    """Every vertex (E, N, H) of the view's surfaces, rings closed, sorted."""
    rows = cluster.sql(db, f"SELECT ST_X(d.geom), ST_Y(d.geom), ST_Z(d.geom) FROM {view} v,"
                           " ST_DumpPoints(v.geom) d")
    return np.array(sorted(rows), dtype=float)


def city_vertices(svc, pid: str, tmp_path) -> np.ndarray:
    """The distinct vertices of the project's CityJSON export (its millimetre transform
    applied), sorted."""
    path, _ = export_project(svc, pid, tmp_path, "cityjson")
    doc = json.loads(path.read_text())
    t = doc["transform"]
    v = np.array(doc["vertices"], dtype=float) * t["scale"] + t["translate"]
    return np.array(sorted(map(tuple, v)), dtype=float)


def test_buildings_are_a_typed_postgis_layer_that_follows_its_points(cluster, db, svc, house,
                                                                     tmp_path):
    cols = cluster.sql(db, "SELECT f_geometry_column, type, srid, coord_dimension"
                           " FROM geometry_columns WHERE f_table_name = 'gsgeo_h_buildings'")
    assert cols == [("geom", "POLYGON", 27700, 3)]
    names = [r[0] for r in cluster.sql(
        db, "SELECT column_name FROM information_schema.columns WHERE table_name ="
            " 'gsgeo_h_buildings' ORDER BY ordinal_position")]
    assert names == ["fid", *BUILDING_TYPES, "geom"]  # the export schema as columns

    rows = cluster.sql(db, "SELECT building_id, surface_type, volume, ST_SRID(geom),"
                           " ST_IsClosed(ST_ExteriorRing(geom)) FROM gsgeo_h_buildings"
                           " ORDER BY surface_index")
    built = svc.get_building("h", "B1")
    types = [r[1] for r in rows]
    assert types == [s["kind"] for s in built["surfaces"]]
    assert types.count("RoofSurface") == 2 and types.count("GroundSurface") == 1
    assert {r[0] for r in rows} == {"B1"} and {r[3] for r in rows} == {27700}
    assert all(r[4] for r in rows)
    assert rows[0][2] == pytest.approx(built["measures"]["volume"], rel=1e-12)

    # the layer's corners are the CityJSON export's (which rounds to the millimetre)
    city = city_vertices(svc, "h", tmp_path)
    layer = np.unique(layer_vertices(cluster, db), axis=0)
    assert layer.shape == city.shape
    assert np.abs(layer - city).max() <= 0.0005 + 1e-9

    # a point measured again moves the building, and its layer with it, in the same change
    before = layer_vertices(cluster, db)
    moved = next(p for p in house_points(seed=11) if p["id"] == "R1")
    svc.update_point("h", "R1", {"rays": moved["rays"]})
    after = layer_vertices(cluster, db)
    assert np.abs(after - before).max() > 1e-4
    now = np.array(sorted(map(tuple, svc.get_building("h", "B1")["vertices"])), dtype=float)
    assert np.abs(np.unique(after, axis=0) - now).max() < 1e-6

    # a CRS change re-types the layer and moves it into the new grid
    svc.update_project("h", {"crs": "EPSG:32631"})
    srid = cluster.sql(db, "SELECT DISTINCT ST_SRID(geom) FROM gsgeo_h_buildings")
    assert srid == [(32631,)]
    now = np.array(sorted(map(tuple, svc.get_building("h", "B1")["vertices"])), dtype=float)
    assert np.abs(np.unique(layer_vertices(cluster, db), axis=0) - now).max() < 1e-6

    # a renamed building keeps its surfaces; a deleted one takes them along
    svc.update_building("h", "B1", {"id": "B2"})
    assert {r[0] for r in cluster.sql(db, "SELECT building_id FROM gsgeo_h_buildings")} == {"B2"}
    svc.delete_building("h", "B2")
    assert cluster.sql(db, "SELECT count(*) FROM gsgeo_h_buildings") == [(0,)]


def test_a_session_import_fills_the_buildings_layer(cluster, db, svc):
    svc.create_project(name="house", id="h", crs=CRS)
    svc.import_session("h", {"points": house_points(), "buildings": [HOUSE]})
    n = cluster.sql(db, "SELECT count(DISTINCT building_id), count(*) FROM gsgeo_h_buildings")
    assert n[0][0] == 1 and n[0][1] >= 7


def test_views_made_by_an_older_gsgeo_are_made_again_on_start(cluster, db, svc, tmp_path):
    svc.create_project(name="old", id="old", crs=CRS)
    svc.store.close()
    # as an older gsgeo left them: no buildings view, no provenance columns
    cluster.sql(db, "DROP VIEW gsgeo_old_buildings")
    cluster.sql(db, "UPDATE gsgeo_schema SET views = 1")
    reopened = open_store(tmp_path, cluster.url(db))
    try:
        cols = cluster.sql(db, "SELECT f_table_name FROM geometry_columns"
                               " WHERE f_table_name LIKE 'gsgeo_old_%' ORDER BY 1")
        assert [c[0] for c in cols] == ["gsgeo_old_buildings", "gsgeo_old_lines",
                                        "gsgeo_old_points", "gsgeo_old_polygons"]
        assert cluster.sql(db, "SELECT views FROM gsgeo_schema") == [(VIEWS_VERSION,)]
    finally:
        reopened.close()


def test_buildings_stored_by_an_older_gsgeo_get_their_surfaces_on_start(cluster, db, svc,
                                                                        house, tmp_path):
    from gsgeo.service import open_projects

    n = cluster.sql(db, "SELECT count(*) FROM gsgeo_h_buildings")[0][0]
    cluster.sql(db, "DELETE FROM building_surfaces")  # as a gsgeo before the layer left it
    svc.store.close()
    again = open_projects(tmp_path, url=cluster.url(db))
    try:
        assert cluster.sql(db, "SELECT count(*) FROM gsgeo_h_buildings") == [(n,)]
        assert again.keep_missing_surfaces() == 0  # nothing left to catch up
    finally:
        again.store.close()
