"""The measuring view at a place (web/js/main.js: ?lon=&lat=), as the QGIS plugin's map tool
opens it (tests/test_qgis_plugin.py checks the URL the tool makes): the viewer's camera looks at
lon, lat; a lon/lat that is not a place is said, and the viewer still starts."""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.e2e

LOOK_AT_JS = """() => {
  const C = gsgeo.Cesium, cam = gsgeo.viewer.camera;
  const target = C.Cartesian3.add(cam.positionWC,
      C.Cartesian3.multiplyByScalar(cam.directionWC, 40, new C.Cartesian3()), new C.Cartesian3());
  const g = C.Cartographic.fromCartesian(target);
  return [C.Math.toDegrees(g.longitude), C.Math.toDegrees(g.latitude)];
}"""


def test_viewer_looks_at_the_place_in_the_url(browser, box_server):
    """The URL the map tool opens: the viewer's camera looks at lon, lat (40 m away); a
    lon/lat that is not a place is said, and the viewer still starts. (The session's browser
    and box scene, tests/e2e/shared.py.)"""
    from tests.e2e.workplace import ORIGIN, SCENE

    base = box_server
    lat, lon = ORIGIN[0] + 1e-4, ORIGIN[1] - 2e-4
    page = browser.new_page(viewport={"width": 800, "height": 600})
    try:
        page.goto(f"{base}/?scene={SCENE}&lon={lon}&lat={lat}")
        page.wait_for_function("window.gsgeo && window.gsgeo.ready === true", timeout=90_000)
        got = page.evaluate(LOOK_AT_JS)
        assert abs(got[0] - lon) < 1e-6 and abs(got[1] - lat) < 1e-6, got
        page.goto(f"{base}/?scene={SCENE}&lon=east&lat={lat}")
        page.wait_for_function("window.gsgeo && window.gsgeo.ready === true", timeout=90_000)
        assert "is not a place" in page.inner_text("#messages")
    finally:
        page.close()
