"""The shared real tileset (../shared/data/white-sculpture) read in ECEF, rebuilt and re-tiled."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gsgeo.crs.ellipsoid import ecef_to_geodetic_closed_form
from gsgeo.tiles.reader import read_tileset, splat_count
from gsgeo.tiles.splats import quat_to_matrix
from tests.tiles_helpers import TOL_COLOR, TOL_LOG_SCALE, TOL_POS_M, TOL_ROT_DEG, rotation_error_deg


def test_real_tileset_reads_in_ecef(white_sculpture):
    assert splat_count(white_sculpture) == 690_573
    s = read_tileset(white_sculpture)
    assert s.count == 690_573 and s.sh_degree == 3
    lon, lat, h = ecef_to_geodetic_closed_form(s.positions[::97])
    # data README: ENU at lon -83.02341, lat 40.01609, content heights about 128-145 m
    assert np.all(np.abs(lon + 83.02341) < 0.002) and np.all(np.abs(lat - 40.01609) < 0.002)
    assert 120 < np.median(h) < 150
    # the root transform puts the frame's origin where the README says
    doc = json.loads((white_sculpture / "tileset.json").read_text())
    np.testing.assert_allclose(doc["root"]["transform"][12:15],
                               [594147.335, -4855341.260, 4079353.987], atol=1e-3)


@pytest.mark.slow
def test_rebuilt_ply_gives_the_same_ecef_splats(white_sculpture, white_sculpture_rebuilt):
    cKDTree = pytest.importorskip("scipy.spatial").cKDTree
    orig = read_tileset(white_sculpture)
    rebuilt, summary = white_sculpture_rebuilt
    assert summary.splats_written == 690_573 and summary.dropped_nonfinite == 0
    ours = read_tileset(rebuilt)
    assert ours.count == orig.count
    centre = orig.positions.mean(axis=0)
    dist, idx = cKDTree(ours.positions - centre).query(orig.positions - centre)
    # exact duplicates exist in real scenes; every splat must still find a partner this close
    assert dist.max() <= TOL_POS_M, dist.max()
    matched = ours.take(idx)
    same = np.abs(matched.colors - orig.colors).max(axis=1) <= TOL_COLOR
    assert same.mean() > 0.999
    assert np.percentile(np.abs(matched.scales - orig.scales).max(axis=1), 99.9) <= TOL_LOG_SCALE
    err = rotation_error_deg(quat_to_matrix(orig.rotations.astype(float)), matched.rotations)
    assert np.percentile(err, 99.9) <= TOL_ROT_DEG
