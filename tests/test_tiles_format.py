"""Tileset/glTF structure (docs/architecture.md, 'CesiumJS 1.145 and 3D Tiles with splats'),
LOD rules, atomic output, PLY layouts and the `gsgeo tiles` command line."""

from __future__ import annotations

import gc
import json
import struct
from pathlib import Path

import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from gsgeo.cli import main
from gsgeo.errors import InputError
from gsgeo.tiles import build as build_mod
from gsgeo.tiles import lod, spz
from gsgeo.tiles.build import build_tileset
from gsgeo.tiles.georef import Georeference
from gsgeo.tiles.gltf import parse_glb
from gsgeo.tiles.ply import read_layout, read_ply, write_ply
from gsgeo.tiles.reader import iter_tileset, read_tileset
from tests.tiles_helpers import random_splats

ORIGIN = Georeference("origin", origin=(40.0, -83.0, 200.0))
EXTS = ["KHR_gaussian_splatting", "KHR_gaussian_splatting_compression_spz_2"]


def _glb_json(path):
    data = path.read_bytes()
    jlen = struct.unpack("<I", data[12:16])[0]
    return json.loads(data[20:20 + jlen])


@pytest.fixture
def built(tmp_path, rng):
    s = random_splats(rng, 5000, 3, extent=30.0)
    write_ply(tmp_path / "in.ply", s)
    build_tileset(tmp_path / "in.ply", tmp_path / "out", Georeference("origin",
                  origin=(40.0, -83.0, 200.0)), max_splats=1000, progress=None)
    return s, tmp_path / "out"


def test_tileset_json_follows_cesium_facts(built):
    _, out = built
    doc = json.loads((out / "tileset.json").read_text())
    assert doc["asset"]["version"] == "1.1"
    assert doc["extensionsUsed"] == doc["extensionsRequired"] == ["3DTILES_content_gltf"]
    ext = doc["extensions"]["3DTILES_content_gltf"]
    assert ext["extensionsUsed"] == ext["extensionsRequired"] == EXTS
    root = doc["root"]
    m = np.array(root["transform"]).reshape(4, 4).T
    # root frame = ENU at the scene centre: orthonormal, up = ellipsoid normal there
    assert np.allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-12)
    lat, lon = np.radians(40.0), np.radians(-83.0)
    up = [np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)]
    assert np.allclose(m[:3, 2], up, atol=1e-5)
    assert 6.3e6 < np.linalg.norm(m[:3, 3]) < 6.4e6

    def tiles(t, depth=0):
        yield t, depth
        for c in t.get("children", []):
            assert "transform" not in c          # the georeference sits on the root only
            yield from tiles(c, depth + 1)
    for t, _ in tiles(root):
        assert t["refine"] == "ADD"
        assert (t["geometricError"] > 0) == bool(t.get("children"))
        for c in t.get("children", []):
            assert c["geometricError"] <= t["geometricError"]


def test_glb_layout(built):
    _, out = built
    for path in sorted((out / "tiles").glob("*.glb")):
        g = _glb_json(path)
        assert g["extensionsRequired"] == EXTS
        prim, = g["meshes"][0]["primitives"]
        assert prim["mode"] == 0
        names = set(prim["attributes"])
        assert {"POSITION", "COLOR_0", "KHR_gaussian_splatting:SCALE",
                "KHR_gaussian_splatting:ROTATION"} <= names
        sh = [n for n in names if "SH_DEGREE_" in n]
        assert len(sh) == 15 and "KHR_gaussian_splatting:SH_DEGREE_3_COEF_6" in names
        assert all("bufferView" not in a for a in g["accessors"])
        assert prim["extensions"]["KHR_gaussian_splatting"]["extensions"][
            "KHR_gaussian_splatting_compression_spz_2"]["bufferView"] == 0
        assert g["nodes"][0]["matrix"] == [1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1]
        # POSITION min/max bound the centres exactly as they decode from the SPZ payload
        (blob, _), = parse_glb(path.read_bytes())
        decoded = spz.decode(blob)[0].positions
        pos_acc = g["accessors"][prim["attributes"]["POSITION"]]
        assert pos_acc["min"] == decoded.min(axis=0).tolist()
        assert pos_acc["max"] == decoded.max(axis=0).tolist()


def test_lod_bounds_and_parents_hold_the_most_prominent(built):
    s, out = built
    per_tile = [(t.level, t.splats) for t in iter_tileset(out, frame="content")]
    assert sum(p.count for _, p in per_tile) == s.count
    assert max(p.count for _, p in per_tile) <= 1000
    assert max(level for level, _ in per_tile) >= 1
    # the root tile holds the largest (alpha x area) splats of the scene
    def prominence(p):
        return 1 / (1 + np.exp(-p.opacities)) * np.exp(p.scales.sum(axis=1) * 2 / 3)
    root = [p for level, p in per_tile if level == 0][0]
    rest = np.concatenate([prominence(p) for level, p in per_tile if level > 0])
    assert np.median(prominence(root)) > np.percentile(rest, 90)


def test_parent_subset_of_tied_splats_covers_the_scene():
    """Equal prominence (common after byte quantisation) must not keep a strip of the file."""
    n = 40_000
    rng = np.random.default_rng(3)
    pos = np.c_[np.linspace(0.0, 100.0, n), rng.uniform(0, 100, n), np.zeros(n)]  # x in file order
    root = lod.build_tree(pos, np.full(n, 0.01), np.ones(n, dtype=np.float32), max_splats=10_000)
    counts, _ = np.histogram(pos[root.index, 0], bins=10, range=(0, 100))
    assert counts.min() > 0.8 * counts.mean()


def test_output_directory_has_ordinary_permissions(built):
    _, out = built
    assert out.stat().st_mode & 0o755 == 0o755


def test_tree_with_identical_positions_terminates():
    pos = np.zeros((5000, 3))
    root = lod.build_tree(pos, np.zeros(5000), np.ones(5000), max_splats=1000)
    counts = [n.index.shape[0] for n in root.walk()]
    assert sum(counts) == 5000 and max(counts) <= 1000


def test_existing_output_survives_a_failed_run(tmp_path, rng, monkeypatch):
    s = random_splats(rng, 3000, 0)
    write_ply(tmp_path / "in.ply", s)
    out = tmp_path / "out"
    build_tileset(tmp_path / "in.ply", out, ORIGIN, max_splats=1000, progress=None)
    before = {p.name: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    calls = []

    def boom(*a, **k):
        calls.append(1)
        if len(calls) > 2:
            raise KeyboardInterrupt
        return b"x"
    monkeypatch.setattr(build_mod.gltf, "tile_glb", boom)
    with pytest.raises(KeyboardInterrupt):
        build_tileset(tmp_path / "in.ply", out, ORIGIN, max_splats=1000, overwrite=True,
                      progress=None)
    after = {p.name: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.ply", "out"]  # no temp left


def test_output_not_replaced_without_overwrite(tmp_path, rng):
    write_ply(tmp_path / "in.ply", random_splats(rng, 100, 0))
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "keep.txt").write_text("mine")
    with pytest.raises(InputError, match="--overwrite"):
        build_tileset(tmp_path / "in.ply", tmp_path / "out", ORIGIN, progress=None)
    assert (tmp_path / "out" / "keep.txt").read_text() == "mine"


def _plyfile_write(path, fields, n, rng, text=False):
    arr = np.zeros(n, [(f, "f4") for f in fields])
    for f in fields:
        arr[f] = rng.normal(size=n)
    PlyData([PlyElement.describe(arr, "vertex")], text=text).write(str(path))
    return arr


def test_ply_written_by_plyfile_reads_channel_major_sh(tmp_path, rng):
    fields = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"] + \
        [f"f_rest_{i}" for i in range(24)] + ["opacity", "scale_0", "scale_1", "scale_2",
                                              "rot_0", "rot_1", "rot_2", "rot_3", "extra"]
    for text in (False, True):
        arr = _plyfile_write(tmp_path / "a.ply", fields, 50, rng, text=text)
        s = read_ply(tmp_path / "a.ply")
        assert s.sh_degree == 2
        # coefficient j of green is f_rest_{8 + j}
        np.testing.assert_allclose(s.sh[:, 5, 1], arr["f_rest_13"], rtol=1e-6)
        np.testing.assert_allclose(s.rotations[:, 3], arr["rot_0"], rtol=1e-6)  # w-first
        np.testing.assert_allclose(s.positions[:, 2], arr["z"], rtol=1e-6)


def test_ply_with_rgb_colours(tmp_path, rng):
    n = 20
    dt = [(f, "f4") for f in ["x", "y", "z", "opacity", "scale_0", "scale_1", "scale_2",
                              "rot_0", "rot_1", "rot_2", "rot_3"]] + \
        [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    arr = np.zeros(n, dt)
    arr["rot_0"] = 1
    arr["red"] = 255
    PlyData([PlyElement.describe(arr, "vertex")]).write(str(tmp_path / "c.ply"))
    s = read_ply(tmp_path / "c.ply")
    assert np.allclose(0.5 + 0.28209479177387814 * s.colors[:, 0], 1.0)
    assert np.allclose(0.5 + 0.28209479177387814 * s.colors[:, 1], 0.0)


def test_unknown_layout_names_missing_properties(tmp_path, rng):
    _plyfile_write(tmp_path / "pc.ply", ["x", "y", "z", "opacity"], 5, rng)
    with pytest.raises(InputError, match="scale_0, scale_1, scale_2, rot_0.*f_dc_0"):
        read_layout(tmp_path / "pc.ply")
    _plyfile_write(tmp_path / "sh.ply", ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2",
                                         "f_rest_0", "opacity", "scale_0", "scale_1",
                                         "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"], 5, rng)
    with pytest.raises(InputError, match="1 f_rest"):
        read_layout(tmp_path / "sh.ply")
    (tmp_path / "t.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\n"
                                     b"element vertex 10\nproperty float x\nend_header\n")
    with pytest.raises(InputError, match="lacks"):
        read_layout(tmp_path / "t.ply")


def test_spz_file_input(tmp_path, rng):
    s = random_splats(rng, 2000, 1)
    (tmp_path / "in.spz").write_bytes(spz.encode(s))
    build_tileset(tmp_path / "in.spz", tmp_path / "out", ORIGIN, progress=None)
    assert read_tileset(tmp_path / "out").count == 2000


def test_cli_summary_and_errors(tmp_path, rng, capsys):
    write_ply(tmp_path / "in.ply", random_splats(rng, 2000, 3))
    rc = main(["tiles", str(tmp_path / "in.ply"), "-o", str(tmp_path / "out"),
               "--origin", "40,-83,200", "--heading", "10"])
    cap = capsys.readouterr()
    assert rc == 0
    assert "2,000 written" in cap.out and "lat 39.99" in cap.out and "Z-up" in cap.out
    assert "reading" in cap.err and "writing" in cap.err      # progress bars
    assert gc.isenabled()          # the command pauses the cyclic collector only while it runs
    rc = main(["tiles", str(tmp_path / "in.ply"), "-o", str(tmp_path / "o2")])
    assert rc == 0 and "default origin" in capsys.readouterr().err
    for argv, msg in [
        (["--origin", "40,-83"], "3 comma-separated"),
        (["--origin", "95,0,0"], "latitude"),
        (["--crs", "EPSG:32617"], "--offset"),
        (["--crs", "EPSG:4326", "--offset", "0,0,0"], "not a projected CRS"),
        (["--crs", "EPSG:999999", "--offset", "0,0,0"], "unknown CRS"),
        (["--origin", "1,2,3", "--crs", "EPSG:32617"], "choose one"),
        (["--transform", str(tmp_path / "nope.json")], "cannot read"),
    ]:
        rc = main(["tiles", str(tmp_path / "in.ply"), "-o", str(tmp_path / "o3")] + argv)
        err = capsys.readouterr().err
        assert rc == 2 and msg in err, (argv, err)
    rc = main(["tiles", str(tmp_path / "missing.ply"), "-o", str(tmp_path / "o4")])
    assert rc == 2 and "cannot open" in capsys.readouterr().err
    (tmp_path / "shear.json").write_text(json.dumps([[1, 0.5, 0, 0], [0, 1, 0, 0],
                                                     [0, 0, 1, 0], [0, 0, 0, 1]]))
    rc = main(["tiles", str(tmp_path / "in.ply"), "-o", str(tmp_path / "o5"),
               "--transform", str(tmp_path / "shear.json")])
    assert rc == 2 and "uniform scale" in capsys.readouterr().err


COMPRESSED = Path(__file__).parent / "data" / "splats_1000_sh3.compressed.ply"


def test_compressed_ply_from_splat_transform(tmp_path):
    """tests/data/splats_1000_sh3.compressed.ply was written by @playcanvas/splat-transform
    3.7.0 from random_splats(default_rng(3), 1000, 3, extent=20) saved as an INRIA PLY; it
    must decode to those splats within the compressed format's quantisation."""
    from gsgeo.tiles.splats import quat_to_matrix
    from tests.tiles_helpers import match, rotation_error_deg, sigmoid
    want = random_splats(np.random.default_rng(3), 1000, 3, extent=20)
    got = read_ply(COMPRESSED)
    assert got.count == 1000 and got.sh_degree == 3
    idx = match(want.positions, got.positions)   # splat-transform reorders splats
    assert len(np.unique(idx)) == 1000
    dist = np.linalg.norm(got.positions[idx] - want.positions, axis=1)
    g = got.take(idx)
    # 11/10-bit positions over each 256-splat chunk's box (about 40 m here)
    assert dist.max() < 0.03
    assert np.abs(g.scales - want.scales).max() < 0.005          # 10-11 bits over ~4
    assert np.abs(sigmoid(g.opacities) - sigmoid(want.opacities)).max() <= 0.5 / 255 + 1e-4
    assert np.abs(g.colors - want.colors).max() < 0.02
    assert np.abs(g.sh - want.sh).max() <= 4 / 256 + 1e-5       # 8-bit over [-4, 4]
    assert rotation_error_deg(quat_to_matrix(want.rotations.astype(float)),
                              g.rotations).max() < 0.3
    summary = build_tileset(COMPRESSED, tmp_path / "out", ORIGIN, progress=None)
    assert summary.splats_written == 1000 and summary.sh_degree == 3


def test_broken_compressed_ply_is_named(tmp_path):
    data = COMPRESSED.read_bytes()
    head = data[:data.index(b"end_header\n") + 11]
    (tmp_path / "t.ply").write_bytes(head + b"\0" * 100)
    with pytest.raises(InputError, match="truncated"):
        read_layout(tmp_path / "t.ply")
    bad = head.replace(b"property uint packed_scale\n", b"property uint packed_scal3\n")
    (tmp_path / "b.ply").write_bytes(bad + data[len(head):])
    with pytest.raises(InputError, match="lacks packed_scale"):
        read_layout(tmp_path / "b.ply")


def test_tree_grown_by_worker_processes_equals_the_serial_tree():
    """gsgeo tiles splits the root and grows subtrees in forked workers on shared memory; the
    tree must be the one build_tree gives in one process, node for node (indices and boxes)."""
    from gsgeo.tiles.workers import pool, shared_empty

    rng = np.random.default_rng(1)
    n = 60_000
    pos = (rng.normal(size=(n, 3)) * [50, 50, 5]).astype(np.float32)
    rad, prom = np.full(n, 0.02, np.float32), rng.random(n).astype(np.float32)
    serial = lod.build_tree(pos, rad, prom, max_splats=1000)
    ref = lod.TreeInput.from_splats(pos, rad, prom)

    def fresh():
        w = lod.TreeInput(shared_empty((3, n), np.float32), shared_empty(n, np.float32),
                          shared_empty(n, np.float32), shared_empty(n, np.int32))
        for dst, src in ((w.pos, ref.pos), (w.radius, ref.radius), (w.key, ref.key),
                         (w.perm, ref.perm)):
            dst[:] = src
        return w

    # the root split by the workers into a second set of columns: with a half per worker
    # (they grow the root's children too), and with more workers than halves
    par = {}
    for nproc in (2, 4):
        shared, order = fresh(), shared_empty(n, np.int32)
        second = lod.TreeInput(shared_empty((3, n), np.float32), shared_empty(n, np.float32),
                               shared_empty(n, np.float32), shared_empty(n, np.int32))
        build_mod.WORKER_JOB = build_mod.WorkerJob(None, None, None, shared, 3, 3, 1, second, order)
        try:
            with pool(2) as imap:
                par[nproc], t = build_mod.build_tree(shared, imap, nproc, 1000, None, second,
                                                      order)
        finally:
            build_mod.WORKER_JOB = None
        assert t == 1
    shared = fresh()         # the root split here, in place
    build_mod.WORKER_JOB = build_mod.WorkerJob(None, None, None, shared, 3, 3, 1)
    try:
        with pool(2) as imap:
            par_top, t = build_mod.build_tree(shared, imap, 2, 1000, None)
    finally:
        build_mod.WORKER_JOB = None
    assert t == 0

    def nodes(root):
        return {nd.name: (nd.index.tolist(), nd.lo.tolist(), nd.hi.tolist()) for nd in root.walk()}
    assert max(nd.level for nd in serial.walk()) >= 3
    assert nodes(par[2]) == nodes(serial)
    assert nodes(par[4]) == nodes(serial)
    assert nodes(par_top) == nodes(serial)
