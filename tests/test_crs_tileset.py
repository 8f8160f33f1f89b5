"""The 3D Tiles transform chain on the real white-sculpture tileset and on hand-made tilesets."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from gsgeo.crs.frames import ecef_to_geodetic, enu_rotation, geodetic_to_ecef
from gsgeo.crs.modelmatrix import column_major
from gsgeo.errors import InputError
from gsgeo.tiles.tileset import Y_UP_TO_Z_UP, Tileset, read_content

# From ../shared/data/README.md
ORIGIN_LON, ORIGIN_LAT = -83.02341, 40.01609
ORIGIN_ECEF = np.array([594147.335, -4855341.260, 4079353.987])


def test_root_frame_origin_and_axes(white_sculpture):
    ts = Tileset(white_sculpture)
    m = ts.root_transform
    np.testing.assert_allclose(m[:3, 3], ORIGIN_ECEF, atol=1e-3)
    lon, lat, h = ecef_to_geodetic(m[:3, 3])
    assert float(lon) == pytest.approx(ORIGIN_LON, abs=1e-7)
    assert float(lat) == pytest.approx(ORIGIN_LAT, abs=1e-7)
    assert abs(float(h)) < 1e-3
    # columns of the root transform are the local east, north, up axes (8 significant digits)
    np.testing.assert_allclose(m[:3, :3], enu_rotation(ORIGIN_LON, ORIGIN_LAT).T, atol=1e-7)
    # a point 100 m up the frame's z axis is 100 m above the ellipsoid
    assert float(ecef_to_geodetic(ts.to_ecef([0, 0, 100.0]))[2]) == pytest.approx(100.0, abs=1e-3)


def test_tiles_and_content_chain(white_sculpture):
    ts = Tileset(white_sculpture)
    tiles = ts.tiles()
    assert len(tiles) == 17 and ts.version == "1.1"
    assert all(np.array_equal(t.transform, ts.root_transform) for t in tiles)  # no child transforms
    c = read_content(white_sculpture / tiles[0].content_uri)
    assert c.count == 119332 and c.rtc_center is None
    # node 0's Z-up -> Y-up matrix cancels CesiumJS's Y-up -> Z-up (README)
    np.testing.assert_allclose(Y_UP_TO_Z_UP @ c.node_matrix, np.eye(4), atol=1e-12)
    assert sum(read_content(white_sculpture / t.content_uri).count for t in tiles[1:9]) > 0


def test_splat_bounding_box_in_lat_lon_h(white_sculpture):
    ts = Tileset(white_sculpture)
    corners = ts.content_bounds_ecef()
    b = ts.geodetic_bounds(corners)
    # heights 128..145 m per README (the extreme splats reach 126..150 m)
    assert 125 < b["h"][0] < 129 and 145 < b["h"][1] < 151
    # a ~107 m x 104 m footprint around the origin
    dlon = (b["lon"][1] - b["lon"][0]) * 111320 * np.cos(np.radians(ORIGIN_LAT))
    dlat = (b["lat"][1] - b["lat"][0]) * 111000
    assert 100 < dlon < 115 and 98 < dlat < 112
    assert b["lon"][0] < ORIGIN_LON < b["lon"][1] and b["lat"][0] < ORIGIN_LAT < b["lat"][1]
    # every content box lies inside the root tile's bounding box (tileset frame, 1 cm slack)
    local = ts.from_ecef(corners)
    box = np.asarray(ts.root.bounding_volume["box"])
    half = np.abs(box[3:].reshape(3, 3)).sum(axis=0)
    assert np.all(np.abs(local - box[:3]) <= half + 0.01)
    rb = ts.geodetic_bounds(ts.bounding_box_corners_ecef())
    assert rb["h"][0] <= b["h"][0] + 0.01 and rb["h"][1] >= b["h"][1] - 0.01


def test_local_ecef_round_trip(white_sculpture, rng):
    ts = Tileset(white_sculpture)
    p = rng.uniform(-60, 60, (100, 3))
    np.testing.assert_allclose(ts.from_ecef(ts.to_ecef(p)), p, atol=1e-8)
    d = rng.normal(size=(100, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_allclose(ts.directions_from_ecef(ts.directions_to_ecef(d)), d, atol=1e-12)


def _glb(gltf: dict) -> bytes:
    js = json.dumps(gltf).encode()
    js += b" " * (-len(js) % 4)
    return struct.pack("<4sII", b"glTF", 2, 20 + len(js)) + struct.pack("<II", len(js), 0x4E4F534A) + js


def _b3dm(glb: bytes, feature: dict) -> bytes:
    ft = json.dumps(feature).encode()
    ft += b" " * (-(28 + len(ft)) % 8)
    total = 28 + len(ft) + len(glb)
    return struct.pack("<4sIIIIII", b"b3dm", 1, total, len(ft), 0, 0, 0) + ft + glb


def _mesh_gltf(node: dict, **extra) -> dict:
    return {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
            "nodes": [node], "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
            "accessors": [{"componentType": 5126, "count": 1, "type": "VEC3",
                           "min": [1.0, 2.0, 3.0], "max": [1.0, 2.0, 3.0]}], **extra}


def test_nested_transforms_rtc_and_gltf_up_axis(tmp_path):
    """3D Tiles 1.0: child transform, b3dm RTC_CENTER, CESIUM_RTC, node TRS, glTF y-up."""
    origin = geodetic_to_ecef(9.5, 50.0, 100.0)
    root = np.eye(4)
    root[:3, :3] = enu_rotation(9.5, 50.0).T
    root[:3, 3] = origin
    child = np.eye(4)
    child[:3, 3] = [10.0, 0.0, 0.0]
    # node: translation (0, 0, 5) and a 90-degree rotation about glTF's y axis
    q = [0.0, np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)]
    node = {"mesh": 0, "translation": [0.0, 0.0, 5.0], "rotation": q}
    (tmp_path / "a.b3dm").write_bytes(_b3dm(_glb(_mesh_gltf(node)), {"RTC_CENTER": [0.0, 20.0, 0.0],
                                                                        "BATCH_LENGTH": 0}))
    (tmp_path / "b.glb").write_bytes(_glb(_mesh_gltf({"mesh": 0},
                                                     extensions={"CESIUM_RTC": {"center": [1.0, 1.0, 1.0]}})))
    doc = {"asset": {"version": "1.0"}, "geometricError": 1,
           "root": {"transform": column_major(root), "boundingVolume": {"sphere": [0, 0, 0, 100]},
                    "geometricError": 1, "content": {"uri": "b.glb"},
                    "children": [{"transform": column_major(child), "geometricError": 0,
                                  "boundingVolume": {"sphere": [0, 0, 0, 50]},
                                  "content": {"uri": "a.b3dm"}}]}}
    (tmp_path / "tileset.json").write_text(json.dumps(doc))
    ts = Tileset(tmp_path)
    kid = ts.root.children[0]
    np.testing.assert_allclose(kid.transform, root @ child)
    c = read_content(tmp_path / "a.b3dm")
    assert c.rtc_center.tolist() == [0.0, 20.0, 0.0]
    # by hand: p = (1, 2, 3) -> rot_y(90): (3, 2, -1) -> + (0, 0, 5): (3, 2, 4)
    # -> y-up to z-up (x, -z, y): (3, -4, 2) -> + RTC (0, 20, 0): (3, 16, 2) -> child: (13, 16, 2)
    p = (ts.content_matrix(kid, c) @ [1.0, 2.0, 3.0, 1.0])[:3]
    np.testing.assert_allclose(ts.from_ecef(p), [13.0, 16.0, 2.0], atol=1e-8)
    enu = (p - origin) @ enu_rotation(9.5, 50.0).T
    np.testing.assert_allclose(enu, [13.0, 16.0, 2.0], atol=1e-8)
    cb = read_content(tmp_path / "b.glb")
    pb = (ts.content_matrix(ts.root, cb) @ [1.0, 2.0, 3.0, 1.0])[:3]
    np.testing.assert_allclose(ts.from_ecef(pb), [2.0, -2.0, 3.0], atol=1e-8)  # (1,-3,2)+(1,1,1)
    doc["asset"]["gltfUpAxis"] = "Z"
    (tmp_path / "tileset.json").write_text(json.dumps(doc))
    pz = (Tileset(tmp_path).content_matrix(ts.root, cb) @ [1.0, 2.0, 3.0, 1.0])[:3]
    np.testing.assert_allclose(ts.from_ecef(pz), [2.0, 3.0, 4.0], atol=1e-8)


def test_bad_tilesets(tmp_path):
    with pytest.raises(InputError, match="no such tileset"):
        Tileset(tmp_path / "missing.json")
    (tmp_path / "tileset.json").write_text("{}")
    with pytest.raises(InputError, match="no 'root'"):
        Tileset(tmp_path)
