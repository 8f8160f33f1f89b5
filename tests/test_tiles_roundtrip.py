"""PLY -> gsgeo tiles -> read back in ECEF, for every georeference option.

Expected ECEF values come from pyproj directly (topocentric, projected CRS -> geocentric) and
from hand-written matrices; orientations for grid input from a finite-difference Jacobian of
the pyproj transformation (independent of the convergence/scale-factor code under test).
"""

from __future__ import annotations

import json

import numpy as np
import pyproj
import pytest

from gsgeo.tiles.build import build_tileset
from gsgeo.tiles.georef import Georeference
from gsgeo.tiles.ply import write_ply
from gsgeo.tiles.reader import read_tileset, splat_count
from gsgeo.tiles.splats import quat_to_matrix, sh_rotation
from tests.tiles_helpers import (
    TOL_ALPHA,
    TOL_COLOR,
    TOL_LOG_SCALE,
    TOL_POS_M,
    TOL_ROT_DEG,
    TOL_SH,
    match,
    random_splats,
    rotation_error_deg,
    sigmoid,
)

LAT, LON, H = 40.01609, -83.02341, 210.0


def _enu_basis(lat, lon):
    """Rows east, north, up (docs/architecture.md, 'Frames and conventions')."""
    p, l = np.radians(lat), np.radians(lon)
    return np.array([[-np.sin(l), np.cos(l), 0],
                     [-np.sin(p) * np.cos(l), -np.sin(p) * np.sin(l), np.cos(p)],
                     [np.cos(p) * np.cos(l), np.cos(p) * np.sin(l), np.sin(p)]])


def _topocentric_to_ecef(enu, lat, lon, h):
    t = pyproj.Transformer.from_pipeline(
        f"+proj=topocentric +ellps=WGS84 +lat_0={lat} +lon_0={lon} +h_0={h}")
    x, y, z = t.transform(enu[:, 0], enu[:, 1], enu[:, 2], direction="INVERSE")
    return np.stack([x, y, z], axis=1)


def _check(tmp_path, s, georef, expected_ecef, expected_rot, log_scale_shift=0.0,
           sh_turn=None, max_splats=1000):
    ply = tmp_path / "in.ply"
    write_ply(ply, s)
    out = tmp_path / "out"
    summary = build_tileset(ply, out, georef, max_splats=max_splats, progress=None)
    assert summary.splats_written == s.count and summary.dropped_nonfinite == 0
    assert splat_count(out) == s.count
    got = read_tileset(out)
    assert got.count == s.count
    idx = match(expected_ecef, got.positions)
    assert len(np.unique(idx)) == s.count            # one-to-one: every splat exactly once
    g = got.take(idx)
    err = np.linalg.norm(g.positions - expected_ecef, axis=1)
    assert err.max() <= TOL_POS_M, f"max centre error {err.max() * 1000:.3f} mm"
    assert rotation_error_deg(expected_rot, g.rotations).max() <= TOL_ROT_DEG
    assert np.abs(g.scales - (s.scales + log_scale_shift)).max() <= TOL_LOG_SCALE
    assert np.abs(sigmoid(g.opacities) - sigmoid(s.opacities)).max() <= TOL_ALPHA
    assert np.abs(g.colors - s.colors).max() <= TOL_COLOR
    if s.sh.shape[1]:
        d = sh_rotation(sh_turn, s.sh.shape[1])
        want = np.einsum("ij,njc->nic", d, s.sh)
        # per band, the L2 error is bounded by the per-coefficient one (D is orthogonal)
        for lo, hi in ((0, 3), (3, 8), (8, 15)):
            e = np.linalg.norm(g.sh[:, lo:hi] - want[:, lo:hi], axis=1).max()
            assert e <= TOL_SH * np.sqrt(hi - lo) + 1e-5
    return summary, out


@pytest.mark.parametrize("degree", [0, 3])
@pytest.mark.parametrize("heading", [0.0, 37.5])
def test_origin(tmp_path, rng, degree, heading):
    s = random_splats(rng, 3000, degree, centre=(120.0, -60.0, 5.0))
    g = Georeference("origin", origin=(LAT, LON, H), heading=heading)
    a = np.radians(heading)
    # input +y points at `heading` clockwise from north
    turn = np.array([[np.cos(a), np.sin(a), 0], [-np.sin(a), np.cos(a), 0], [0, 0, 1]])
    enu = s.positions @ turn.T
    r_total = _enu_basis(LAT, LON).T @ turn
    summary, out = _check(tmp_path, s, g, _topocentric_to_ecef(enu, LAT, LON, H),
                          r_total @ quat_to_matrix(s.rotations.astype(float)), sh_turn=r_total)
    doc = json.loads((out / "tileset.json").read_text())
    assert doc["asset"]["version"] == "1.1"
    lon_c, lat_c, _ = summary.root_lon_lat_h
    assert abs(lat_c - LAT) < 0.01 and abs(lon_c - LON) < 0.01


@pytest.mark.parametrize("axes, turn", [
    ("y-up", [[1, 0, 0], [0, 0, -1], [0, 1, 0]]),
    ("y-down", [[1, 0, 0], [0, 0, 1], [0, -1, 0]]),
])
def test_axis_conventions(tmp_path, rng, axes, turn):
    s = random_splats(rng, 2000, 3)
    turn = np.array(turn, float)
    g = Georeference("origin", origin=(LAT, LON, H), axes=axes)
    r_total = _enu_basis(LAT, LON).T @ turn
    _check(tmp_path, s, g, _topocentric_to_ecef(s.positions @ turn.T, LAT, LON, H),
           r_total @ quat_to_matrix(s.rotations.astype(float)), sh_turn=r_total)


def test_no_georeference_uses_default_origin_with_warning(tmp_path, rng):
    s = random_splats(rng, 1500, 0)
    g = Georeference("none")
    summary, _ = _check(tmp_path, s, g, _topocentric_to_ecef(s.positions, 0.0, 0.0, 0.0),
                        _enu_basis(0, 0).T @ quat_to_matrix(s.rotations.astype(float)))
    assert any("default origin" in w for w in summary.warnings)


@pytest.mark.parametrize("degree", [0, 3])
def test_transform_matrix(tmp_path, rng, degree):
    s = random_splats(rng, 2500, degree)
    q = rng.normal(size=4)
    rot = quat_to_matrix(q / np.linalg.norm(q))
    scale = 1.7
    m = np.eye(4)
    m[:3, :3] = scale * rot
    m[:3, 3] = [594147.335, -4855341.260, 4079353.987]
    path = tmp_path / "m.json"
    path.write_text(json.dumps(m.T.reshape(-1).tolist()))   # column-major, as 3D Tiles
    from gsgeo.tiles.georef import load_matrix
    g = Georeference("transform", matrix=load_matrix(path))
    expected = s.positions @ m[:3, :3].T + m[:3, 3]
    _check(tmp_path, s, g, expected, rot @ quat_to_matrix(s.rotations.astype(float)),
           log_scale_shift=np.log(scale), sh_turn=rot)


def _grid_jacobian(t, e, n, h, d=0.5):
    """Finite-difference Jacobian (N, 3, 3) of the pyproj grid -> ECEF transformation."""
    cols = []
    for de in np.eye(3):
        xp = np.stack(t.transform(e + d * de[0], n + d * de[1], h + d * de[2]), 1)
        xm = np.stack(t.transform(e - d * de[0], n - d * de[1], h - d * de[2]), 1)
        cols.append((xp - xm) / (2 * d))
    return np.stack(cols, axis=2)


@pytest.mark.parametrize("degree", [0, 3])
def test_projected_crs_with_offset(tmp_path, rng, degree):
    offset = (330000.0, 4430000.0, 180.0)            # UTM 17N near Columbus, Ohio
    # far from the central meridian (81 W), so convergence is about -1.3 degrees
    s = random_splats(rng, 3000, degree, extent=60.0, centre=(-2000.0, 500.0, 0.0))
    g = Georeference("crs", crs="EPSG:32617", offset=offset)
    t = pyproj.Transformer.from_crs(pyproj.CRS("EPSG:32617").to_3d(), "EPSG:4978",
                                    always_xy=True)
    e, n, h = (s.positions + offset).T
    expected = np.stack(t.transform(e, n, h), axis=1)
    jac = _grid_jacobian(t, e, n, h)
    u, sv, vt = np.linalg.svd(jac)
    r_grid = u @ vt                                   # rotation part (polar decomposition)
    # ECEF metres per grid metre horizontally = 1/k, k the point scale factor
    inv_k = np.sqrt(sv[:, 0] * sv[:, 1])
    assert np.all(np.abs(np.degrees(np.arccos(np.clip(
        (np.trace(_enu_basis(40.0, -83.0) @ r_grid[0]) - 1) / 2, -1, 1)))) > 1.0)
    # SH turn: the splat frame's rotation at the scene centre is what we check against
    _check(tmp_path, s, g, expected, r_grid @ quat_to_matrix(s.rotations.astype(float)),
           log_scale_shift=np.log(inv_k)[:, None].astype(np.float32),
           sh_turn=r_grid[np.argmin(np.linalg.norm(s.positions - s.positions.mean(0), axis=1))])


def test_nonfinite_splats_are_dropped_and_counted(tmp_path, rng):
    s = random_splats(rng, 500, 1)
    s.positions[3, 1] = np.nan
    s.scales[10, 2] = np.inf
    s.sh[20, 1, 2] = np.nan
    write_ply(tmp_path / "in.ply", s)
    summary = build_tileset(tmp_path / "in.ply", tmp_path / "out",
                            Georeference("origin", origin=(LAT, LON, H)), progress=None)
    assert (summary.splats_in, summary.splats_written, summary.dropped_nonfinite) == (500, 497, 3)
    assert "NaN/inf dropped" in summary.text()
    assert read_tileset(tmp_path / "out").count == 497


def test_nonfinite_screen_of_float_records_equals_the_exact_check(tmp_path, rng):
    """Binary PLY blocks are screened by one row sum over every float of a record; records
    it flags get the exact per-attribute check. A NaN normal (a property gsgeo ignores) keeps
    its splat; a zero quaternion, a NaN opacity or an infinite SH coefficient drop theirs."""
    from gsgeo.tiles.ply import read_layout
    from gsgeo.tiles.source import open_source

    s = random_splats(rng, 3000, 3)
    write_ply(tmp_path / "in.ply", s)
    lay = read_layout(tmp_path / "in.ply")
    rec = np.memmap(tmp_path / "in.ply", lay.dtype, "r+", offset=lay.data_offset, shape=lay.count)
    rec["nx"][7] = np.nan
    rec["ny"][8] = np.inf
    for name in ("rot_0", "rot_1", "rot_2", "rot_3"):
        rec[name][100] = 0.0
    rec["opacity"][200] = np.nan
    rec["f_rest_44"][2999] = -np.inf
    rec["nx"][1500] = rec["ny"][1500] = 2e38  # finite, but the row sum overflows: exact check
    rec.flush()
    del rec
    src = open_source(tmp_path / "in.ply", 1024)
    for a in range(0, 3000, 1024):
        got, ok = src.read_finite(a, min(3000, a + 1024))
        np.testing.assert_array_equal(ok, got.finite_mask())
    summary = build_tileset(tmp_path / "in.ply", tmp_path / "out",
                            Georeference("origin", origin=(LAT, LON, H)), progress=None)
    assert summary.dropped_nonfinite == 3


def _geoid_tif(path, n0=-33.0, slope=0.5):
    """A small geoid grid over Ohio: N = n0 + slope * (lon + 83) metres, WGS 84 lon/lat."""
    import rasterio
    from rasterio.transform import from_origin
    lon = -84.0 + 0.05 * (np.arange(41) + 0.5)
    data = np.tile((n0 + slope * (lon + 83.0)).astype(np.float32), (41, 1))
    with rasterio.open(path, "w", driver="GTiff", width=41, height=41, count=1,
                       dtype="float32", crs="EPSG:4326",
                       transform=from_origin(-84.0, 41.0, 0.05, 0.05)) as ds:
        ds.write(data, 1)


def test_projected_crs_with_geoid_heights(tmp_path, rng):
    tif = tmp_path / "geoid.tif"
    _geoid_tif(tif)
    offset = (330000.0, 4430000.0, 180.0)
    s = random_splats(rng, 1500, 0, extent=50.0)
    g = Georeference("crs", crs="EPSG:32617", offset=offset, height="geoid", geoid=str(tif))
    e, n, hh = (s.positions + offset).T
    lon, lat = pyproj.Transformer.from_crs("EPSG:32617", "EPSG:4326", always_xy=True).transform(e, n)
    # bilinear between pixel centres of a grid linear in lon is exact
    h = hh + (-33.0 + 0.5 * (lon + 83.0))
    x, y, z = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True).transform(lon, lat, h)
    expected = np.stack([x, y, z], axis=1)
    write_ply(tmp_path / "in.ply", s)
    build_tileset(tmp_path / "in.ply", tmp_path / "out", g, progress=None)
    got = read_tileset(tmp_path / "out")
    idx = match(expected, got.positions)
    assert np.linalg.norm(got.positions[idx] - expected, axis=1).max() <= TOL_POS_M


def test_vertical_crs_without_its_grid_is_refused(tmp_path, rng):
    from gsgeo.errors import DatumError
    s = random_splats(rng, 10, 0)
    write_ply(tmp_path / "in.ply", s)
    g = Georeference("crs", crs="EPSG:32617", offset=(330000.0, 4430000.0, 180.0),
                     height="vertical", vertical_crs="EPSG:5703")
    with pytest.raises(DatumError, match="geoid grid"):
        build_tileset(tmp_path / "in.ply", tmp_path / "out", g, progress=None)
    assert not (tmp_path / "out").exists()


def test_worker_processes_write_the_same_tileset(tmp_path, rng):
    """Forked workers (small blocks, dropped splats, the pyproj grid path) must write exactly
    the files one process writes; the in-process path is what the tests above check."""
    s = random_splats(rng, 6000, 3, extent=60.0, centre=(-2000.0, 500.0, 0.0))
    s.positions[17, 0] = np.nan
    s.opacities[4000] = np.inf
    write_ply(tmp_path / "in.ply", s)
    g = Georeference("crs", crs="EPSG:32617", offset=(330000.0, 4430000.0, 180.0))
    one = build_tileset(tmp_path / "in.ply", tmp_path / "one", g, max_splats=1000,
                        progress=None, workers=1)
    g = Georeference("crs", crs="EPSG:32617", offset=(330000.0, 4430000.0, 180.0))
    two = build_tileset(tmp_path / "in.ply", tmp_path / "two", g, max_splats=1000,
                        progress=None, workers=2, block=700)
    assert (one.splats_written, one.dropped_nonfinite) == (two.splats_written,
                                                           two.dropped_nonfinite) == (5998, 2)
    files = sorted(p.relative_to(tmp_path / "one") for p in (tmp_path / "one").rglob("*.glb"))
    assert len(files) > 3
    assert files == sorted(p.relative_to(tmp_path / "two") for p in (tmp_path / "two").rglob("*.glb"))
    for f in files:
        assert (tmp_path / "one" / f).read_bytes() == (tmp_path / "two" / f).read_bytes(), f
    one_doc, two_doc = (json.loads((tmp_path / d / "tileset.json").read_text())
                        for d in ("one", "two"))
    for doc in (one_doc, two_doc):  # when each was tiled (to the second) may differ
        (entry,) = doc["extras"]["gsgeo"]["georef"]["history"]
        assert entry.pop("at").endswith("Z")
    assert one_doc == two_doc
