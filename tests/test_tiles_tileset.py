"""The one tileset reader (gsgeo.tiles.tileset): external tilesets, gltfUpAxis and loops, the
same for the transform chain and for the splat reader."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from gsgeo.crs.modelmatrix import column_major
from gsgeo.errors import InputError
from gsgeo.tiles.build import build_tileset
from gsgeo.tiles.georef import Georeference
from gsgeo.tiles.ply import write_ply
from gsgeo.tiles.reader import iter_tileset, read_tileset, splat_count
from gsgeo.tiles.tileset import Y_UP_TO_Z_UP, Tileset
from tests.tiles_helpers import random_splats


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    d = tmp_path_factory.mktemp("ext")
    s = random_splats(np.random.default_rng(3), 300, 0, extent=5.0)
    write_ply(d / "in.ply", s)
    build_tileset(d / "in.ply", d / "out", Georeference("origin", origin=(50.0, 9.5, 100.0)),
                  max_splats=1000, progress=None)
    return d / "out"


def _wrap(built, where, shift=(0.0, 0.0, 0.0), up=None):
    """A tileset whose root holds `built` as an external tileset under a translation."""
    inner = where / "inner"
    shutil.copytree(built, inner)
    if up is not None:
        doc = json.loads((inner / "tileset.json").read_text())
        doc["asset"]["gltfUpAxis"] = up
        (inner / "tileset.json").write_text(json.dumps(doc))
    m = np.eye(4)
    m[:3, 3] = shift
    outer = {"asset": {"version": "1.1"}, "geometricError": 1,
             "root": {"transform": column_major(m), "geometricError": 1,
                      "boundingVolume": {"sphere": [0, 0, 0, 1e7]},
                      "content": {"uri": "inner/tileset.json"}}}
    (where / "tileset.json").write_text(json.dumps(outer))
    return where


def test_the_transform_chain_follows_external_tilesets(built, tmp_path):
    plain = Tileset(built)
    outer = Tileset(_wrap(built, tmp_path, shift=(1.0, 2.0, 3.0)))
    inner_root = outer.root.children[0]
    np.testing.assert_allclose(inner_root.transform[:3, 3], plain.root_transform[:3, 3] + [1, 2, 3])
    assert len(outer.tiles()) == len(plain.tiles()) + 1
    shifted = outer.content_bounds_ecef()
    np.testing.assert_allclose(shifted, plain.content_bounds_ecef() + [1.0, 2.0, 3.0], atol=1e-6)
    # the splat reader walks the same tree
    assert splat_count(tmp_path) == splat_count(built) == 300
    np.testing.assert_allclose(read_tileset(tmp_path).positions,
                               read_tileset(built).positions + [1.0, 2.0, 3.0], atol=1e-6)


def test_the_splat_reader_honours_gltf_up_axis(built, tmp_path):
    _wrap(built, tmp_path, up="Z")
    by_y = {t.uri: t.to_ecef for t in iter_tileset(built)}
    tiles = Tileset(built).tiles()
    got = list(iter_tileset(tmp_path))
    assert len(got) == len(by_y) > 0
    for t in got:
        tile = next(x for x in tiles if t.uri in x.content_uris)
        # "Z": no y-up -> z-up turn between the tile frame and the glTF node matrices
        node = np.linalg.solve(tile.transform, t.to_ecef)
        np.testing.assert_allclose(by_y[t.uri], tile.transform @ Y_UP_TO_Z_UP @ node, atol=1e-6)
        assert not np.allclose(by_y[t.uri], t.to_ecef, atol=1e-3)


def test_a_loop_of_external_tilesets_is_refused_by_name(tmp_path):
    doc = {"asset": {"version": "1.1"}, "geometricError": 1,
           "root": {"geometricError": 1, "boundingVolume": {"sphere": [0, 0, 0, 1]},
                    "content": {"uri": "tileset.json"}}}
    (tmp_path / "tileset.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="loop"):
        Tileset(tmp_path)
    with pytest.raises(InputError, match="loop"):
        read_tileset(tmp_path)
