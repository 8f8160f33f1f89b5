"""A minimal CesiumJS page and loopback HTTP server to render a 3D Tiles splat tileset.

No Cesium ion, no imagery, no globe: the page shows only the tileset on black, so pixels
that are not black are splats. Used by tests/e2e/test_tiles_render.py; the workplace tests
take ALL_SPLATS_DRAWN_JS to know when a screenshot shows the whole scene.
"""

from __future__ import annotations

import functools
import http.server
import threading
from contextlib import contextmanager
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
CESIUM_BUILD = REPO / "web" / "node_modules" / "cesium" / "Build" / "Cesium"

#: JavaScript predicate on a Cesium3DTileset: its Gaussian splat primitive holds one snapshot
#: of every selected splat, sorted and ready to draw. CesiumJS 1.145 (pinned) has no public
#: signal for it, so this reads the primitive's snapshot fields (revisit on a Cesium upgrade).
#: In gsgeo's viewer also its renderer settled: the splats drawn, not waiting (still.js holds
#: them back in a software renderer while the globe loads its tiles for a new view).
ALL_SPLATS_DRAWN_JS = """(t) => { const p = t && t.gaussianSplatPrimitive;
  const n = t ? t.statistics.numberOfPointsSelected : 0;
  const r = window.gsgeo && window.gsgeo.renderer;
  return !!p && t.show && t.tilesLoaded && n > 0 && p._numSplats === n &&
    !p._pendingSnapshot && !p._needsSnapshotRebuild && !!p._drawCommand && (!r || r.settled()); }"""

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
window.state = {loaded: false, done: false, error: null, drawn: 0};
// CesiumJS 1.145 (pinned) has no public signal that the splat primitive draws every selected
// splat: its isStable is true while it still draws an older snapshot of a few tiles, and it
// waits dozens of frames before it rebuilds (seconds each in SwiftShader). So the tileset
// loads hidden (preloadWhenHidden), is shown once every tile is in, and the picture is done
// when the frame just drawn holds one snapshot of all selected splats, sorted for this camera.
const allSplatsDrawn = () => (ALL_SPLATS_DRAWN)(window.state.tileset);
scene.postRender.addEventListener(() => {
  if (window.state.done || !allSplatsDrawn()) return;
  window.state.drawn = window.state.tileset.gaussianSplatPrimitive._numSplats;
  window.state.done = true;
  // nothing changes any more: stop drawing, so that the screenshot does not wait for
  // further frames of hundreds of thousands of splats in software
  viewer.useDefaultRenderLoop = false;
});
(async () => {
  try {
    const tileset = await Cesium.Cesium3DTileset.fromUrl("TILESET", {
      maximumScreenSpaceError: 16, show: false, preloadWhenHidden: true});
    scene.primitives.add(tileset);
    let bs = tileset.boundingSphere;
    if ("CAMERA" !== "") {  // place the camera by another tileset's bounding sphere
      const other = await Cesium.Cesium3DTileset.fromUrl("CAMERA");
      bs = other.boundingSphere;
      other.destroy();
    }
    viewer.camera.viewBoundingSphere(bs, new Cesium.HeadingPitchRange(0.3, -0.6, bs.radius * 2.2));
    viewer.camera.lookAtTransform(Cesium.Matrix4.IDENTITY);
    tileset.allTilesLoaded.addEventListener(() => {
      window.state.loaded = true;
      tileset.show = true;
    });
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
    p.write_text(PAGE.replace("ALL_SPLATS_DRAWN", ALL_SPLATS_DRAWN_JS)
                 .replace("TILESET", tileset_url).replace("CAMERA", camera_url))
    return p


def render(browser, site: Path, tileset_url: str, png: Path, *, size=(800, 600),
           timeout_s: float = 180.0, camera_url: str = ""):
    """Render the tileset in headless Chromium; save a screenshot; return it as an RGB array,
    a dict of tileset statistics and the page errors.

    The camera looks at the bounding sphere of the tileset (or of `camera_url`'s tileset). The
    screenshot is the one frame in which every selected splat was drawn, sorted for this
    camera (`info["drawn"]` splats); Cesium draws nothing after it."""
    write_page(site, tileset_url, camera_url)
    with serve(site) as base:
        page = browser.new_page(viewport={"width": size[0], "height": size[1]})
        try:
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"{base}/index.html")
            page.wait_for_function("window.state && (window.state.error || window.state.done)",
                                   timeout=timeout_s * 1000, polling=250)
            err = page.evaluate("window.state.error")
            if err:
                raise RuntimeError(f"Cesium could not load the tileset: {err}")
            png.parent.mkdir(parents=True, exist_ok=True)
            # the GPU process may still be drawing that last frame: the screenshot waits for it
            page.screenshot(path=str(png), timeout=timeout_s * 1000)
            info = page.evaluate("""() => { const t = window.state.tileset;
                return {selected: t.statistics.selected,
                        features: t.statistics.numberOfPointsSelected,
                        drawn: window.state.drawn}; }""")
        finally:
            page.close()
    return _read_png(png), info, errors


def _read_png(png: Path):
    import matplotlib.image as mpimg
    import numpy as np
    return (mpimg.imread(str(png))[..., :3] * 255).astype(np.uint8)
