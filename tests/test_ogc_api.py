"""OGC API – Features at /ogc, read by GDAL's OAPIF driver (pyogrio) from a live `gsgeo serve`.

One server for the module (project ``t``: five points in EPSG:27700, a line, a polygon, two
check points); the live-write and token tests start their own.
"""

from __future__ import annotations

import math
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import numpy as np
import pyogrio
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis_profiles import examples
from servertools import LONDON, ecef_of, rays_at, start_server

from gsgeo.export.tables import CHECK_POINT_TYPES, LINE_TYPES, POLYGON_TYPES, RAY_TYPES
from gsgeo.pointschema import EXPORT_KEYS
from gsgeo.server.ogc.pages import PageCache
from gsgeo.service import open_projects
from gsgeo.service.checkpoints import CheckPointRow
from gsgeo.store.base import PointFilter, Transaction
from gsgeo.store.sqlite import SQLiteTransaction

GRID = "http://www.opengis.net/def/crs/EPSG/0/27700"
CRS84 = "http://www.opengis.net/def/crs/OGC/1.3/CRS84"
CODES = ["tree", "lamp", "tree", "lamp", "<b>kerb</b>"]


def point_rays(i: int) -> list[dict]:
    return rays_at(ecef_of(LONDON[0] + i * 1e-4, LONDON[1] + i * 2e-5, LONDON[2] + i), 4)


def make_project(data: Path, pid: str = "t", n: int = 5) -> None:
    svc = open_projects(data)
    try:
        svc.create_project(name=f"project {pid}", id=pid, crs="EPSG:27700")
        for i in range(n):
            svc.add_point(pid, {"id": f"P{i}", "code": CODES[i % len(CODES)],
                                "rays": point_rays(i)})
        if n < 4:
            return
        svc.add_feature(pid, "line", {"id": "L1", "points": ["P0", "P1", "P2"]})
        svc.add_feature(pid, "polygon", {"id": "A1", "points": ["P0", "P1", "P3"]})
        rec = svc.get_point(pid, "P1").record
        assert rec is not None
        svc.add_check_points(pid, [
            CheckPointRow("P1", rec["easting"] + 0.01, rec["northing"] - 0.02,
                          rec["height"] + 0.03),
            CheckPointRow("C9", rec["easting"] + 5.0, rec["northing"] + 5.0, rec["height"])],
            "EPSG:27700")
    finally:
        svc.store.close()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    data = tmp_path_factory.mktemp("ogc") / "data"
    make_project(data)
    proc, base = start_server(data)
    try:
        yield base
    finally:
        proc.terminate()
        proc.wait(10)


def api_points(base: str, pid: str = "t") -> dict[str, dict]:
    r = httpx.get(f"{base}/api/projects/{pid}/points")
    assert r.status_code == 200
    return {p["id"]: p for p in r.json()["points"]}


def record(p: dict) -> dict:
    return p.get("record") or p["result"]


def oapif(base: str) -> str:
    return f"OAPIF:{base}/ogc"


# GDAL's OAPIF driver -----------------------------------------------------------------------
def test_gdal_lists_the_projects_collections(server):
    layers = {name for name, _ in pyogrio.list_layers(oapif(server))}
    assert {"t.points", "t.lines", "t.polygons", "t.check_points", "t.rays"} <= layers


def test_gdal_reads_the_points_in_crs84_with_their_attributes(server):
    df = pyogrio.read_dataframe(oapif(server), layer="t.points", CRS="OGC:CRS84")
    pts = api_points(server)
    assert sorted(df["point_id"]) == sorted(pts)
    for _, row in df.iterrows():
        rec = record(pts[row["point_id"]])
        g = row.geometry
        metres_per_deg = 111_320.0
        assert abs(g.x - rec["lon"]) * metres_per_deg * math.cos(math.radians(rec["lat"])) < 1e-3
        assert abs(g.y - rec["lat"]) * metres_per_deg < 1e-3
        assert abs(g.z - rec["h_wgs84"]) < 1e-3
        assert row["code"] == rec["code"] and row["n_rays"] == rec["n_rays"]
        assert row["easting"] == pytest.approx(rec["easting"], abs=1e-6)
    # GDAL adds the feature id as a field "id"; then the export schema, in its order
    assert list(df.columns[1:-1]) == list(EXPORT_KEYS) and df.columns[0] == "id"


def test_gdal_reads_the_points_in_the_grid_crs(server):
    df = pyogrio.read_dataframe(oapif(server), layer="t.points", CRS="EPSG:27700")
    assert df.crs.to_epsg() == 27700
    pts = api_points(server)
    for _, row in df.iterrows():
        rec = record(pts[row["point_id"]])
        g = row.geometry
        assert abs(g.x - rec["easting"]) < 1e-3 and abs(g.y - rec["northing"]) < 1e-3
        assert abs(g.z - rec["height"]) < 1e-3


def test_a_point_stored_through_the_api_is_in_the_next_read(tmp_path):
    data = tmp_path / "data"
    make_project(data, "live", 2)
    proc, base = start_server(data)
    try:
        before = pyogrio.read_dataframe(oapif(base), layer="live.points")
        assert sorted(before["point_id"]) == ["P0", "P1"]
        r = httpx.post(f"{base}/api/projects/live/points",
                       json={"id": "NEW", "code": "fresh", "rays": point_rays(7)})
        assert r.status_code in (200, 201), r.text
        after = pyogrio.read_dataframe(oapif(base), layer="live.points", CRS="EPSG:27700")
        assert sorted(after["point_id"]) == ["NEW", "P0", "P1"]
        new = after[after["point_id"] == "NEW"].iloc[0]
        rec = record(api_points(base, "live")["NEW"])
        assert abs(new.geometry.x - rec["easting"]) < 1e-3 and new["code"] == "fresh"
    finally:
        proc.terminate()
        proc.wait(10)


def test_gdal_attribute_filters_reach_the_server(server):
    df = pyogrio.read_dataframe(oapif(server), layer="t.points", where="code = 'lamp'")
    assert sorted(df["point_id"]) == ["P1", "P3"]


def test_gdal_pages_through_next_links(server):
    df = pyogrio.read_dataframe(oapif(server), layer="t.points", PAGE_SIZE="2")
    assert sorted(df["point_id"]) == [f"P{i}" for i in range(5)]


# the HTTP interface ------------------------------------------------------------------------
def test_landing_conformance_and_openapi(server):
    doc = httpx.get(f"{server}/ogc").json()
    rels = {k["rel"]: k for k in doc["links"]}
    assert {"self", "service-desc", "conformance", "data"} <= set(rels)
    api = httpx.get(rels["service-desc"]["href"])
    assert api.status_code == 200 and api.json()["openapi"].startswith("3.0")
    assert "/collections/{collectionId}/items" in api.json()["paths"]
    conf = httpx.get(rels["conformance"]["href"]).json()["conformsTo"]
    for part in ("ogcapi-features-1/1.0/conf/core", "ogcapi-features-1/1.0/conf/geojson",
                 "ogcapi-features-1/1.0/conf/html", "ogcapi-features-1/1.0/conf/oas30",
                 "ogcapi-features-2/1.0/conf/crs"):
        assert any(c.endswith(part) for c in conf), part


def test_collections_announce_their_crs_and_storage_crs(server):
    doc = httpx.get(f"{server}/ogc/collections").json()
    ids = [c["id"] for c in doc["collections"]]
    assert ids[:5] == ["t.points", "t.lines", "t.polygons", "t.check_points", "t.rays"]
    c = httpx.get(f"{server}/ogc/collections/t.points").json()
    assert c["storageCrs"] == GRID and set(c["crs"]) == {GRID, CRS84}
    assert any(k["rel"] == "items" for k in c["links"])
    q = httpx.get(f"{server}/ogc/collections/t.points/queryables")
    assert q.status_code == 200 and {"code", "measured_at"} <= set(q.json()["properties"])


def test_items_carry_content_crs_and_match_the_records(server):
    pts = api_points(server)
    r = httpx.get(f"{server}/ogc/collections/t.points/items", params={"crs": GRID})
    assert r.status_code == 200 and r.headers["content-crs"] == f"<{GRID}>"
    assert r.headers["content-type"].startswith("application/geo+json")
    for f in r.json()["features"]:
        rec = record(pts[f["id"]])
        assert f["geometry"]["coordinates"] == [rec["easting"], rec["northing"], rec["height"]]
        assert list(f["properties"]) == list(EXPORT_KEYS)  # the point schema, then provenance
    r = httpx.get(f"{server}/ogc/collections/t.points/items/P2")
    assert r.headers["content-crs"] == f"<{CRS84}>"
    rec = record(pts["P2"])
    assert r.json()["geometry"]["coordinates"] == [rec["lon"], rec["lat"], rec["h_wgs84"]]


def test_paging_limit_offset_next_prev_and_number_matched(server):
    url = f"{server}/ogc/collections/t.points/items?limit=2"
    seen = []
    pages = 0
    while url:
        doc = httpx.get(url).json()
        pages += 1
        assert doc["numberMatched"] == 5 and doc["numberReturned"] == len(doc["features"])
        seen += [f["id"] for f in doc["features"]]
        links = {k["rel"]: k["href"] for k in doc["links"]}
        assert ("prev" in links) == (pages > 1)
        url = links.get("next")
    assert seen == [f"P{i}" for i in range(5)] and pages == 3
    doc = httpx.get(f"{server}/ogc/collections/t.points/items?limit=100000").json()
    assert doc["numberReturned"] == 5  # a limit over the maximum is capped, not refused


def test_bbox_datetime_and_code_filters(server):
    pts = api_points(server)
    p0 = record(pts["P0"])
    items = f"{server}/ogc/collections/t.points/items"

    def ids(**params) -> list[str]:
        r = httpx.get(items, params=params)
        assert r.status_code == 200, r.text
        return [f["id"] for f in r.json()["features"]]

    box = f"{p0['lon'] - 1e-5},{p0['lat'] - 1e-5},{p0['lon'] + 1e-5},{p0['lat'] + 1e-5}"
    assert ids(bbox=box) == ["P0"]
    gbox = f"{p0['easting'] - 1},{p0['northing'] - 1},{p0['easting'] + 1},{p0['northing'] + 1}"
    assert ids(bbox=gbox, **{"bbox-crs": GRID}) == ["P0"]
    r = httpx.get(items, params={"bbox": gbox})  # grid numbers taken as CRS84
    assert r.status_code == 400 and "latitudes" in r.json()["description"]
    now = datetime.now(UTC)
    later = (now + timedelta(hours=1)).isoformat()
    earlier = (now - timedelta(days=1)).isoformat()
    assert len(ids(datetime=f"{earlier}/{later}")) == 5
    assert len(ids(datetime=f"../{later}")) == 5
    assert ids(datetime=f"../{earlier}") == []
    assert ids(datetime="2001-01-01T00:00:00Z") == []
    assert ids(datetime="9999-12-31T23:59:59.9999Z/..") == ids(datetime="9999-12-31") == []
    day = p0["measured_at"][:10]
    assert len(ids(datetime=day)) == 5  # a date is the whole UTC day
    assert ids(code="lamp") == ["P1", "P3"]
    assert len(ids(measured_at=f"{earlier}/{later}")) == 5
    assert ids(measured_at=p0["measured_at"]) == ids(datetime=p0["measured_at"])
    r = httpx.get(items, params={"measured_at": "soon"})
    assert r.status_code == 400 and r.json()["description"].startswith("measured_at:")
    r = httpx.get(items, params={"measured_at": later, "datetime": later})
    assert r.status_code == 400 and "not both" in r.json()["description"]
    doc = httpx.get(items, params={"code": "tree", "limit": 1}).json()
    assert doc["numberMatched"] == 2 and doc["numberReturned"] == 1
    lbox = f"{p0['lon'] - 1e-5},{p0['lat'] - 1e-5},{p0['lon'] + 1e-5},{p0['lat'] + 1e-5}"
    lines = httpx.get(f"{server}/ogc/collections/t.lines/items", params={"bbox": lbox}).json()
    assert [f["id"] for f in lines["features"]] == ["L1"]
    far = "10,10,11,11"
    assert httpx.get(f"{server}/ogc/collections/t.lines/items",
                     params={"bbox": far}).json()["features"] == []


@pytest.mark.parametrize("query, words", [
    ("limit=0", "limit"), ("limit=ten", "limit"), ("offset=-1", "offset"),
    ("bbox=1,2,3", "bbox"), ("bbox=a,b,c,d", "bbox"), ("bbox=0,60,1,50", "bbox"),
    ("bbox=0,0,1,100", "latitude"), ("bbox=0,0,1,1&bbox-crs=EPSG:4326", "not offered"),
    ("crs=http://www.opengis.net/def/crs/EPSG/0/4326", "not offered"),
    ("crs=nonsense", "not offered"), ("datetime=yesterday", "RFC 3339"),
    ("datetime=2026-01-01T00:00:00", "time zone"), ("datetime=../..", "interval"),
    ("datetime=2026-02-01T00:00:00Z/2026-01-01T00:00:00Z", "before it starts"),
    ("colour=red", "unknown parameter"), ("limit=1&limit=2", "2 times"), ("f=xml", "json or html"),
    ("offset=99999999999999999999999", "at most"), ("datetime=9999-12-31T23:59:59-01:00", "range"),
    ("datetime=0001-01-01T00:00:00%2B01:00", "range"),
])
def test_bad_parameters_get_400_with_an_ogc_exception(server, query, words):
    r = httpx.get(f"{server}/ogc/collections/t.points/items?{query}")
    assert r.status_code == 400, (query, r.text)
    body = r.json()
    assert body["code"] == "InvalidParameterValue" and words in body["description"]


def test_filters_a_layer_does_not_have_get_400(server):
    r = httpx.get(f"{server}/ogc/collections/t.lines/items?code=x")
    assert r.status_code == 400 and "code" in r.json()["description"]
    r = httpx.get(f"{server}/ogc/collections/t.polygons/items?datetime=2026-01-01T00:00:00Z")
    assert r.status_code == 400 and "time" in r.json()["description"]


@pytest.mark.parametrize("path", [
    "/ogc/collections/nope.points", "/ogc/collections/t.buildings", "/ogc/collections/t",
    "/ogc/collections/nope.points/items", "/ogc/collections/t.points/items/NOPE",
    "/ogc/collections/t.lines/items/NOPE", "/ogc/collections/t.rays/items/P0~99",
    "/ogc/collections/t.check_points/items/NOPE",
])
def test_unknown_collections_and_features_get_404(server, path):
    r = httpx.get(server + path)
    assert r.status_code == 404 and r.json()["code"] == "NotFound"


def test_html_views(server):
    for path in ("/ogc", "/ogc/conformance", "/ogc/collections", "/ogc/collections/t.points",
                 "/ogc/collections/t.points/queryables", "/ogc/collections/t.points/items",
                 "/ogc/collections/t.points/items/P4"):
        r = httpx.get(server + path, params={"f": "html"})
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/html"), path
        assert "<html" in r.text
    r = httpx.get(f"{server}/ogc/collections/t.points/items",
                  headers={"Accept": "text/html,application/xhtml+xml"})
    assert r.headers["content-type"].startswith("text/html")
    assert "&lt;b&gt;kerb&lt;/b&gt;" in r.text and "<b>kerb</b>" not in r.text


def test_etag_last_modified_and_304(tmp_path):
    data = tmp_path / "data"
    make_project(data, "e", 2)
    proc, base = start_server(data)
    try:
        url = f"{base}/ogc/collections/e.points/items"
        r = httpx.get(url)
        etag = r.headers["etag"]
        assert r.headers["last-modified"].endswith("GMT")
        time.sleep(1.1)  # the ETag follows the data, not the clock
        again = httpx.get(url, headers={"If-None-Match": etag})
        assert again.status_code == 304 and again.content == b""
        assert httpx.get(url).headers["etag"] == etag
        one = httpx.get(f"{url}/P0")
        assert httpx.get(f"{url}/P0", headers={"If-None-Match": one.headers["etag"]}
                         ).status_code == 304
        r = httpx.patch(f"{base}/api/projects/e/points/P0", json={"code": "changed"})
        assert r.status_code == 200
        changed = httpx.get(url, headers={"If-None-Match": etag})
        assert changed.status_code == 200 and changed.headers["etag"] != etag
        assert changed.json()["features"][0]["properties"]["code"] == "changed"
    finally:
        proc.terminate()
        proc.wait(10)


def test_the_token_applies_to_ogc_off_loopback(tmp_path):
    data = tmp_path / "data"
    make_project(data, "k", 2)
    proc, base = start_server(data, "--host", "0.0.0.0", env={"GSGEO_TOKEN": "tok-ogc"})
    try:
        r = httpx.get(f"{base}/ogc/collections")
        assert r.status_code == 401 and "token" in r.json()["message"]
        assert httpx.get(f"{base}/ogc", headers={"Authorization": "Bearer wrong"}
                         ).status_code == 401
        assert httpx.get(f"{base}/ogc/collections", headers={"Cookie": "gsgeo-token=tok-ogc"}
                         ).status_code == 401
        assert httpx.get(f"{base}/ogc/collections",
                         headers={"Authorization": "Bearer tok-ogc"}).status_code == 200
        with pytest.raises(pyogrio.errors.DataSourceError):
            pyogrio.list_layers(oapif(base))
        # GDAL sends 'Authorization: Bearer TOKEN' with these (OAPIF's own Accept header
        # replaces GDAL_HTTP_HEADERS)
        bearer = {"GDAL_HTTP_AUTH": "BEARER", "GDAL_HTTP_BEARER": "tok-ogc"}
        pyogrio.set_gdal_config_options(bearer)
        try:
            df = pyogrio.read_dataframe(oapif(base), layer="k.points")
        finally:
            pyogrio.set_gdal_config_options(dict.fromkeys(bearer))
        assert sorted(df["point_id"]) == ["P0", "P1"]
    finally:
        proc.terminate()
        proc.wait(10)


def test_lines_polygons_check_points_and_rays_carry_the_export_columns(server):
    pts = api_points(server)

    def get(layer: str, **params) -> dict:
        r = httpx.get(f"{server}/ogc/collections/t.{layer}/items", params=params)
        assert r.status_code == 200, r.text
        return r.json()

    line = get("lines", crs=GRID)["features"][0]
    assert list(line["properties"]) == list(LINE_TYPES)
    assert line["geometry"]["coordinates"] == [
        [record(pts[q])[k] for k in ("easting", "northing", "height")] for q in ("P0", "P1", "P2")]
    poly = get("polygons")["features"][0]
    assert list(poly["properties"]) == list(POLYGON_TYPES)
    ring = poly["geometry"]["coordinates"][0]
    assert ring[0] == ring[-1] and len(ring) == 4
    checks = {f["id"]: f for f in get("check_points", crs=GRID)["features"]}
    assert set(checks) == {"P1", "C9"}
    assert set(CHECK_POINT_TYPES) <= set(checks["P1"]["properties"])
    p1 = checks["P1"]["properties"]
    assert p1["measured"] is True and p1["d_easting"] == pytest.approx(-0.01, abs=1e-6)
    assert checks["C9"]["properties"]["measured"] is False
    assert checks["C9"]["properties"]["d_easting"] is None
    c84 = {f["id"]: f for f in get("check_points")["features"]}["P1"]["geometry"]["coordinates"]
    rec = record(pts["P1"])
    assert abs(c84[1] - rec["lat"]) * 111_320 < 0.05  # 2 cm off the point, as stored
    rays = get("rays", limit=4)
    assert rays["numberMatched"] == 20 and len(rays["features"]) == 4
    assert list(rays["features"][0]["properties"]) == list(RAY_TYPES)
    p0 = record(pts["P0"])  # a ray ends at its point
    assert rays["features"][0]["geometry"]["coordinates"][1] == [p0["lon"], p0["lat"],
                                                                 p0["h_wgs84"]]
    r = httpx.get(f"{server}/ogc/collections/t.rays/items/P0~1")
    assert r.status_code == 200 and r.json()["properties"]["ray_index"] == 1


# the store's pages -------------------------------------------------------------------------
def test_store_pages_match_the_reference_filter(tmp_path):
    """SQLite's paged, filtered reads give what the interface's plain Python reading gives."""
    data = tmp_path / "data"
    make_project(data, "s", 5)
    svc = open_projects(data)
    try:
        with svc.store.transaction(write=False) as tx:
            assert isinstance(tx, SQLiteTransaction)
            recs = {p.id: p.record for p in tx.list_points("s")}
            lons = sorted(r["lon"] for r in recs.values())
            now = datetime.now(UTC)
            filters = [
                None, PointFilter(code="tree"), PointFilter(code="none"),
                PointFilter(measured_from=now - timedelta(hours=1)),
                PointFilter(measured_to=now - timedelta(hours=1)),
                PointFilter(box=("lon", "lat", lons[1] - 1e-9, -90, lons[3] + 1e-9, 90)),
                PointFilter(box=("lon", "lat", lons[3] - 1e-9, -90, lons[1] + 1e-9, 90)),
                PointFilter(code="lamp", box=("easting", "northing", 0, 0, 1e7, 1e7)),
            ]
            for f in filters:
                for offset, limit in ((0, None), (1, 2), (4, 10), (9, 1)):
                    got = tx.page_point_records("s", f, offset, limit)
                    want = Transaction.page_point_records(tx, "s", f, offset, limit)
                    assert [(g.id, g.record) for g in got] == [(w.id, w.record) for w in want]
                assert tx.count_point_records("s", f) == Transaction.count_point_records(
                    tx, "s", f)
            assert tx.count_point_records("s", PointFilter(box=(
                "lon", "lat", lons[3] - 1e-9, -90, lons[1] + 1e-9, 90))) == 4  # wraps around
            assert np.isfinite([r["lon"] for r in recs.values()]).all()
    finally:
        svc.store.close()


# pages made ahead ------------------------------------------------------------------------
def test_a_page_made_ahead_is_not_served_after_a_change(tmp_path):
    """The next page is made while the client reads this one; a change committed in between
    (through the API, on another connection) is in the answer all the same."""
    data = tmp_path / "data"
    make_project(data, "n", 4)
    proc, base = start_server(data)
    try:
        first = httpx.get(f"{base}/ogc/collections/n.points/items?limit=2").json()
        nxt = next(k["href"] for k in first["links"] if k["rel"] == "next")
        time.sleep(0.5)  # the page after it is made by now
        r = httpx.patch(f"{base}/api/projects/n/points/P3", json={"code": "renamed"})
        assert r.status_code == 200
        second = httpx.get(nxt).json()
        assert [f["id"] for f in second["features"]] == ["P2", "P3"]
        assert second["features"][1]["properties"]["code"] == "renamed"
        # unchanged: the page made ahead is the one served, equal to a fresh one
        again = httpx.get(f"{base}/ogc/collections/n.points/items?limit=2").json()
        time.sleep(0.5)
        made_ahead = httpx.get(nxt).json()
        assert made_ahead["features"] == second["features"]
        assert again["numberMatched"] == made_ahead["numberMatched"] == 4
    finally:
        proc.terminate()
        proc.wait(10)


def test_page_cache_drops_a_page_of_an_older_revision():
    rev = [1]
    made = []
    cache: PageCache[str] = PageCache(lambda: rev[0])

    def make() -> str:
        made.append(rev[0])
        return f"page at {rev[0]}"

    cache.make_ahead("k", make)
    assert cache.take("k") == "page at 1"  # waits for the page being made
    assert cache.take("k") is None  # taken once
    cache.make_ahead("k", make)
    cache.take("nothing")
    time.sleep(0.2)
    rev[0] = 2  # a change committed after the page was made
    assert cache.take("k") is None
    unknown: PageCache[str] = PageCache(lambda: None)  # a store that cannot tell
    unknown.make_ahead("k", make)
    time.sleep(0.2)
    assert unknown.take("k") is None
    cache.close()
    unknown.close()


QUERY_WORDS = ["limit", "offset", "bbox", "bbox-crs", "datetime", "crs", "code", "f", "x", ""]


@settings(max_examples=examples(60), deadline=None)
@given(st.lists(st.tuples(st.sampled_from(QUERY_WORDS),
                          st.text(alphabet=st.characters(codec="utf-8"), max_size=30)),
                max_size=4),
       st.sampled_from(["t.points", "t.lines", "t.rays", "t.check_points", "t.nope", "t"]))
def test_no_query_gets_a_500(server, pairs, collection):
    r = httpx.get(f"{server}/ogc/collections/{collection}/items", params=pairs)
    assert r.status_code in (200, 400, 404), (pairs, r.text)
    if r.status_code != 200:
        assert r.json()["code"] in ("InvalidParameterValue", "NotFound")


def test_a_project_without_a_grid_offers_crs84_only(server):
    r = httpx.post(f"{server}/api/projects", json={"name": "no grid", "id": "nogrid"})
    assert r.status_code in (200, 201), r.text
    r = httpx.post(f"{server}/api/projects/nogrid/points", json={"id": "Q1", "rays": point_rays(2)})
    assert r.status_code in (200, 201), r.text
    c = httpx.get(f"{server}/ogc/collections/nogrid.points").json()
    assert c["crs"] == [CRS84] and c["storageCrs"] == CRS84
    doc = httpx.get(f"{server}/ogc/collections/nogrid.points/items").json()
    rec = record(api_points(server, "nogrid")["Q1"])
    assert doc["features"][0]["geometry"]["coordinates"] == [rec["lon"], rec["lat"], rec["h_wgs84"]]
    assert doc["features"][0]["properties"]["easting"] is None
    r = httpx.get(f"{server}/ogc/collections/nogrid.points/items", params={"crs": GRID})
    assert r.status_code == 400 and "not offered" in r.json()["description"]
    lines = httpx.get(f"{server}/ogc/collections/nogrid.rays/items").json()
    assert lines["numberMatched"] == 0 and lines["features"] == []
