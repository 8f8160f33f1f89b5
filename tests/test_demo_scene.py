"""The demo scene: analytic geometry, splats, PLY, tileset and ground truth.

References are independent of gsgeo.demo: hand-computed geometry, quaternions turned into
matrices by hand, PLY read with plyfile, ECEF and heights from pyproj directly.
"""

from __future__ import annotations

import hashlib
import math
import re

import numpy as np
import pyproj
import pytest
from plyfile import PlyData

from gsgeo.demo import place, scene
from gsgeo.demo import splats as demo_splats
from gsgeo.demo.build import build_demo, paths

SH_C0 = 0.28209479177387814


# --- geometry -------------------------------------------------------------------------------

def test_validation_points_cover_the_papers_cases():
    vps = scene.VALIDATION_POINTS
    assert len(vps) == 20
    ids = [v.id for v in vps]
    assert len(set(ids)) == 20
    # the web client names new points P1, P2, ...: truth ids must never collide with those
    assert not any(re.fullmatch(r"P\d+", i) for i in ids)
    counts = {s: sum(v.subset == s for v in vps) for s in scene.SUBSETS}
    assert counts == {"targets": 5, "building corners": 6, "thin poles": 5, "low corners": 4}
    low = [v.xyz[2] for v in vps if v.subset == "low corners"]
    assert max(low) <= 0.6 + 1e-12 and min(low) >= 0.25 - 1e-12


def test_sculpture_corners_by_hand():
    c = scene.sculpture_corners()
    a = math.radians(30)
    u, v = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    expect_xy = np.array([6, 6]) + np.array([-0.8 * u - 0.45 * v, 0.8 * u - 0.45 * v,
                                             0.8 * u + 0.45 * v, -0.8 * u + 0.45 * v])
    np.testing.assert_allclose(c[:, :2], expect_xy, atol=1e-12)
    np.testing.assert_allclose(c[:, 2], [0.25, 0.60, 0.60, 0.25], atol=1e-12)


def test_first_hit_by_hand():
    o = np.array([
        [-9.0, 5.5, 30.0],     # straight down on the ridge: z = 7.5
        [-9.0, 3.75, 30.0],    # down on the south slope, half-way: z = 6.25
        [9.0, -8.0, 30.0],     # down on a pole's top: z = 4
        [-30.0, 5.0, 1.0],     # east at 1 m height into the west gable wall x = -14
        [9.2, -8.0, 30.0],     # beside the pole (radius 4 cm): the ground
        [0.0, 0.0, 10.0],      # up: nothing
        [20.0, RAIL := -12.0, 1.05],  # west along the top rail's axis: its end cap at x = -2
    ])
    d = np.array([[0, 0, -1.0], [0, 0, -1.0], [0, 0, -1.0], [1.0, 0, 0], [0, 0, -1.0],
                  [0, 0, 1.0], [-1.0, 0, 0]])
    t = scene.first_hit(o, d)
    np.testing.assert_allclose(t[:5], [22.5, 23.75, 26.0, 16.0, 30.0], atol=1e-9)
    assert math.isinf(t[5])
    # the end post at x = -2 (radius 2.5 cm) is met before the rail's cap at x = -2
    assert t[6] == pytest.approx(22.0 - scene.RAIL_POST_RADIUS, abs=1e-9)
    assert RAIL == scene.RAIL_Y


def test_visibility_of_corners():
    b1 = np.array(scene.BUILDING_X[0:1] + (scene.BUILDING_Y[0], scene.EAVES_Z))  # south-west
    outside = np.array([[-30.0, -20.0, 20.0]])     # south-west and above: sees the corner
    behind = np.array([[0.0, 20.0, 6.0]])          # north-east, low: the roof hides it
    assert scene.visible(outside, b1[None])[0]
    assert not scene.visible(behind, b1[None])[0]
    pole_top = np.array([[3.0, -8.0, 4.0]])
    assert scene.visible(np.array([[3.0, -20.0, 10.0]]), pole_top)[0]
    assert not scene.visible(np.array([[3.0, -20.0, 2.0]]), pole_top)[0]  # from below the top


def test_surface_height_by_hand():
    x = np.array([-9.0, -9.0, 9.0, 9.05, 6.0, 0.0])
    y = np.array([5.5, 2.0, -8.0, -8.0, 6.0, 0.0])
    np.testing.assert_allclose(scene.surface_height(x, y), [7.5, 5.0, 4.0, 0.0, 0.425, 0.0],
                               atol=1e-12)


# --- splats and PLY -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def ply_twice(tmp_path_factory):
    d = tmp_path_factory.mktemp("ply")
    a, b = d / "a.ply", d / "b.ply"
    demo_splats.write_ply(a, demo_splats.build_part())
    demo_splats.write_ply(b, demo_splats.build_part())
    return a, b


def test_ply_is_deterministic_and_modest(ply_twice):
    a, b = ply_twice
    ha, hb = (hashlib.sha256(p.read_bytes()).hexdigest() for p in (a, b))
    assert ha == hb
    v = PlyData.read(str(a))["vertex"]
    assert 200_000 <= v.count <= 600_000
    names = [p.name for p in v.properties]
    assert names == ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                     "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]


def _rgb(v) -> np.ndarray:
    return 0.5 + SH_C0 * np.stack([v["f_dc_0"], v["f_dc_1"], v["f_dc_2"]], -1)


def test_truth_markers_in_the_ply(ply_twice):
    v = PlyData.read(str(ply_twice[0]))["vertex"]
    xyz = np.stack([v["x"], v["y"], v["z"]], -1).astype(np.float64)
    rgb = _rgb(v)
    for vp in scene.VALIDATION_POINTS:
        dist = np.linalg.norm(xyz - np.array(vp.xyz), axis=1)
        order = np.argsort(dist)
        assert dist[order[0]] < 1e-5, vp.id          # a splat exactly on the truth (float32)
        np.testing.assert_allclose(rgb[order[0]], demo_splats.MARKER_RGB, atol=1e-3)
        assert np.exp(v["scale_0"][order[0]]) == pytest.approx(demo_splats.MARKER_SIZE, rel=1e-4)
        assert dist[order[1]] > 0.005, vp.id         # and it is the only one there


def _quat_wxyz_to_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def test_flat_splats_lie_in_their_surfaces(ply_twice):
    """The thin axis of a roof splat is the roof's normal; of a ground splat, the vertical
    (rotations w-first, scales natural logs: the INRIA convention)."""
    v = PlyData.read(str(ply_twice[0]))["vertex"]
    xyz = np.stack([v["x"], v["y"], v["z"]], -1)
    q = np.stack([v[f"rot_{i}"] for i in range(4)], -1).astype(np.float64)
    s = np.exp(np.stack([v[f"scale_{i}"] for i in range(3)], -1))
    x0, x1 = scene.BUILDING_X
    south_roof = ((xyz[:, 0] > x0 + 0.2) & (xyz[:, 0] < x1 - 0.2) & (xyz[:, 1] > 2.3)
                  & (xyz[:, 1] < 5.2) & (xyz[:, 2] > 5.1))
    ground = (np.abs(xyz[:, 2]) < 1e-6) & (np.abs(xyz[:, 0]) > 1) & (np.abs(xyz[:, 0]) < 2)
    big = s.max(axis=1) > 0.02          # surface splats, not the targets' discs or the dots
    south_roof &= big
    ground &= big
    slope = (scene.RIDGE_Z - scene.EAVES_Z) / (scene.RIDGE_Y - scene.BUILDING_Y[0])
    n_roof = np.array([0.0, -slope, 1.0]) / math.hypot(slope, 1.0)
    for mask, normal in ((south_roof, n_roof), (ground, np.array([0.0, 0.0, 1.0]))):
        assert mask.sum() > 1000
        m = _quat_wxyz_to_matrix(q[mask])
        thin = np.argmin(s[mask], axis=1)
        axis = m[np.arange(mask.sum()), :, thin]        # column of the thinnest scale
        assert np.all(np.abs(axis @ normal) > 1 - 1e-5)
        assert np.all(s[mask].min(axis=1) < 0.01)


# --- tileset and ground truth ---------------------------------------------------------------

@pytest.fixture(scope="module")
def demo_build(tmp_path_factory):
    return build_demo(tmp_path_factory.mktemp("data"), progress=None)


def _truth_ecef_by_pyproj() -> np.ndarray:
    """Scene frame -> ECEF with pyproj directly: E, N = offset + x, y on EPSG:27700; z + 12 m
    an OSGB36 ellipsoidal height; then OSGB36 geographic 3-D -> WGS 84 geocentric."""
    local = np.array([v.xyz for v in scene.VALIDATION_POINTS])
    osgb = pyproj.CRS("EPSG:27700")
    lon, lat = pyproj.Transformer.from_crs(osgb, "EPSG:4277", always_xy=True).transform(
        local[:, 0] + 545400.0, local[:, 1] + 258100.0)
    x, y, z = pyproj.Transformer.from_crs(pyproj.CRS("EPSG:4277").to_3d(), "EPSG:4978",
                                          always_xy=True).transform(lon, lat, local[:, 2] + 12.0)
    return np.stack([x, y, z], -1)


def test_tileset_holds_the_markers_at_the_truth(demo_build):
    from gsgeo.tiles.reader import read_tileset

    s = read_tileset(demo_build.tileset / "tileset.json")
    assert s.count == demo_build.splats
    truth = _truth_ecef_by_pyproj()
    rgb = 0.5 + SH_C0 * s.colors
    for vp, t in zip(scene.VALIDATION_POINTS, truth, strict=True):
        d = np.linalg.norm(s.positions - t, axis=1)
        i = int(np.argmin(d))
        assert d[i] < 0.003, (vp.id, d[i])       # SPZ keeps positions to 0.24 mm
        np.testing.assert_allclose(rgb[i], demo_splats.MARKER_RGB, atol=0.02)


def test_check_points_are_what_gsgeo_reports_at_the_truth(demo_build):
    import csv

    rows = list(csv.DictReader(demo_build.checkpoints_csv.open(encoding="utf-8")))
    assert [r["point_id"] for r in rows] == [v.id for v in scene.VALIDATION_POINTS]
    truth = _truth_ecef_by_pyproj()
    lon, lat, h = pyproj.Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True).transform(
        truth[:, 0], truth[:, 1], truth[:, 2])
    for r, vp, hh in zip(rows, scene.VALIDATION_POINTS, h, strict=True):
        # E, N: the offset plus the scene coordinates (the datum link is undone exactly)
        assert float(r["easting"]) == pytest.approx(545400.0 + vp.xyz[0], abs=1e-3)
        assert float(r["northing"]) == pytest.approx(258100.0 + vp.xyz[1], abs=1e-3)
        # H: WGS 84 ellipsoidal height of the truth, as gsgeo reports without --vertical
        assert float(r["height"]) == pytest.approx(hh, abs=1e-3)
    assert place.CRS == "EPSG:27700"


def test_build_is_reused_and_rebuilt(demo_build, tmp_path):
    again = build_demo(demo_build.data_dir, progress=None)
    assert not again.built and again.splats == demo_build.splats
    # a truth.json from another version forces a rebuild
    p = paths(tmp_path)
    p["truth"].parent.mkdir(parents=True)
    p["truth"].write_text('{"version": -1}')
    fresh = build_demo(tmp_path, progress=None)
    assert fresh.built
    assert (p["scene"] / "tileset.json").is_file()
