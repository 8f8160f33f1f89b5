"""Hypothesis fuzzes POST /api/projects/{pid}/checkpoints/import with malformed files.

CSV (dialects, quotes, huge fields and numbers, random bytes), GeoJSON (random JSON, deep
nesting, numbers beyond a double) and GeoPackages corrupted by truncation and flipped bytes.
No file may get a 5xx, every refusal names the problem, and a refused import leaves the
project's check points and points exactly as they were. Bounded: a few seconds in all.
"""

from __future__ import annotations

import json
import warnings

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from servertools import london_rays

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from hypothesis_profiles import examples

from gsgeo.server.app import ServerConfig, create_app

PID = "fuzz"
FUZZ = settings(max_examples=examples(40), deadline=None,
                suppress_health_check=list(HealthCheck))


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    app = create_app(ServerConfig(data_dir=tmp_path_factory.mktemp("fuzz") / "data",
                                  allowed_hosts={"testserver"}))
    with TestClient(app, raise_server_exceptions=False) as c:
        c.post("/api/projects", json={"name": PID, "id": PID, "crs": "EPSG:32630"})
        c.post(f"/api/projects/{PID}/points", json={"id": "P1", "rays": london_rays(3)})
        c.post(f"/api/projects/{PID}/checkpoints", json={"crs": "EPSG:32630", "points": [
            {"id": "K1", "x": 699000.5, "y": 5710000.25, "z": 40.0}, {"id": "K2", "x": 1, "y": 2}]})
        yield c


def stored(client) -> tuple:
    cps = client.get(f"/api/projects/{PID}/checkpoints").json()
    pts = client.get(f"/api/projects/{PID}/points?summary=true").json()
    return cps, pts


def check_import(client, name: str, content: bytes, form: dict) -> None:
    before = stored(client)
    r = client.post(f"/api/projects/{PID}/checkpoints/import", files={"file": (name, content)},
                    data=form)
    assert r.status_code < 500, (r.status_code, r.text[:500])
    if r.status_code == 201:
        return
    msg = r.json()["message"]
    assert msg, r.text
    if r.status_code == 422 and "file" in (r.json().get("field") or ""):
        assert name in msg, msg  # the refusal names the file
    assert stored(client) == before  # a refused import changes nothing


FORM = st.fixed_dictionaries({"crs": st.sampled_from(["EPSG:32630", "EPSG:4979", ""]),
                              "replace": st.sampled_from(["true", "false"])})


# CSV -------------------------------------------------------------------------------------------
HEADERS = ["id,x,y", "point_id;easting;northing;height", "name\te\tn\th", "label,lon,lat",
           "who,what", ""]
NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=300, max_value=6000).map(lambda n: "9" * n),
    st.sampled_from(["1e309", "-1e999", "nan", "inf", "0x10", "1_000", "", " ", "1,5", "--1"]),
)
FIELDS = st.one_of(NUMBERS, st.text(max_size=20),
                   st.integers(min_value=131_000, max_value=140_000).map(lambda n: "x" * n),
                   st.sampled_from(['"', '""', '"a,b"', "\x00", "\r", "\u2028", "P1", "K1"]))


@st.composite
def csv_files(draw) -> bytes:
    delim = draw(st.sampled_from([",", ";", "\t", "|"]))
    rows = [draw(st.sampled_from(HEADERS)).replace(",", delim)]
    for _ in range(draw(st.integers(0, 6))):
        rows.append(delim.join(draw(st.lists(FIELDS, min_size=0, max_size=5))))
    text = draw(st.sampled_from(["\n", "\r\n", "\r"])).join(rows)
    data = text.encode("utf-8", "surrogatepass")
    if draw(st.booleans()):
        return data
    return draw(st.sampled_from([b"\xef\xbb\xbf", b"", b"\xff\xfe"])) + data


@FUZZ
@given(data=st.one_of(csv_files(), st.binary(max_size=300)), form=FORM)
def test_csv_imports_never_fail_the_server(client, data, form):
    check_import(client, "points.csv", data, form)


# GeoJSON ---------------------------------------------------------------------------------------
JSON = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=False, allow_infinity=False)
    | st.integers(min_value=-(2**70), max_value=2**70) | st.text(max_size=10),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                max_size=4),
    max_leaves=12)
BIG_NUMBER = st.one_of(st.integers(min_value=309, max_value=6000).map(lambda n: "1" + "0" * n),
                       st.sampled_from(["1e400", "-1e400", "NaN", "Infinity", "1e-400"]))


@st.composite
def geojson_files(draw) -> bytes:
    kind = draw(st.integers(0, 3))
    if kind == 0:  # random JSON
        return json.dumps(draw(JSON)).encode()
    if kind == 1:  # deep nesting
        depth = draw(st.one_of(st.integers(100, 3000), st.integers(3000, 200_000)))
        opener, closer = draw(st.sampled_from([("[", "]"), ('{"a":', "}")]))
        return (opener * depth + "1" + closer * depth).encode()
    coords = [draw(st.one_of(BIG_NUMBER, st.floats().map(json.dumps), st.just("2")))
              for _ in range(draw(st.sampled_from([2, 3, 3, 0, 1, 4])))]
    ident = draw(st.one_of(BIG_NUMBER, JSON.map(json.dumps), st.just('"G1"')))
    geometry = draw(st.sampled_from(["Point", "Point", "Point", "LineString"]))
    feature = (f'{{"type": "Feature", "properties": {{"id": {ident}, "extra": '
               f'{json.dumps(draw(JSON))}}}, "geometry": {{"type": "{geometry}", '
               f'"coordinates": [{", ".join(coords)}]}}}}')
    if kind == 2:
        return feature.encode()
    features = ", ".join([feature] * draw(st.integers(1, 3)))
    return f'{{"type": "FeatureCollection", "features": [{features}]}}'.encode()


@FUZZ
@given(data=geojson_files(), form=FORM)
def test_geojson_imports_never_fail_the_server(client, data, form):
    check_import(client, "points.geojson", data, form)


# GeoPackage ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def gpkg_bytes(tmp_path_factory) -> bytes:
    import geopandas as gpd
    from shapely.geometry import Point

    path = tmp_path_factory.mktemp("gpkg") / "cps.gpkg"
    gpd.GeoDataFrame({"point_id": ["G1", "G2", "G3"], "code": ["a", "b", "c"]},
                     geometry=[Point(699000.0 + k, 5710000.0, 40.0 + k) for k in range(3)],
                     crs="EPSG:32630").to_file(path, layer="cps", driver="GPKG")
    return path.read_bytes()


@st.composite
def corruptions(draw) -> tuple[float, list[tuple[float, int]]]:
    """(kept fraction of the file, [(position as a fraction, XOR mask), ...])."""
    keep = draw(st.one_of(st.just(1.0), st.floats(0.0, 1.0)))
    flips = draw(st.lists(st.tuples(st.floats(0.0, 1.0, exclude_max=True),
                                    st.integers(1, 255)), max_size=8))
    return keep, flips


def corrupt(data: bytes, keep: float, flips: list[tuple[float, int]]) -> bytes:
    out = bytearray(data[: int(len(data) * keep)])
    for where, mask in flips:
        if out:
            out[int(where * len(out))] ^= mask
    return bytes(out)


def test_the_uncorrupted_geopackage_imports(client, gpkg_bytes):
    # the module's project may hold these ids from the fuzzed imports: the file is the whole set
    r = client.post(f"/api/projects/{PID}/checkpoints/import",
                    files={"file": ("cps.gpkg", gpkg_bytes)}, data={"role": "control", "replace": "true"})
    assert r.status_code == 201 and r.json() == {"imported": 3, "crs": "EPSG:32630",
                                                 "format": "gpkg"}


@FUZZ
@given(damage=corruptions(), form=FORM)
def test_corrupt_geopackages_never_fail_the_server(client, gpkg_bytes, damage, form):
    check_import(client, "points.gpkg", corrupt(gpkg_bytes, *damage), form)
