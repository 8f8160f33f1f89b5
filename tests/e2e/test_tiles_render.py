"""CesiumJS 1.145 in headless Chromium renders gsgeo tilesets as splats (not 1-pixel points)."""

from __future__ import annotations

import numpy as np
import pytest

from gsgeo.tiles.build import build_tileset
from gsgeo.tiles.georef import Georeference
from gsgeo.tiles.ply import write_ply
from gsgeo.tiles.splats import SH_C0, Splats
from tests.conftest import REPO
from tests.e2e.tiles_page import render

pytestmark = pytest.mark.e2e
ARTIFACTS = REPO / "artifacts"
REAL_VIEWPORT = (320, 240)


def _lit(img: np.ndarray) -> np.ndarray:
    return img.max(axis=2) > 24


def _coloured_blobs(n: int, rng) -> Splats:
    """n round splats of 0.4 m sigma in a 20 m cube, each pure red, green or blue."""
    pos = rng.uniform(-10, 10, (n, 3))
    rgb = np.eye(3)[rng.integers(0, 3, n)] * 0.9 + 0.05
    return Splats(pos, np.full((n, 3), np.log(0.4), np.float32),
                  np.tile(np.array([0, 0, 0, 1], np.float32), (n, 1)),
                  np.full(n, 4.0, np.float32), ((rgb - 0.5) / SH_C0).astype(np.float32),
                  np.zeros((n, 0, 3), np.float32))


def test_synthetic_scene_renders_as_splats(browser, tmp_path, rng):
    n = 400
    write_ply(tmp_path / "blobs.ply", _coloured_blobs(n, rng))
    site = tmp_path / "site"
    build_tileset(tmp_path / "blobs.ply", site / "ts", Georeference(
        "origin", origin=(40.0, -83.0, 250.0)), max_splats=1000, progress=None)
    img, info, errors = render(browser, site, "ts/tileset.json", ARTIFACTS / "tiles_blobs.png")
    assert info["drawn"] == n, info
    lit = _lit(img)
    # 1-pixel points would light at most n pixels; splats of 0.4 m light far more
    assert lit.sum() > 25 * n, (lit.sum(), info, errors)
    # and they keep their colours: strongly red, green and blue areas all present
    for c in range(3):
        others = [o for o in range(3) if o != c]
        strong = (img[..., c] > 120) & (img[..., others].max(axis=2) < 90)
        assert strong.sum() > 2 * n, (c, strong.sum())


def test_real_scene_rebuilt_renders(browser, tmp_path, white_sculpture, white_sculpture_rebuilt):
    """The shared real tileset -> PLY -> gsgeo tiles -> renders like the original: from the
    same camera, with every splat of each drawn and sorted, the two pictures cover the same
    pixels in the same colours."""
    rebuilt, summary = white_sculpture_rebuilt
    assert summary.splats_written == 690_573
    site = tmp_path / "site"
    site.mkdir()
    (site / "orig").symlink_to(white_sculpture, target_is_directory=True)
    (site / "ours").symlink_to(rebuilt, target_is_directory=True)
    # a small viewport: SwiftShader's time per frame grows with the pixels splats cover
    size = REAL_VIEWPORT
    img_o, info_o, errors_o = render(browser, site, "orig/tileset.json",
                                     ARTIFACTS / "tiles_real_original.png", size=size)
    img_n, info, errors = render(browser, site, "ours/tileset.json", ARTIFACTS / "tiles_real_gsgeo.png",
                                 size=size, camera_url="orig/tileset.json")
    assert errors_o == [] and errors == [], (errors_o, errors)
    # every splat of each tileset is in the picture
    assert info_o["drawn"] == info_o["features"] == 690_573, info_o
    assert info["drawn"] == info["features"] == 690_573, info
    lit_o, lit_n = _lit(img_o), _lit(img_n)
    pixels = size[0] * size[1]
    assert lit_o.sum() > 0.1 * pixels and lit_n.sum() > 0.1 * pixels, (lit_o.sum(), lit_n.sum())
    overlap = (lit_o & lit_n).sum() / (lit_o | lit_n).sum()
    assert overlap > 0.95, overlap
    both = lit_o & lit_n
    diff = np.abs(img_o.astype(int) - img_n.astype(int)).max(axis=2)[both]
    assert np.median(diff) <= 10 and np.percentile(diff, 90) <= 40, np.percentile(diff, [50, 90])
