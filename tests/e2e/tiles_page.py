"""A minimal CesiumJS page and loopback HTTP server to render a 3D Tiles splat tileset.

No Cesium ion, no imagery, no globe: the page shows only the tileset on black, so pixels
that are not black are splats. Used by tests/e2e/test_tiles_render.py and benchmarks.
"""

from __future__ import annotations

import functools
import http.server
import threading
import time
from contextlib import contextmanager
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
CESIUM_BUILD = REPO / "web" / "node_modules" / "cesium" / "Build" / "Cesium"
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--use-angle=swiftshader",
                 "--enable-unsafe-swiftshader", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run"]

PAGE = """<!doctype html>
<html><head><meta charset="utf-8">
<script src="/cesium/Cesium.js"></script>
<link href="/cesium/Widgets/widgets.css" rel="stylesheet">
<style>html,body,#v{margin:0;width:100%;height:100%;overflow:hidden;background:#000}
.cesium-viewer-bottom{display:none}</style>
</head><body><div id="v"></div><script>
Cesium.Ion.defaultAccessToken = "";
const viewer = new Cesium.Viewer("v", {
  baseLayer: false, geocoder: false, baseLayerPicker: false, timeline: false,
  animation: false, homeButton: false, sceneModePicker: false, navigationHelpButton: false,
  fullscreenButton: false, infoBox: false, selectionIndicator: false,
  terrainProvider: new Cesium.EllipsoidTerrainProvider(),
});
const scene = viewer.scene;
scene.globe.show = false;
scene.skyBox.show = false;
scene.skyAtmosphere.show = false;
scene.sun.show = false;
scene.moon.show = false;
scene.backgroundColor = Cesium.Color.BLACK;
window.state = {loaded: false, error: null};
// loaded, and Cesium's splat primitive has built its textures and sorted the splats
window.splatsStable = () => {
  const t = window.state.tileset, p = t && t.gaussianSplatPrimitive;
  return window.state.loaded && !!p && p.isStable;
};
(async () => {
  try {
    const tileset = await Cesium.Cesium3DTileset.fromUrl("TILESET", {maximumScreenSpaceError: 16});
    scene.primitives.add(tileset);
    let bs = tileset.boundingSphere;
    if ("CAMERA" !== "") {  // place the camera by another tileset's bounding sphere
      const other = await Cesium.Cesium3DTileset.fromUrl("CAMERA");
      bs = other.boundingSphere;
      other.destroy();
    }
    viewer.camera.viewBoundingSphere(bs, new Cesium.HeadingPitchRange(0.3, -0.6, bs.radius * 2.2));
    viewer.camera.lookAtTransform(Cesium.Matrix4.IDENTITY);
    tileset.allTilesLoaded.addEventListener(() => { window.state.loaded = true; });
    window.state.tileset = tileset;
  } catch (e) { window.state.error = String(e); }
})();
</script></body></html>
"""


class _Handler(http.server.SimpleHTTPRequestHandler):
    def translate_path(self, path: str) -> str:
        clean = path.split("?", 1)[0].split("#", 1)[0]
        if clean.startswith("/cesium/"):
            return str(CESIUM_BUILD / clean[len("/cesium/"):])
        return super().translate_path(path)

    def log_message(self, *args) -> None:  # keep test output clean
        pass


@contextmanager
def serve(site: Path):
    """Serve `site` (and Cesium under /cesium/) on 127.0.0.1; yields the base URL."""
    handler = functools.partial(_Handler, directory=str(site))
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    th = threading.Thread(target=srv.serve_forever, daemon=True)
    th.start()
    try:
        yield f"http://127.0.0.1:{srv.server_address[1]}"
    finally:
        srv.shutdown()
        srv.server_close()


def write_page(site: Path, tileset_url: str, camera_url: str = "") -> Path:
    p = site / "index.html"
    p.write_text(PAGE.replace("TILESET", tileset_url).replace("CAMERA", camera_url))
    return p


def render(site: Path, tileset_url: str, png: Path, *, size=(800, 600),
           timeout_s: float = 180.0, settle_ms: int = 2000, camera_url: str = ""):
    """Render the tileset in headless Chromium; save a screenshot; return it as an RGB array.

    The camera looks at the bounding sphere of the tileset (or of `camera_url`'s tileset)."""
    from playwright.sync_api import sync_playwright

    write_page(site, tileset_url, camera_url)
    with serve(site) as base, sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": size[0], "height": size[1]})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"{base}/index.html")
            page.wait_for_function("window.state && (window.state.error || window.splatsStable())",
                                   timeout=timeout_s * 1000, polling=500)
            err = page.evaluate("window.state.error")
            if err:
                raise RuntimeError(f"Cesium could not load the tileset: {err}")
            png.parent.mkdir(parents=True, exist_ok=True)
            # splats are sorted by a web worker after loading: wait until the picture settles
            # (SwiftShader can take seconds a frame: two equal screenshots alone may be one
            # frame still being drawn, so the tileset must also report every tile loaded and
            # the splat primitive stable, three times in a row)
            t_end = time.monotonic() + timeout_s
            last, calm = -1, 0
            while True:
                page.wait_for_timeout(settle_ms)
                ready = page.evaluate(
                    "window.splatsStable() && window.state.tileset.tilesLoaded")
                page.screenshot(path=str(png), timeout=180_000)
                lit = int((_read_png(png).max(axis=2) > 24).sum())
                calm = calm + 1 if ready and last > 0 and abs(lit - last) <= 0.01 * last else 0
                if calm >= 2 or time.monotonic() > t_end:
                    break
                last = lit
            info = page.evaluate("""() => { const t = window.state.tileset;
                return {selected: t.statistics.selected,
                        features: t.statistics.numberOfPointsSelected,
                        gs: t.statistics.numberOfGaussianSplatsSelected || null}; }""")
        finally:
            browser.close()
    return _read_png(png), info, errors


def _read_png(png: Path):
    import matplotlib.image as mpimg
    import numpy as np
    return (mpimg.imread(str(png))[..., :3] * 255).astype(np.uint8)
