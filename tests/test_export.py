"""gsgeo.export: GeoPackage, GeoJSON and CSV round trips, CRS (compound too), errors, atomicity.

Every value read back is compared with what gsgeo.crs computed (Measurement.record()) and,
for geometry, with independent computations (pyproj, shapely, hand formulas).
"""

from __future__ import annotations

import copy
import csv
import io
import json
import math
from pathlib import Path

import geopandas as gpd
import numpy as np
import pandas as pd
import pyogrio
import pytest
import shapely
from export_helpers import (
    LAT0,
    LON0,
    UNWEIGHTED,
    proj_data_dir,
    session,
    undulation,
    write_fake_osgm15,
)
from pyproj import CRS, Transformer

from gsgeo.errors import CRSError, GeometryError, InputError
from gsgeo.export import write_measurements
from gsgeo.export.csvfile import CSV_COLUMNS
from gsgeo.export.tables import ELLIPSE_VERTICES, POINT_TYPES
from gsgeo.measure import RECORD_KEYS, Measurement
from gsgeo.pointschema import EXPORT_KEYS
from gsgeo.session import measure_session

EGM96 = Path("/usr/share/proj/egm96_15.gtx")
ALL_LAYERS = {"points", "rays", "lines", "polygons", "error_ellipses"}


def _measure(rng, crs, **kw):
    s = session(rng, **kw)
    res = measure_session(s, crs=crs)
    assert all(isinstance(m, Measurement) for m in res)
    return s, res


@pytest.fixture(scope="module")
def bng():
    """Session and measurements in EPSG:27700 (ellipsoidal heights)."""
    return _measure(np.random.default_rng(1), "EPSG:27700")


@pytest.fixture(scope="module")
def odn(tmp_path_factory):
    """EPSG:27700+5701 (ODN heights) through a fake OSGM15 grid on PROJ's path: EPSG:7405."""
    d = tmp_path_factory.mktemp("grids")
    write_fake_osgm15(d)
    with proj_data_dir(d):
        return _measure(np.random.default_rng(2), "EPSG:27700+5701")


@pytest.fixture(scope="module")
def utm_egm96():
    """EPSG:32630+5773 (UTM 30N + EGM96 height): a compound without an EPSG code of its own."""
    if not EGM96.is_file():
        pytest.skip("Debian proj-data's egm96_15.gtx is not installed")
    with proj_data_dir(EGM96.parent):
        return _measure(np.random.default_rng(3), "EPSG:32630+5773")


def _records(res):
    return {m.point_id: m.record() for m in res}


def _check_fields(row: dict, rec: dict):
    for k in RECORD_KEYS:
        a, b = row[k], rec[k]
        if b is None:
            assert a is None or (isinstance(a, float) and math.isnan(a)), (k, a)
        elif POINT_TYPES[k] == "float":
            assert float(a) == b, (k, a, b)
        elif POINT_TYPES[k] == "int":
            assert int(a) == b, k
        else:
            assert str(a) == b, (k, a, b)


# GeoPackage -----------------------------------------------------------------------------------
@pytest.mark.parametrize("which", ["bng", "odn", "utm_egm96"])
def test_gpkg_round_trip(which, request, tmp_path):
    s, res = request.getfixturevalue(which)
    recs = _records(res)
    out = write_measurements(tmp_path / "out.gpkg", res, lines=s.lines, polygons=s.polygons)
    assert out == tmp_path / "out.gpkg" and sorted(p.name for p in tmp_path.iterdir()) == ["out.gpkg"]
    crs_text = recs["P1"]["crs"]
    want = CRS(crs_text)
    horiz = want.sub_crs_list[0] if want.is_compound else want
    layers = {name: gtype for name, gtype in pyogrio.list_layers(out)}
    assert layers == {"points": "Point Z", "rays": "LineString Z", "lines": "LineString Z",
                      "polygons": "Polygon Z", "error_ellipses": "Polygon"}
    for name in ALL_LAYERS:
        info = pyogrio.read_info(out, layer=name)
        crs_back = CRS(info["crs"])
        assert crs_back.equals(horiz if name == "error_ellipses" else want), (name, info["crs"])
        df = gpd.read_file(out, layer=name)
        assert CRS(df.crs).equals(horiz if name == "error_ellipses" else want)
        assert len(df) == info["features"] > 0
        assert bool(df.has_z.all()) == (name != "error_ellipses")

    # points: every schema field with its type and value, geometry = E, N, H
    info = pyogrio.read_info(out, layer="points")
    types = dict(zip(info["fields"], info["dtypes"], strict=True))
    assert list(info["fields"]) == list(EXPORT_KEYS)  # the point schema, then provenance
    for k, kind in POINT_TYPES.items():
        assert types[k] == {"float": "float64", "int": "int32", "str": "object"}[kind], k
    for reader in (pyogrio.read_dataframe, gpd.read_file):
        df = reader(out, layer="points")
        assert len(df) == len(recs)
        for _, row in df.iterrows():
            rec = recs[row["point_id"]]
            d = row.to_dict()
            d = {k: (None if not isinstance(v, str) and pd.isna(v) else v) for k, v in d.items()}
            _check_fields(d, rec)
            assert (row.geometry.x, row.geometry.y, row.geometry.z) == (
                rec["easting"], rec["northing"], rec["height"])
    if "5701" in crs_text:  # ODN height from the fake geoid: H = h - N (h on WGS 84 here)
        for m in res:
            h = m.grid.h_ellipsoidal
            n_geoid = undulation(m.grid.lon, m.grid.lat)
            assert recs[m.point_id]["height"] == pytest.approx(h - n_geoid, abs=2e-3)
            assert recs[m.point_id]["height_type"] == "orthometric"
        import sqlite3

        with sqlite3.connect(out) as con:
            orgs = set(con.execute("SELECT organization, organization_coordsys_id FROM gpkg_spatial_ref_sys"
                                   " WHERE srs_id > 0"))
        assert ("EPSG", 7405) in orgs  # registered by EPSG code (27700 + 5701 = 7405)
    if "5773" in crs_text:  # no EPSG code of its own: WKT2 in the gpkg_crs_wkt extension
        import sqlite3

        with sqlite3.connect(out) as con:
            wkt2 = [r[0] for r in con.execute("SELECT definition_12_063 FROM gpkg_spatial_ref_sys"
                                              " WHERE srs_name LIKE '%EGM96%'")]
            ext = {r[0] for r in con.execute("SELECT extension_name FROM gpkg_extensions")}
        assert len(wkt2) == 1 and CRS(wkt2[0]).equals(want) and "gpkg_crs_wkt_1_1" in ext

    # rays: camera centre -> point, residuals and flags as computed
    rays = pyogrio.read_dataframe(out, layer="rays")
    assert len(rays) == sum(len(m.excluded) for m in res)
    for m in res:
        sub = rays[rays.point_id == m.point_id].sort_values("ray_index")
        assert sub.ray_index.tolist() == list(range(len(m.excluded)))
        coords = np.array([np.asarray(g.coords) for g in sub.geometry])  # (N, 2, 3)
        np.testing.assert_array_equal(coords[:, 0], m.ray_origins_grid)
        np.testing.assert_array_equal(coords[:, 1], np.broadcast_to(
            [recs[m.point_id][k] for k in ("easting", "northing", "height")], (len(sub), 3)))
        np.testing.assert_array_equal(sub.residual_m.to_numpy(), m.residuals_m)
        if m.point_id in UNWEIGHTED:
            assert sub.residual_px.isna().all()
        else:
            np.testing.assert_array_equal(sub.residual_px.to_numpy(), m.residuals_px)
        assert sub.outlier.dtype == bool and sub.outlier.tolist() == m.outliers.tolist()

    # lines: geometry through the points, lengths recomputed by hand
    lines = pyogrio.read_dataframe(out, layer="lines").set_index("line_id")
    for f in s.lines:
        xyz = np.array([[recs[p][k] for k in ("easting", "northing", "height")] for p in f.points])
        g = lines.loc[f.id, "geometry"]
        np.testing.assert_array_equal(np.asarray(g.coords), xyz)
        seg = np.diff(xyz, axis=0)
        l3, l2 = np.linalg.norm(seg, axis=1).sum(), np.linalg.norm(seg[:, :2], axis=1).sum()
        assert lines.loc[f.id, "length_3d"] == pytest.approx(l3, rel=1e-12)
        assert lines.loc[f.id, "length_2d"] == pytest.approx(l2, rel=1e-12)
        assert 0 < lines.loc[f.id, "sigma_length_2d"] < 0.1 and 0 < lines.loc[f.id, "sigma_length_3d"] < 0.1
        assert json.loads(lines.loc[f.id, "point_ids"]) == f.points

    # polygons: closed, counterclockwise, Z kept, area = shapely's
    polys = pyogrio.read_dataframe(out, layer="polygons").set_index("polygon_id")
    g = polys.loc["A1", "geometry"]
    ring = np.asarray(g.exterior.coords)
    assert ring.shape == (5, 3) and np.array_equal(ring[0], ring[-1])
    assert g.exterior.is_ccw and g.is_valid
    assert {tuple(r) for r in ring} == {tuple(recs[p][k] for k in ("easting", "northing", "height"))
                                         for p in ("P1", "P2", "P3", "P4")}
    assert polys.loc["A1", "area_2d"] == pytest.approx(g.area, rel=1e-9)
    assert polys.loc["A1", "perimeter_2d"] == pytest.approx(g.exterior.length, rel=1e-12)
    assert polys.loc["A1", "area_2d"] == pytest.approx(80.0, abs=1.0)  # 10 m x 8 m footprint
    assert 0 < polys.loc["A1", "sigma_area_2d"] < 1

    # error ellipses: true-size 95 % ellipses centred on the points
    ell = pyogrio.read_dataframe(out, layer="error_ellipses").set_index("point_id")
    for pid, rec in recs.items():
        poly = ell.loc[pid, "geometry"]
        a, b = rec["ellipse_major_95"], rec["ellipse_minor_95"]
        assert poly.is_valid and poly.exterior.is_ccw
        nv = ELLIPSE_VERTICES  # inscribed polygon of an ellipse: (n / 2) a b sin(2 pi / n)
        assert len(poly.exterior.coords) == nv + 1
        assert poly.area == pytest.approx(nv / 2 * a * b * math.sin(2 * math.pi / nv), rel=1e-6)
        xy = np.asarray(poly.exterior.coords) - [rec["easting"], rec["northing"]]
        far = xy[np.argmax(np.hypot(*xy.T))]
        bearing = math.degrees(math.atan2(far[0], far[1])) % 180
        assert np.hypot(*far) == pytest.approx(a, abs=1e-8)  # float spacing of 1e6 m coordinates
        diff = abs(bearing - rec["ellipse_bearing_deg"])
        assert min(diff, 180 - diff) < 1e-6


def test_user_geoid_file_export_states_its_datum(tmp_path, rng):
    """--geoid FILE.tif: orthometric heights without a vertical CRS; the CRS stays 2-D EPSG:27700
    and the height_type / vertical_datum fields say what the heights are."""
    write_fake_osgm15(tmp_path)
    geoid = tmp_path / "uk_os_OSGM15_GB.tif"
    res = measure_session(session(rng), crs="EPSG:27700", geoid=geoid)
    out = write_measurements(tmp_path / "g.gpkg", res)
    assert CRS(pyogrio.read_info(out, layer="points")["crs"]).equals(CRS("EPSG:27700"))
    df = pyogrio.read_dataframe(out, layer="points").set_index("point_id")
    for m in res:
        row = df.loc[m.point_id]
        assert row.height_type == "orthometric" and "uk_os_OSGM15_GB.tif" in row.vertical_datum
        assert row.geometry.z == row.height == pytest.approx(
            m.grid.h_ellipsoidal - undulation(m.grid.lon, m.grid.lat), abs=1e-3)
    rows = list(csv.DictReader(write_measurements(tmp_path / "g.csv", res).read_text().splitlines()))
    assert {r["height_type"] for r in rows} == {"orthometric"} and {r["crs"] for r in rows} == {"EPSG:27700"}


def test_gpkg_has_no_empty_layers(bng, tmp_path):
    _, res = bng
    out = write_measurements(tmp_path / "pts.gpkg", res)  # no lines, no polygons
    assert {n for n, _ in pyogrio.list_layers(out)} == {"points", "rays", "error_ellipses"}


def test_check_points_layer(bng, tmp_path):
    s, res = bng
    rec = res[0].record()
    cps = [{"id": rec["point_id"], "easting": rec["easting"] + 0.01, "northing": rec["northing"],
            "height": rec["height"] - 0.02},
           {"id": "CP9", "x": rec["easting"] + 50, "y": rec["northing"], "z": 70.0,
            "description": "PK nail in kerb"}]
    out = write_measurements(tmp_path / "cp.gpkg", res, check_points=cps)
    df = pyogrio.read_dataframe(out, layer="check_points").set_index("point_id")
    assert df.loc["CP9", "description"] == "PK nail in kerb"  # read back by GDAL
    assert df.loc[rec["point_id"], "description"] == ""
    assert df.loc[rec["point_id"], "d_easting"] == pytest.approx(-0.01, abs=1e-9)
    assert df.loc[rec["point_id"], "d_height"] == pytest.approx(0.02, abs=1e-9)
    assert bool(df.loc[rec["point_id"], "measured"]) and not bool(df.loc["CP9", "measured"])
    assert math.isnan(df.loc["CP9", "d_easting"])
    doc = json.loads(write_measurements(tmp_path / "cp.geojson", res, check_points=cps).read_text())
    cp = [f for f in doc["features"] if f["properties"]["layer"] == "check_points"]
    assert len(cp) == 2 and all(f["geometry"] is None for f in cp)


# GeoJSON --------------------------------------------------------------------------------------
def _ring_ccw(ring):
    x, y = np.asarray(ring)[:, 0], np.asarray(ring)[:, 1]
    return float(np.sum(x[:-1] * y[1:] - x[1:] * y[:-1])) > 0


@pytest.mark.parametrize("which", ["bng", "odn"])
def test_geojson_rfc7946(which, request, tmp_path):
    s, res = request.getfixturevalue(which)
    recs = _records(res)
    out = write_measurements(tmp_path / "out.geojson", res, lines=s.lines, polygons=s.polygons)
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert doc["type"] == "FeatureCollection" and "crs" not in doc
    t = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
    by_layer: dict[str, list] = {}
    for f in doc["features"]:
        by_layer.setdefault(f["properties"]["layer"], []).append(f)
    assert set(by_layer) == {"points", "lines", "polygons"}
    for f in by_layer["points"]:
        lon, lat, h = f["geometry"]["coordinates"]
        assert -180 <= lon <= 180 and -90 <= lat <= 90
        assert abs(lon - LON0) < 0.01 and abs(lat - LAT0) < 0.01  # lon first, lat second
        m = next(m for m in res if m.point_id == f["id"])
        elon, elat, eh = t.transform(*m.point_ecef)  # independent: pyproj directly
        assert lon == pytest.approx(elon, abs=2e-9) and lat == pytest.approx(elat, abs=2e-9)
        assert h == pytest.approx(eh, abs=1e-4)
        props = f["properties"]
        rec = recs[f["id"]]
        for k in RECORD_KEYS:  # every grid value, sigma and covariance, exactly
            assert props[k] == rec[k], k
    for f in by_layer["polygons"]:
        ring = f["geometry"]["coordinates"][0]
        assert ring[0] == ring[-1] and len(ring) == 5 and _ring_ccw(ring)  # right-hand rule
        assert f["properties"]["point_ids"] == ["P1", "P4", "P3", "P2"]
    for f in by_layer["lines"]:
        pos = {p["id"]: p["geometry"]["coordinates"] for p in by_layer["points"]}
        assert f["geometry"]["coordinates"] == [pos[p] for p in f["properties"]["point_ids"]]
    # GDAL reads it as OGC:CRS84 longitude/latitude, 3-D
    df = gpd.read_file(out)
    assert CRS(df.crs).equals(CRS("OGC:CRS84")) or CRS(df.crs).to_epsg() == 4326
    assert df.has_z.all() and len(df) == len(doc["features"])


def test_geojson_written_in_chunks_is_the_same_document(bng, tmp_path, monkeypatch):
    import gsgeo.export.geojson as gj

    s, res = bng
    one = json.loads(write_measurements(tmp_path / "a.geojson", res, lines=s.lines,
                                        polygons=s.polygons).read_text())
    monkeypatch.setattr(gj, "FEATURE_CHUNK", 2)
    many = json.loads(write_measurements(tmp_path / "b.geojson", res, lines=s.lines,
                                         polygons=s.polygons).read_text())
    assert many == one and len(many["features"]) == 9


@pytest.mark.parametrize("grid", [False, True])
def test_geojson_text_equals_the_dict_built_document(odn, tmp_path, grid):
    """The template-filled GeoJSON parses to the document built with dicts and json
    (export_helpers.reference_geojson): same values, same precision, nulls, escaping."""
    from export_helpers import reference_geojson

    from gsgeo.export.geojson import feature_collection
    from gsgeo.export.tables import collect

    s, res = odn
    res = list(res)
    k = next(i for i, m in enumerate(res) if m.point_id == "P5")  # not in the polygon
    res[k] = copy.copy(res[k])
    res[k].point_id, res[k].description = "P%1 \"ü\"", 'a,"b"\n%s %b \\ 角\u2028'
    lines = [{"id": "L%d", "points": [res[k].point_id, "P2", "P3"]}]
    cps = [{"id": "P2", "easting": 1.0, "northing": 2.0, "height": 3.0}, {"id": "C9", "x": 5.0, "y": 6.0}]
    data = collect(res, lines=lines, polygons=s.polygons, check_points=cps, map_layers=False)
    want = reference_geojson(data, grid=grid)
    out = write_measurements(tmp_path / "x.geojson", res, lines=lines, polygons=s.polygons,
                             check_points=cps, fmt="geojson-grid" if grid else "geojson")
    got = json.loads(out.read_text(encoding="utf-8"))
    assert got == want and feature_collection(data, grid=grid) == want
    assert got["features"][k]["id"] == "P%1 \"ü\"" and len(got["features"]) == 6 + 1 + 1 + 2
    assert any(f["properties"]["max_residual_px"] is None for f in got["features"][:6])


def test_geojson_legacy_grid(odn, tmp_path):
    s, res = odn
    recs = _records(res)
    out = write_measurements(tmp_path / "grid.geojson", res, lines=s.lines, polygons=s.polygons,
                             fmt="geojson-grid")
    doc = json.loads(out.read_text())
    assert doc["rfc7946"] is False and "NOT RFC 7946" in doc["description"]
    assert doc["crs"] == {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::7405"}}
    p1 = next(f for f in doc["features"] if f["id"] == "P1")
    assert p1["geometry"]["coordinates"] == pytest.approx(
        [recs["P1"]["easting"], recs["P1"]["northing"], recs["P1"]["height"]], abs=5e-5)
    poly = next(f for f in doc["features"] if f["properties"]["layer"] == "polygons")
    assert _ring_ccw(poly["geometry"]["coordinates"][0])
    df = gpd.read_file(out)
    assert CRS(df.crs).equals(CRS("EPSG:27700+5701"))


# CSV ------------------------------------------------------------------------------------------
def test_csv_round_trip(odn, tmp_path):
    s, res = odn
    recs = _records(res)
    out = write_measurements(tmp_path / "out.csv", res)
    text = out.read_text(encoding="utf-8")
    header = text.splitlines()[0]
    assert header.startswith("point_id,easting,northing,height,code,")
    assert header.split(",") == list(CSV_COLUMNS) and set(CSV_COLUMNS) == set(EXPORT_KEYS)
    rows = list(csv.DictReader(text.splitlines()))
    assert len(rows) == len(recs)
    for row in rows:
        rec = recs[row["point_id"]]
        for k in RECORD_KEYS:
            v, want = row[k], rec[k]
            if want is None:
                assert v == "", k
            elif k in ("easting", "northing", "height", "h_wgs84"):
                assert abs(float(v) - want) <= 5e-5, k  # 4 decimals
            elif k in ("lon", "lat"):
                assert abs(float(v) - want) <= 5e-11, k
            elif POINT_TYPES[k] == "float":
                assert float(v) == want, k  # full precision
            elif POINT_TYPES[k] == "int":
                assert int(v) == want
            else:
                assert v == want, k
        assert row["crs"] == "EPSG:27700+5701" and row["height_type"] == "orthometric"
    # pandas reads the same numbers
    df = pd.read_csv(out)
    assert list(df.columns) == list(CSV_COLUMNS)
    np.testing.assert_array_equal(df.cov_en.to_numpy(), [recs[p]["cov_en"] for p in df.point_id])


# Errors and atomicity -------------------------------------------------------------------------
def _files(d: Path) -> list[str]:
    return sorted(p.name for p in d.iterdir())


@pytest.mark.parametrize("chunk", [10000, 2])
def test_csv_text_equals_the_csv_module_output(odn, tmp_path, monkeypatch, chunk):
    """Cell by cell the CSV is what csv.writer writes (export_helpers.reference_csv): the same
    text, quoting and empty cells; full-precision floats the same numbers (1e-05 or 1e-5)."""
    from export_helpers import reference_csv

    import gsgeo.export.csvfile as cf
    from gsgeo.export.tables import collect

    monkeypatch.setattr(cf, "CHUNK", chunk)
    _, res = odn
    res = list(res)
    for k, text in enumerate(['a,"b"', "line\nbreak", "cr\rhere", '"', " spaced ", "ü,角"]):
        res[k] = copy.copy(res[k])
        res[k].description = text
    data = collect(res, map_layers=False)
    data.points.columns["sigma0"][0] = 1.5e-7  # exponent form
    data.points.columns["lon"][1] = np.nan
    out = tmp_path / "x.csv"
    cf.write_csv(out, data)
    got = list(csv.reader(out.open(encoding="utf-8", newline="")))
    want = list(csv.reader(io.StringIO(reference_csv(data), newline="")))
    assert len(got) == len(want) == 7 and got[0] == want[0]
    for g, w in zip(got[1:], want[1:], strict=True):
        for k, a, b in zip(CSV_COLUMNS, g, w, strict=True):
            if POINT_TYPES[k] == "float" and b:
                assert float(a) == float(b), k
            else:
                assert a == b, k
    assert got[1][CSV_COLUMNS.index("lon")] != "" and got[2][CSV_COLUMNS.index("lon")] == ""
    assert [r[CSV_COLUMNS.index("description")] for r in got[1:]][:6] == [
        'a,"b"', "line\nbreak", "cr\rhere", '"', " spaced ", "ü,角"]


def test_empty_and_unsolved(tmp_path):
    with pytest.raises(InputError, match="nothing to export"):
        write_measurements(tmp_path / "a.gpkg", [])
    from gsgeo.measure import MeasurementFailure

    with pytest.raises(InputError, match=r"nothing to export.*1 point\(s\) could not be solved"):
        write_measurements(tmp_path / "a.csv", [MeasurementFailure("P1", "rays are parallel")])
    assert _files(tmp_path) == []


def test_no_grid_and_unknown_crs(rng, tmp_path):
    s = session(rng)
    res = measure_session(s, crs=None)
    with pytest.raises(CRSError, match="without grid coordinates.*--crs"):
        write_measurements(tmp_path / "a.gpkg", res)
    with pytest.raises(CRSError, match="unknown CRS 'EPSG:999999'"):
        measure_session(s, crs="EPSG:999999")
    rec = dict(measure_session(s, crs="EPSG:27700")[0].to_dict(), crs="EPSG:999999")
    with pytest.raises(CRSError, match="EPSG:999999"):
        write_measurements(tmp_path / "a.gpkg", [rec])
    assert _files(tmp_path) == []


@pytest.mark.parametrize("polygons, lines, err, match", [
    ([{"id": "A1", "points": ["P1", "P3", "P2", "P4"]}], [], GeometryError, "'A1'.*self-intersecting"),
    ([{"id": "A2", "points": ["P1", "P2"]}], [], GeometryError, "'A2'.*at least 3 distinct"),
    ([{"id": "A3", "points": ["P1", "P2", "P1"]}], [], GeometryError, "'A3'.*at least 3 distinct"),
    ([{"id": "A4", "points": ["P1", "P2", "P9"]}], [], InputError, "polygon 'A4': unknown point id 'P9'"),
    ([{"id": "A5", "points": ["P1", "P2", "P3", "P2"]}], [], InputError, "'P2' appears more than once"),
    ([], [{"id": "L9", "points": ["P1", "PX"]}], InputError, "line 'L9': unknown point id 'PX'"),
    ([], [{"id": "L8", "points": ["P1"]}], GeometryError, "line 'L8'.*at least 2 distinct"),
])
def test_bad_features_leave_earlier_export_intact(bng, tmp_path, polygons, lines, err, match):
    s, res = bng
    for name in ("out.gpkg", "out.geojson", "out.csv"):
        good = write_measurements(tmp_path / name, res, lines=s.lines, polygons=s.polygons)
        before = good.read_bytes()
        with pytest.raises(err, match=match):
            write_measurements(good, res, lines=lines, polygons=polygons)
        assert good.read_bytes() == before
    assert _files(tmp_path) == ["out.csv", "out.geojson", "out.gpkg"]


def test_polygon_closing_point_accepted(bng, tmp_path):
    _, res = bng
    out = write_measurements(tmp_path / "c.gpkg", res,
                             polygons=[{"id": "A", "points": ["P1", "P2", "P3", "P4", "P1"]}])
    df = pyogrio.read_dataframe(out, layer="polygons")
    assert df.n_points[0] == 4 and len(df.geometry[0].exterior.coords) == 5


def test_unwritable_paths(bng, tmp_path):
    _, res = bng
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir.gpkg").mkdir()
    cases = [(tmp_path / "missing" / "out.gpkg", "directory .*missing does not exist"),
             (tmp_path / "afile" / "out.gpkg", "is not a directory"),
             (tmp_path / "adir.gpkg", "is a directory"),
             (tmp_path / "out.shp", "cannot tell the export format")]
    for path, match in cases:
        with pytest.raises(InputError, match=match):
            write_measurements(path, res)
    assert _files(tmp_path) == ["adir.gpkg", "afile"]


def test_failure_while_writing_leaves_nothing(bng, tmp_path, monkeypatch):
    """A crash after the first layer: no temp file, no SQLite side files, old export intact."""
    s, res = bng
    good = write_measurements(tmp_path / "out.gpkg", res)
    before = good.read_bytes()
    import gsgeo.export.gpkg as gp

    real = gp.write_layer
    calls = []

    def boom(*a, **k):
        calls.append(a[1])
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return real(*a, **k)

    monkeypatch.setattr(gp, "write_layer", boom)
    with pytest.raises(InputError, match="cannot write .*out.gpkg: No space left on device"):
        write_measurements(good, res, lines=s.lines, polygons=s.polygons)
    assert calls == ["points", "rays"]
    assert good.read_bytes() == before and _files(tmp_path) == ["out.gpkg"]


def test_store_style_dicts_export_like_measurements(bng, tmp_path):
    """The project store keeps Measurement.to_dict() JSON; exporting that gives the same file content."""
    s, res = bng
    dicts = [json.loads(json.dumps(m.to_dict())) for m in res]
    a = write_measurements(tmp_path / "a.geojson", res, lines=s.lines, polygons=s.polygons)
    b = write_measurements(tmp_path / "b.geojson", dicts,
                           lines=[{"id": f.id, "point_ids": f.points} for f in s.lines],
                           polygons=[(f.id, f.points) for f in s.polygons])
    assert json.loads(a.read_text()) == json.loads(b.read_text())
    ra = pyogrio.read_dataframe(write_measurements(tmp_path / "a.gpkg", res), layer="rays")
    rb = pyogrio.read_dataframe(write_measurements(tmp_path / "b.gpkg", dicts), layer="rays")
    assert ra.drop(columns="geometry").equals(rb.drop(columns="geometry"))
    assert shapely.equals_exact(ra.geometry.values, rb.geometry.values, tolerance=0).all()


# Command line ---------------------------------------------------------------------------------
def _session_file(tmp_path, rng, **kw):
    from export_helpers import session_doc

    p = tmp_path / "session.json"
    p.write_text(json.dumps(session_doc(rng, **kw)))
    return p


@pytest.mark.parametrize("name", ["out.gpkg", "out.geojson", "out.csv"])
def test_cli_solve_exports(tmp_path, rng, capsys, name):
    from gsgeo.cli import main

    sess = _session_file(tmp_path, rng)
    out = tmp_path / name
    assert main(["solve", str(sess), "--crs", "EPSG:27700", "-o", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().err
    if name.endswith(".gpkg"):
        assert {n for n, _ in pyogrio.list_layers(out)} == ALL_LAYERS
        assert CRS(pyogrio.read_info(out, layer="points")["crs"]).equals(CRS("EPSG:27700"))
    elif name.endswith(".geojson"):
        doc = json.loads(out.read_text())
        assert "crs" not in doc and len(doc["features"]) == 6 + 2 + 1
    else:
        assert len(out.read_text().splitlines()) == 1 + 6


def test_cli_legacy_geojson_and_errors(tmp_path, rng, capsys):
    from gsgeo.cli import main

    sess = _session_file(tmp_path, rng)
    out = tmp_path / "grid.json"
    assert main(["solve", str(sess), "--crs", "EPSG:27700", "-o", str(out),
                 "--export-format", "geojson-grid"]) == 0
    assert json.loads(out.read_text())["crs"]["properties"]["name"] == "urn:ogc:def:crs:EPSG::27700"
    capsys.readouterr()
    cases = [
        (["--crs", "EPSG:999999", "-o", str(tmp_path / "x.gpkg")], "unknown CRS 'EPSG:999999'"),
        (["-o", str(tmp_path / "x.gpkg")], "-o/--output needs a grid CRS"),
        (["--crs", "EPSG:27700", "-o", str(tmp_path / "x.txt")], "cannot tell the export format"),
        (["--crs", "EPSG:27700", "-o", str(tmp_path / "no" / "x.csv")], "does not exist"),
    ]
    for extra, msg in cases:
        assert main(["solve", str(sess), *extra]) == 2
        err = capsys.readouterr().err
        assert msg in err and "Traceback" not in err
    bad = _session_file(tmp_path, rng, polygons=[{"id": "A1", "points": ["P1", "P3", "P2", "P4"]}])
    assert main(["solve", str(bad), "--crs", "EPSG:27700", "-o", str(tmp_path / "x.gpkg")]) == 2
    assert "polygon 'A1': the polygon is self-intersecting" in capsys.readouterr().err
    empty = tmp_path / "empty.json"
    empty.write_text(json.dumps({"points": []}))
    assert main(["solve", str(empty), "--crs", "EPSG:27700", "-o", str(tmp_path / "x.gpkg")]) == 2
    assert "no points" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.json", "grid.json", "session.json"]


def test_text_fields_with_unicode_commas_quotes_and_newlines(tmp_path, rng):
    from export_helpers import session_doc

    from gsgeo.session import parse_session

    doc = session_doc(rng, lines=[], polygons=[])
    doc["points"][0]["id"] = "Pünkt 1"
    doc["points"][0]["description"] = 'gable, "north"\nsecond line; 角'
    res = measure_session(parse_session(doc), crs="EPSG:27700")
    want = doc["points"][0]["description"]
    rows = list(csv.DictReader(write_measurements(tmp_path / "t.csv", res).open(encoding="utf-8",
                                                                               newline="")))
    assert rows[0]["point_id"] == "Pünkt 1" and rows[0]["description"] == want
    gj = json.loads(write_measurements(tmp_path / "t.geojson", res).read_text(encoding="utf-8"))
    assert gj["features"][0]["id"] == "Pünkt 1" and gj["features"][0]["properties"]["description"] == want
    df = pyogrio.read_dataframe(write_measurements(tmp_path / "t.gpkg", res), layer="points")
    assert df.point_id[0] == "Pünkt 1" and df.description[0] == want


def test_gpkg_without_arrow_write_is_the_same(bng, tmp_path, monkeypatch):
    """With a GDAL older than 3.8 (no Arrow write) layers go feature by feature: same content."""
    import sqlite3

    import gsgeo.export.gpkg as gp

    s, res = bng
    cps = [{"id": "P1", "easting": 1.0, "northing": 2.0}]
    a = write_measurements(tmp_path / "a.gpkg", res, lines=s.lines, polygons=s.polygons, check_points=cps)
    monkeypatch.setattr(gp, "arrow_write_available", lambda: False)
    b = write_measurements(tmp_path / "b.gpkg", res, lines=s.lines, polygons=s.polygons, check_points=cps)
    with sqlite3.connect(a) as ca, sqlite3.connect(b) as cb:
        tables = [r[0] for r in ca.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
        assert len(tables) > 20
        for sql in ["SELECT type, name, sql FROM sqlite_master ORDER BY name"] + [
                f'SELECT * FROM "{t}"' for t in tables if t != "gpkg_contents"]:
            assert ca.execute(sql).fetchall() == cb.execute(sql).fetchall(), sql
        sql = "SELECT table_name, description, min_x, max_y, srs_id FROM gpkg_contents ORDER BY 1"
        assert ca.execute(sql).fetchall() == cb.execute(sql).fetchall()


@pytest.mark.parametrize("suffix", [".gpkg", ".geojson", ".csv"])
def test_text_that_is_not_unicode_is_a_clear_error(bng, tmp_path, suffix):
    """JSON input can carry a lone surrogate ("\\ud800"); no format can store it: InputError
    naming the point and the field, and no file."""
    s, res = bng
    res = list(res)
    res[1] = copy.copy(res[1])
    res[1].description = "bad \ud800 text"
    with pytest.raises(InputError, match=f"points '{res[1].point_id}': description is not valid Unicode"):
        write_measurements(tmp_path / f"x{suffix}", res)
    res[1].point_id = "P\udc80"
    with pytest.raises(InputError, match=r"points\[1\]: point_id is not valid Unicode"):
        write_measurements(tmp_path / f"x{suffix}", res)
    with pytest.raises(InputError, match=r"lines\[0\]: line_id is not valid Unicode"):
        write_measurements(tmp_path / f"x{suffix}", res[2:],
                           lines=[{"id": "L\ud800", "points": ["P3", "P4"]}])
    assert list(tmp_path.iterdir()) == []
