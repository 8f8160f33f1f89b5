"""The measuring workplace (web/) in a real browser: measure a known point of a scene made by
`gsgeo tiles` from several viewpoints with real mouse clicks and keys, store it in a project,
check it against the ground truth, export it.

The ground truth is independent of the viewer: the marker's ENU coordinates in the generated
PLY, carried to ECEF and to the grid by pyproj. Clicks go to the marker's projected window
position (Cesium.SceneTransforms.worldToWindowCoordinates) through page.mouse.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pyproj
import pytest

from tests.e2e.scene import MARKERS
from tests.e2e.shared import require_browser, serve
from tests.e2e.tiles_page import ALL_SPLATS_DRAWN_JS
from tests.e2e.workplace import (
    AIM_JS,
    ARTIFACTS,
    SCENE,
    VIEWPOINTS,
    enu_to_ecef,
    make_data_dir,
    up_vector,
)

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1280, "height": 720}
GRID = "EPSG:32630"  # WGS 84 / UTM zone 30N: a pure conversion from WGS 84, exact in pyproj
TO_GRID = pyproj.Transformer.from_crs("EPSG:4979", GRID, always_xy=True)
TO_GEO = pyproj.Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    """A box scene of this module's own (tests/e2e/workplace.py's make_data_dir)."""
    require_browser()
    return make_data_dir(tmp_path_factory.mktemp("workplace"))


@pytest.fixture(scope="module")
def server(data_dir):
    yield from serve(data_dir)


@pytest.fixture(scope="module")
def project(server):
    """A project made through the API for the tests that do not test project creation."""
    import httpx

    r = httpx.post(f"{server}/api/projects", json={"name": "E2E", "id": "e2e", "scene": SCENE,
                                                   "crs": GRID, "sigma_px": 1.0})
    assert r.status_code == 201, r.text
    return "e2e"


class Page:
    """A workplace page with console errors collected."""

    def __init__(self, browser, url: str):
        self.errors: list[str] = []
        self.page = browser.new_page(viewport=VIEWPORT, accept_downloads=True)
        self.page.on("console", lambda m: m.type == "error" and self.errors.append(m.text))
        self.page.on("pageerror", lambda e: self.errors.append(f"page error: {e}"))
        self.page.goto(url)
        self.page.wait_for_function("window.gsgeo && window.gsgeo.ready === true", timeout=90_000)
        self.wait_tiles()

    def wait_tiles(self):
        self.page.wait_for_function(
            "window.gsgeo.tileset && window.gsgeo.tilesReady && window.gsgeo.tileset.tilesLoaded",
            timeout=90_000)

    def shot(self, name: str, settle_ms: int = 1000, timeout_s: float = 40.0):
        """Screenshot to artifacts/ once every selected splat is sorted and drawn (SwiftShader
        on a busy machine takes seconds after each camera move). Screenshots are for people
        to look at, not assertions: one that cannot be taken in time is reported and skipped."""
        from playwright.sync_api import TimeoutError as PlaywrightTimeout

        self.page.wait_for_timeout(settle_ms)
        try:
            self.page.wait_for_function(f"({ALL_SPLATS_DRAWN_JS})(window.gsgeo.tileset)",
                                        timeout=timeout_s * 1000, polling=250)
            ARTIFACTS.mkdir(exist_ok=True)
            self.page.screenshot(path=str(ARTIFACTS / f"workplace_{name}.png"), timeout=90_000)
        except PlaywrightTimeout:
            warnings.warn(f"screenshot {name} not taken: the page did not render in time",
                          stacklevel=2)

    def click_world(self, target_rendered, view) -> dict:
        az, el, rng, off = view
        aim = self.page.evaluate(AIM_JS, [list(map(float, target_rendered)), az, el, rng, list(off)])
        assert aim["dist"] < 1e-5, aim  # the projection and the pick ray agree
        w, h = aim["canvas"]
        assert 0 < aim["win"][0] < w and 0 < aim["win"][1] < h, aim
        self.page.mouse.click(aim["x"], aim["y"])
        return aim

    def ray_rows(self) -> int:
        return self.page.locator("#ray-table tbody tr").count()

    def wait_rays(self, n: int):
        self.page.wait_for_function(f"document.querySelectorAll('#ray-table tbody tr').length === {n}")

    def wait_solution(self):
        self.page.wait_for_function(
            "() => /σ0/.test(document.querySelector('#live-solution').textContent)", timeout=30_000)

    def close(self):
        self.page.close()


def _known(marker: str) -> np.ndarray:
    return enu_to_ecef(MARKERS[marker])


def _grid_of(ecef) -> tuple[float, float, float]:
    lon, lat, h = TO_GEO.transform(*ecef)
    e, n = TO_GRID.transform(lon, lat)
    return e, n, h


def _posted(kind: str):
    """Predicate for page.expect_response: the POST that creates a point, line or polygon."""
    return lambda r: r.url.endswith(f"/{kind}") and r.request.method == "POST"


#: The distance (m) of a captured ray from a world point, with what the viewer recorded of it.
RAY_MISS_JS = """([i, target]) => { const r = gsgeo.state.measure.rays[i];
  const w = [0, 1, 2].map((k) => target[k] - r.origin[k]);
  const along = w[0] * r.direction[0] + w[1] * r.direction[1] + w[2] * r.direction[2];
  const miss = Math.hypot(...[0, 1, 2].map((k) => w[k] - along * r.direction[k]));
  const c = gsgeo.viewer.scene.canvas;
  return {miss, pixel: r.pixel, viewport: r.viewport, canvas: [c.clientWidth, c.clientHeight]}; }"""


def _measure(p: Page, target_rendered, views, code: str = "") -> dict:
    p.page.keyboard.press("m")
    p.page.wait_for_selector("#measure-panel:not([hidden])")
    for i, view in enumerate(views):
        aim = p.click_world(target_rendered, view)
        p.wait_rays(i + 1)
        # each ray through the target, where it was clicked (a wrong ray says here how it was
        # taken, not later as a point half a metre off)
        got = p.page.evaluate(RAY_MISS_JS, [i, list(map(float, target_rendered))])
        assert got["miss"] < 1e-3, (i, aim, got)
        if i >= 1:
            p.wait_solution()
    if code:
        p.page.fill("#pt-code", code)
    p.page.keyboard.press("Enter")  # asks for the id (the next P<n>: no check point is near)
    p.page.wait_for_selector("#id-prompt:not([hidden])")
    with p.page.expect_response(_posted("points")) as resp:
        p.page.keyboard.press("Enter")
    assert resp.value.status == 201, resp.value.text()
    p.page.wait_for_selector("#measure-panel", state="hidden")
    return resp.value.json()


def test_create_project_and_measure_known_point(server, browser):
    """Project made in the UI (CRS found by search); 4 rays on the roof corner -> the stored
    point is the marker within 5 mm, and the list shows it in UTM 30N."""
    p = Page(browser, server + "/")
    try:
        p.page.click("#btn-new-project")
        p.page.fill("#pf-name", "Roof survey")
        p.page.fill("#pf-crs-q", "UTM zone 30N")
        p.page.click(f"#pf-crs-results li[data-code='{GRID}']")
        # the vertical datum is searched among vertical CRSs (left empty: ellipsoidal heights)
        p.page.fill("#pf-vertical", "ODN height")
        p.page.wait_for_selector("#pf-vertical-results li[data-code='EPSG:5701']")
        p.page.fill("#pf-vertical", "")
        p.page.fill("#pf-sigma", "0.8")
        p.page.fill("#pf-crs-q", "UTM zone 30N")  # the results list stays for the screenshot
        p.page.wait_for_selector(f"#pf-crs-results li[data-code='{GRID}']")
        p.shot("00_new_project_dialog", settle_ms=300)
        p.page.click("#pf-submit")
        p.page.wait_for_function("document.querySelector('#project-dialog').hidden"
                                 " || document.querySelector('#pf-error').textContent")
        assert p.page.inner_text("#pf-error") == ""
        p.page.wait_for_selector("#project-dialog", state="hidden")
        assert GRID in p.page.inner_text("#project-info")
        assert "0.8" in p.page.inner_text("#project-info")
        p.shot("01_project_created")

        known = _known("roof_ne")
        p.page.keyboard.press("m")
        assert "click the feature to add ray 1" in p.page.inner_text("#status")
        for i, view in enumerate(VIEWPOINTS):
            p.click_world(known, view)
            p.wait_rays(i + 1)
            if i == 0:
                assert "Move the camera to another viewpoint" in p.page.inner_text("#status")
            else:
                p.wait_solution()
            if i == 2:
                p.shot("02_measuring_3_rays")
        # residuals of exact clicks are tiny; every ray has one
        res_px = [float(t) for t in p.page.locator("#ray-table tbody tr td:nth-child(2)").all_inner_texts()]
        assert len(res_px) == 4 and max(res_px) < 0.05, res_px
        # each ray says where it was taken from (the views' azimuth, elevation and range about
        # the marker, which the solution is within millimetres of) and that it was clicked
        stations = p.page.locator("#ray-table tbody tr td.station").all_inner_texts()
        for text, (az, el, rng, _) in zip(stations, VIEWPOINTS, strict=True):
            got = re.fullmatch(r"az ([\d.]+)° el (-?[\d.]+)° ([\d.]+) m", text)
            assert got, text
            assert abs((float(got[1]) - az + 180) % 360 - 180) < 0.2 and abs(float(got[2]) - el) < 0.2, text
            assert abs(float(got[3]) - rng) < 0.02, text
        assert p.page.locator("#ray-table tbody tr td.source").all_inner_texts() == ["click"] * 4
        # the ellipsoid is drawn at its true size: 2.7955 sqrt(eigenvalues of the covariance)
        cov = np.array(p.page.evaluate("gsgeo.state.measure.solution.cov_ecef"))
        expect = 2.7955 * np.sqrt(np.sort(np.linalg.eigvalsh(cov))[::-1]) * 1000  # mm
        note = p.page.inner_text("#ellipsoid-note")
        assert "95 %" in note and "2.7955" in note
        drawn = [float(x) for x in re.search(r"semi-axes ([\d.]+) × ([\d.]+) × ([\d.]+) mm", note).groups()]
        assert np.allclose(drawn, expect, atol=0.051), (drawn, expect)
        p.page.keyboard.press("e")  # 1 sigma
        note = p.page.inner_text("#ellipsoid-note")
        assert "1σ ellipsoid" in note and "19.9 %" in note
        drawn = [float(x) for x in re.search(r"semi-axes ([\d.]+) × ([\d.]+) × ([\d.]+) mm", note).groups()]
        assert np.allclose(drawn, expect / 2.7955, atol=0.051), (drawn, expect)
        p.page.keyboard.press("e")
        p.page.fill("#pt-code", "roof corner")
        p.page.focus("#pt-code")
        p.page.keyboard.press("Enter")  # asks for the id, offering the next free one
        p.page.wait_for_selector("#id-prompt:not([hidden])")
        assert p.page.input_value("#id-prompt-input") == "P1"
        with p.page.expect_response(_posted("points")) as resp:
            p.page.keyboard.press("Enter")
        stored = resp.value.json()
        p.page.wait_for_selector("#points-table tbody tr[data-id='P1']")
        p.shot("03_point_stored")

        got = np.array(stored["result"]["point_ecef"])
        assert np.linalg.norm(got - known) < 0.005, (got - known)
        rec = stored["record"]
        e, n, h = _grid_of(known)
        assert rec["crs"] == GRID and rec["code"] == "roof corner" and rec["n_rays"] == 4
        assert abs(rec["easting"] - e) < 0.005 and abs(rec["northing"] - n) < 0.005
        assert abs(rec["height"] - h) < 0.005

        cells = p.page.locator("#points-table tbody tr[data-id='P1'] td").all_inner_texts()
        assert cells[0] == "P1" and cells[1] == "roof corner"
        assert abs(float(cells[2]) - e) <= 0.0051 and abs(float(cells[3]) - n) <= 0.0051
        assert abs(float(cells[4]) - h) <= 0.0051
        assert cells[7] == "4"
        assert p.errors == []
    finally:
        p.close()


def test_shifted_model_matrix_stores_georeferenced_point(server, browser, project):
    """With the tileset lifted 10 m by its modelMatrix the clicks hit the rendered marker, and
    the stored point is the georeferenced one."""
    p = Page(browser, f"{server}/?project={project}")
    try:
        lift = 10.0
        p.page.evaluate("""(t) => { const C = Cesium;
            gsgeo.tileset.modelMatrix = C.Matrix4.fromTranslation(new C.Cartesian3(t[0], t[1], t[2])); }""",
                        list(up_vector() * lift))
        known = _known("ground_sw")
        rendered = known + up_vector() * lift
        stored = _measure(p, rendered, VIEWPOINTS[:3], code="shifted")
        p.shot("04_shifted_model_matrix")
        got = np.array(stored["result"]["point_ecef"])
        assert np.linalg.norm(got - known) < 0.005, (got - known)
        mm = stored["rays"][0]["model_matrix"]
        assert np.allclose(mm[12:15], up_vector() * lift) and mm[15] == 1.0  # column-major
        e, n, h = _grid_of(known)
        rec = stored["record"]
        assert abs(rec["easting"] - e) < 0.005 and abs(rec["height"] - h) < 0.005
        # the marker of the stored point is drawn where the tileset is now rendered
        drawn = p.page.evaluate(f"""() => gsgeo.draw.overlay.markers('points')
            .find((m) => m.id === '{stored["id"]}').position""")
        assert np.linalg.norm(np.array(drawn) - rendered) < 0.005
        # reopen: exclude ray 1 and bring it back from the point's detail panel
        row = f"#points-table tbody tr[data-id='{stored['id']}']"
        p.page.click("#point-detail button:text('exclude')")
        p.page.wait_for_function(f"document.querySelector(\"{row} td:nth-child(8)\").textContent === '2+1✕'")
        p.page.click("#point-detail button:text('restore')")
        p.page.wait_for_function(f"document.querySelector(\"{row} td:nth-child(8)\").textContent === '3'")
        assert p.errors == []
    finally:
        p.close()


def test_backspace_and_escape(server, browser, project):
    p = Page(browser, f"{server}/?project={project}")
    try:
        before = p.page.locator("#points-table tbody tr[data-id]").count()
        known = _known("roof_c")
        p.page.keyboard.press("m")
        for i, view in enumerate(VIEWPOINTS[:3]):
            p.click_world(known, view)
            p.wait_rays(i + 1)
        p.wait_solution()
        p.page.keyboard.press("Backspace")
        p.wait_rays(2)
        p.wait_solution()
        assert "2 rays" in p.page.inner_text("#status")
        p.page.keyboard.press("Backspace")
        p.wait_rays(1)
        p.page.wait_for_function(
            "() => /at least 2 rays/.test(document.querySelector('#live-solution').textContent)")
        # Enter with one ray stores nothing and says why
        p.page.keyboard.press("Enter")
        p.page.wait_for_function("() => /Nothing stored: P\\d+ has 1 ray/"
                                 ".test(document.querySelector('#messages').textContent)")
        assert p.page.locator("#id-prompt").is_hidden()
        p.shot("05_after_backspace", settle_ms=500)
        p.page.keyboard.press("Escape")
        p.page.wait_for_selector("#measure-panel", state="hidden")
        assert "M (or Measure point) starts a point" in p.page.inner_text("#status")
        # nothing was stored, and Enter outside measuring does not store anything either
        p.page.keyboard.press("Enter")
        p.page.wait_for_timeout(300)
        assert p.page.locator("#points-table tbody tr[data-id]").count() == before
        # the help overlay opens with ? and closes with Escape
        p.page.keyboard.press("?")
        p.page.wait_for_selector("#help:not([hidden])")
        p.shot("06_help", settle_ms=500)
        p.page.keyboard.press("Escape")
        p.page.wait_for_selector("#help", state="hidden")
        assert p.errors == []
    finally:
        p.close()


def test_bad_click_is_flagged_red(server, browser, project):
    """Four exact clicks and one 25 px off: the bad ray gets a large residual in pixels and is
    flagged (red row); excluding it brings the solution back onto the marker."""
    p = Page(browser, f"{server}/?project={project}")
    try:
        known = _known("roof_c")
        views = [*VIEWPOINTS, (80.0, 40.0, 9.0, (0.2, 0.2, 0.0))]
        p.page.keyboard.press("m")
        for i, view in enumerate(views):
            if i < 4:
                p.click_world(known, view)
            else:
                aim = p.page.evaluate(AIM_JS, [list(map(float, known)), *view[:3], list(view[3])])
                p.page.mouse.click(aim["x"] + 25.0, aim["y"])
            p.wait_rays(i + 1)
        p.page.wait_for_function(
            "() => document.querySelectorAll('#ray-table tbody tr.outlier').length === 1", timeout=30_000)
        rows = p.page.locator("#ray-table tbody tr")
        assert "outlier" in (rows.nth(4).get_attribute("class") or "")
        res = [float(t) for t in p.page.locator("#ray-table tbody tr td:nth-child(2)").all_inner_texts()]
        assert res[4] > 10.0 and max(res[:4]) < res[4] / 2, res  # the good rays absorb some
        p.shot("09_outlier_flagged", settle_ms=500)
        sol = p.page.evaluate("gsgeo.state.measure.solution.point_ecef")
        assert np.linalg.norm(np.array(sol) - known) > 0.002  # the bad ray pulls the point
        rows.nth(4).locator("button").click()  # exclude it
        p.page.wait_for_function("() => document.querySelector('#ray-table tbody tr.excluded')")
        p.wait_solution()
        p.page.wait_for_function(
            "() => gsgeo.state.measure.solution && gsgeo.state.measure.solution.n_rays === 4")
        sol = p.page.evaluate("gsgeo.state.measure.solution.point_ecef")
        assert np.linalg.norm(np.array(sol) - known) < 0.005
        p.page.keyboard.press("Escape")
        assert p.errors == []
    finally:
        p.close()


def test_lines_polygons_and_export(server, browser, project, tmp_path):
    """Three measured markers; a line and a polygon from them with the lengths the geometry
    gives; the GeoPackage download reads back with the points."""
    pyogrio = pytest.importorskip("pyogrio")
    p = Page(browser, f"{server}/?project={project}")
    try:
        ids = {}
        for name in ("roof_ne", "ground_sw", "roof_c"):
            ids[name] = _measure(p, _known(name), VIEWPOINTS[:3], code=name)["id"]
        # line: pick in the list
        p.page.keyboard.press("l")
        for name in ("roof_ne", "ground_sw"):
            p.page.click(f"#points-table tbody tr[data-id='{ids[name]}']")
        with p.page.expect_response(_posted("lines")) as resp:
            p.page.keyboard.press("Enter")
        line = resp.value.json()
        a, b = (np.array(MARKERS[k]) for k in ("roof_ne", "ground_sw"))
        # UTM scale factor near 0.12 W, 51.5 N is ~0.99998 over 6 m: well under a millimetre
        assert abs(line["measures"]["length_3d"] - np.linalg.norm(a - b)) < 0.005
        # polygon: pick in the scene by clicking the point markers
        p.page.keyboard.press("p")
        for name in ("roof_ne", "ground_sw", "roof_c"):
            p.click_world(_known(name), (200.0, 70.0, 16.0, (0.0, 0.0, 0.0)))
            p.page.wait_for_timeout(200)
        assert p.page.inner_text("#feature-points").count("→") == 2
        with p.page.expect_response(_posted("polygons")) as resp:
            p.page.keyboard.press("Enter")
        poly = resp.value.json()
        xy = np.array([MARKERS[k][:2] for k in ("roof_ne", "ground_sw", "roof_c")])
        (ux, uy), (vx, vy) = xy[1] - xy[0], xy[2] - xy[0]
        area = 0.5 * abs(ux * vy - uy * vx)
        assert abs(poly["measures"]["area_2d"] - area) < 0.01
        p.page.wait_for_selector("#features-table tbody tr:nth-child(2)")
        p.shot("07_line_polygon")

        with p.page.expect_download() as dl:
            p.page.click("button[data-export='gpkg']")
        path = tmp_path / "export.gpkg"
        dl.value.save_as(path)
        pts = pyogrio.read_dataframe(path, layer="points")
        row = pts[pts["point_id"] == ids["roof_ne"]].iloc[0]
        e, n, h = _grid_of(_known("roof_ne"))
        assert abs(row["easting"] - e) < 0.005 and abs(row["northing"] - n) < 0.005
        assert abs(row["height"] - h) < 0.005
        assert set(pyogrio.list_layers(path)[:, 0]) >= {"points", "lines", "polygons"}
        assert p.errors == []
    finally:
        p.close()


def test_check_points_accuracy_panel(server, browser, project, tmp_path):
    """Import the markers' true grid coordinates as check points (CSV); the accuracy panel
    shows each measured point's differences (a few mm at most) and the RMSE summary."""
    p = Page(browser, f"{server}/?project={project}")
    try:
        pts = p.page.evaluate("gsgeo.state.points.map(q => [q.id, q.code])")
        rows = ["id,x,y,z"]
        for pid, code in pts:
            if code in MARKERS:
                e, n, h = _grid_of(_known(code))
                rows.append(f"{pid},{e:.4f},{n:.4f},{h:.4f}")
        if len(rows) < 2:
            pytest.skip("no marker points measured (run the whole module)")
        csv = tmp_path / "check.csv"
        csv.write_text("\n".join(rows) + "\n")
        p.page.set_input_files("#check-file", str(csv))
        p.page.click("#check-form button[type=submit]")
        p.page.wait_for_selector("#accuracy-table tbody tr")
        diffs = p.page.locator("#accuracy-table tbody tr td:nth-child(5)").all_inner_texts()
        assert len(diffs) == len(rows) - 1
        assert all(abs(float(d)) < 5.0 for d in diffs), diffs  # mm
        summary = p.page.inner_text("#accuracy-summary")
        assert re.search(r"RMSE E [\d.]+", summary) and f"{len(rows) - 1} of {len(rows) - 1}" in summary
        p.shot("08_accuracy", settle_ms=1500)
        assert p.errors == []
    finally:
        p.close()


def test_token_from_url_fragment(data_dir, browser):
    """A server with a token: the page takes it from #token=..., drops it from the address and
    sends it with every API call (scenes, projects, tiles load; no console errors)."""
    from tests.servertools import start_server

    proc, base = start_server(data_dir, env={"GSGEO_TOKEN": "s3cret-token"})
    try:
        p = Page(browser, f"{base}/?scene={SCENE}#token=s3cret-token")
        try:
            assert p.page.evaluate("location.hash") == ""
            assert p.page.input_value("#scene-select") == SCENE
            assert p.page.locator("#project-select option").count() >= 1
            assert p.errors == []
        finally:
            p.close()
    finally:
        proc.terminate()
        proc.communicate(timeout=10)


def test_credits_name_cesiumjs_without_ion_branding(server, browser):
    """Nothing comes from Cesium ion: the viewer's credit area names CesiumJS as text, shows
    no ion logo and no link to cesium.com, and the page never loads the ion logo."""
    p = Page(browser, f"{server}/?scene={SCENE}")
    try:
        credits = p.page.locator("#cesium .cesium-widget-credits")
        p.page.wait_for_function(
            "document.querySelector('#cesium .cesium-widget-credits').textContent.length > 0")
        assert "CesiumJS" in credits.inner_text()
        html = credits.inner_html().lower()
        assert "ion-credit" not in html and "cesium ion" not in html, html
        assert credits.locator("img").count() == 0, html
        assert credits.locator("a[href*='cesium.com']").count() == 0, html
        loaded = p.page.evaluate("performance.getEntriesByType('resource').map(e => e.name)")
        assert not [u for u in loaded if "ion-credit" in u or "ion_credit" in u], loaded
        ARTIFACTS.mkdir(exist_ok=True)
        credits.screenshot(path=str(ARTIFACTS / "workplace_credits.png"), timeout=90_000)
        assert p.errors == []
    finally:
        p.close()


def test_stores_merge_the_servers_answer(server, browser, project):
    """Storing, changing and deleting points and lines updates the lists from the server's
    answer: none of the collections (points, lines, polygons, check points) is fetched again;
    only the line on a changed point (its measures) and the accuracy are."""
    p = Page(browser, f"{server}/?project={project}")
    gets: list[str] = []
    p.page.on("request", lambda r: r.method == "GET" and "/api/projects/" in r.url
              and gets.append(r.url.split("/api/projects/", 1)[1]))
    refetched = re.compile(r"^[^/]+/(points|lines|polygons|checkpoints)(\?|$)")
    try:
        gets.clear()
        b = _measure(p, _known("ground_sw"), VIEWPOINTS[:2], code="merge b")["id"]
        a = _measure(p, _known("roof_c"), VIEWPOINTS[:3], code="merge a")["id"]
        p.page.wait_for_selector(f"#points-table tbody tr.selected[data-id='{a}']")
        state_ids = p.page.evaluate("gsgeo.state.points.map((q) => q.id)")
        assert state_ids[-2:] == [b, a] and len(set(state_ids)) == len(state_ids)
        # the line: picked in the list, stored, listed with its measures
        p.page.keyboard.press("l")
        for pid in (a, b):
            p.page.click(f"#points-table tbody tr[data-id='{pid}']")
        with p.page.expect_response(_posted("lines")) as resp:
            p.page.keyboard.press("Enter")
        line = resp.value.json()
        p.page.wait_for_function(f"gsgeo.state.lines.some((f) => f.id === '{line['id']}')")
        assert line["id"] in p.page.inner_text("#features-table")
        p.page.wait_for_timeout(300)
        assert not [g for g in gets if refetched.match(g)], gets
        # excluding a ray of a changes the line's measures: the lines (only) are fetched again
        row = f"#points-table tbody tr[data-id='{a}']"
        with p.page.expect_response(lambda r: r.url.endswith("/lines") and r.request.method == "GET"):
            p.page.click("#point-detail button:text('exclude')")
        p.page.wait_for_function(f"document.querySelector(\"{row} td:nth-child(8)\").textContent === '2+1✕'")
        assert p.page.evaluate(f"gsgeo.state.points.find((q) => q.id === '{a}').excluded") == [0]
        p.page.wait_for_timeout(300)
        assert [g for g in gets if refetched.match(g)] == [f"{project}/lines"], gets
        gets.clear()
        # the code and description edited after storing, then Ctrl+Z: both back, in the store
        p.page.click("#btn-edit")
        p.page.fill("#edit-code", "kerb edge")
        p.page.fill("#edit-description", "north side")
        with p.page.expect_response(lambda r: r.request.method == "PATCH") as resp:
            p.page.keyboard.press("Enter")
        assert resp.value.request.post_data_json == {"code": "kerb edge", "description": "north side"}
        p.page.wait_for_function(f"gsgeo.state.points.find((q) => q.id === '{a}').code === 'kerb edge'")
        with p.page.expect_response(lambda r: r.request.method == "PATCH") as resp:
            p.page.keyboard.press("Control+z")
        assert resp.value.request.post_data_json == {"code": "merge a", "description": ""}
        p.page.wait_for_function(f"gsgeo.state.points.find((q) => q.id === '{a}').code === 'merge a'")
        p.page.wait_for_timeout(300)
        assert {g for g in gets if refetched.match(g)} <= {f"{project}/lines"}, gets
        gets.clear()
        # deleting the line, then the point
        p.page.click(f"#features-table button[title='delete {line['id']}']")
        p.page.wait_for_function(f"!gsgeo.state.lines.some((f) => f.id === '{line['id']}')")
        before = p.page.evaluate(f"gsgeo.state.points.find((q) => q.id === '{a}')")
        with p.page.expect_response(lambda r: r.request.method == "DELETE"):
            p.page.click("#point-detail button.danger")  # one click
        p.page.wait_for_selector(row, state="detached")
        assert a not in p.page.evaluate("gsgeo.state.points.map((q) => q.id)")
        p.page.wait_for_timeout(300)
        assert not [g for g in gets if refetched.match(g)], gets
        # Ctrl+Z brings it back through the API: its id, code, rays (the exclusion kept) and
        # its point, in the store and in the audit trail
        with p.page.expect_response(lambda r: r.url.endswith("/points")
                                    and r.request.method == "POST") as resp:
            p.page.keyboard.press("Control+z")
        assert resp.value.status == 201, resp.value.text()
        p.page.wait_for_selector(row)
        import httpx

        got = httpx.get(f"{server}/api/projects/{project}/points/{a}").json()
        assert got["code"] == "merge a" and got["excluded"] == [0]
        assert [r["direction"] for r in got["rays"]] == [r["direction"] for r in before["rays"]]
        assert np.allclose(got["result"]["point_ecef"], before["result"]["point_ecef"], atol=1e-6)
        trail = httpx.get(f"{server}/api/projects/{project}/audit",
                          params={"item": a, "order": "oldest"}).json()["entries"]
        assert [e["action"] for e in trail][-2:] == ["deleted", "created"], trail
        # and Ctrl+Shift+Z deletes it again
        with p.page.expect_response(lambda r: r.request.method == "DELETE"):
            p.page.keyboard.press("Control+Shift+Z")
        p.page.wait_for_selector(row, state="detached")
        assert p.errors == []
    finally:
        p.close()
