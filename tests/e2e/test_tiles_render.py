"""CesiumJS 1.145 in headless Chromium renders gsgeo tilesets as splats (not 1-pixel points)."""

from __future__ import annotations

import importlib.util
import shutil

import numpy as np
import pytest

from gsgeo.tiles.build import build_tileset
from gsgeo.tiles.georef import Georeference
from gsgeo.tiles.ply import write_ply
from gsgeo.tiles.splats import SH_C0, Splats
from tests.conftest import REPO
from tests.e2e.tiles_page import CESIUM_BUILD, CHROMIUM, render

pytestmark = pytest.mark.e2e
ARTIFACTS = REPO / "artifacts"


@pytest.fixture(scope="module", autouse=True)
def _browser_available():
    if not CHROMIUM.exists():
        pytest.skip("/usr/bin/chromium is not installed")
    if importlib.util.find_spec("playwright") is None:
        pytest.skip("Playwright for Python is not installed")
    if not (CESIUM_BUILD / "Cesium.js").is_file():
        pytest.skip("cesium is not installed in web/node_modules (run npm ci in web/)")


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


def test_synthetic_scene_renders_as_splats(tmp_path, rng):
    n = 400
    write_ply(tmp_path / "blobs.ply", _coloured_blobs(n, rng))
    site = tmp_path / "site"
    build_tileset(tmp_path / "blobs.ply", site / "ts", Georeference(
        "origin", origin=(40.0, -83.0, 250.0)), max_splats=1000, progress=None)
    img, info, errors = render(site, "ts/tileset.json", ARTIFACTS / "tiles_blobs.png")
    lit = _lit(img)
    # 1-pixel points would light at most n pixels; splats of 0.4 m light far more
    assert lit.sum() > 25 * n, (lit.sum(), info, errors)
    # and they keep their colours: strongly red, green and blue areas all present
    for c in range(3):
        others = [o for o in range(3) if o != c]
        strong = (img[..., c] > 120) & (img[..., others].max(axis=2) < 90)
        assert strong.sum() > 2 * n, (c, strong.sum())


def test_real_scene_rebuilt_renders(tmp_path, white_sculpture):
    """The shared real tileset -> PLY -> gsgeo tiles -> renders like the original."""
    from tests.tiles_real import rebuild_ply_and_tiles
    site = tmp_path / "site"
    shutil.copytree(white_sculpture, site / "orig")
    rebuilt = rebuild_ply_and_tiles(white_sculpture, tmp_path, site / "ours")
    img_o, _, _ = render(site, "orig/tileset.json", ARTIFACTS / "tiles_real_original.png")
    # the same camera (from the original's bounding sphere) for ours
    img_n, info, errors = render(site, "ours/tileset.json", ARTIFACTS / "tiles_real_gsgeo.png",
                                 camera_url="orig/tileset.json")
    lit_o, lit_n = _lit(img_o), _lit(img_n)
    # The original's own tile tree does not always come out whole in SwiftShader under this
    # camera (seen: its ground tiles missing in some runs), so it is the reference for where
    # splats are, not for how many: ours must render as splats and cover what it shows.
    assert lit_o.sum() > 5_000
    assert lit_n.sum() > 20_000, (lit_n.sum(), info, errors)
    assert lit_n.sum() > 0.8 * lit_o.sum(), (lit_n.sum(), lit_o.sum(), info, errors)
    covered = (lit_o & lit_n).sum() / lit_o.sum()
    assert covered > 0.7, covered
    assert rebuilt.splats_written == 690_573
