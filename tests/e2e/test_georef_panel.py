"""The Georeference panel (web/js/georef.js) against a live `gsgeo serve`.

A local scene (tests/e2e/scene.py's box, tiled without a georeference: lat 0, lon 0) is the
true site shrunk, turned and moved by a known similarity TRUTH (local PLY coordinates -> true
ECEF). A project on it holds six control points (EPSG:4979, one with a 0.5 m blunder in its
height) and a check point; the targets are measured through the API by rays aimed at their
positions in the scene's current frame, with the control ids. In the browser: the banner says
the scene is not georeferenced; G opens the panel, which lists the control with residuals and
the blunder in red; excluding it refits; Apply asks first (scale, rotation, shift, points to
re-solve), then the tileset's root transform is the fitted similarity in front of the old one,
the camera stays on the same feature, the banner goes, a point measured afterwards carries the
new georeference version; Undo restores the root transform and the banner.
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import numpy as np
import pyproj
import pytest

from gsgeo.tiles.build import build_tileset
from gsgeo.tiles.georef import Georeference
from tests.e2e.scene import MARKERS, write_scene_ply
from tests.e2e.shared import require_browser
from tests.e2e.workplace import AIM_JS

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1280, "height": 720}
TO_ECEF = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
TO_GEO = pyproj.Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
SCENE = "box"
PID = "geo"

#: Control targets in the scene's local (PLY) coordinates: box top corners and ground marks.
CONTROL = {"C1": (1.0, 1.0, 1.5), "C2": (-1.0, -1.0, 1.5), "C3": (-3.0, -2.5, 0.0),
           "C4": (4.0, 3.5, 0.0), "C5": (3.5, -4.0, 0.0), "C6": (-4.0, 4.0, 0.0)}
BLUNDER = "C6"  # its control height is 0.5 m off
CHECK = {"K1": (1.0, -1.0, 1.5)}


def enu_frame(lat: float, lon: float, h: float) -> np.ndarray:
    """4x4 local ENU at (lat, lon, h) on WGS 84 -> ECEF."""
    o = TO_ECEF.transform(lon, lat, h)
    p, lam = np.radians(lat), np.radians(lon)
    m = np.eye(4)
    m[:3, :3] = np.array([[-np.sin(lam), -np.sin(p) * np.cos(lam), np.cos(p) * np.cos(lam)],
                          [np.cos(lam), -np.sin(p) * np.sin(lam), np.cos(p) * np.sin(lam)],
                          [0.0, np.cos(p), np.sin(p)]])
    m[:3, 3] = o
    return m


def _truth() -> np.ndarray:
    """Local PLY coordinates -> true ECEF: 0.37 m per unit, turned 70 degrees about the
    vertical and tilted 4 degrees, at a site near Cambridge."""
    a, t = np.radians(70.0), np.radians(4.0)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    rx = np.array([[1.0, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    m = np.eye(4)
    m[:3, :3] = 0.37 * rz @ rx
    m[:3, 3] = [2.0, -1.0, 0.5]
    return enu_frame(52.2, 0.12, 20.0) @ m


TRUTH = _truth()
LOCAL = enu_frame(0.0, 0.0, 0.0)  # where gsgeo tiles puts a scene without a georeference


def apply(m: np.ndarray, p) -> np.ndarray:
    return m[:3, :3] @ np.asarray(p, float) + m[:3, 3]


def rays_at(target: np.ndarray, rng: np.random.Generator, n: int = 4) -> list[dict]:
    """Rays at `target` (ECEF) from n cameras 8 m away, 30-50 degrees up, 0.3 mrad noise."""
    up = target / np.linalg.norm(target)
    east = np.cross([0.0, 0.0, 1.0], up)
    east /= np.linalg.norm(east)
    north = np.cross(up, east)
    rays = []
    for k in range(n):
        az, el = 2 * np.pi * k / n + 0.4, np.radians(30 + 20 * k / n)
        o = target + 8.0 * (np.cos(el) * (np.cos(az) * east + np.sin(az) * north) + np.sin(el) * up)
        d = (target - o) / np.linalg.norm(target - o) + rng.normal(0, 3e-4, 3)
        rays.append({"origin": o.tolist(), "direction": (d / np.linalg.norm(d)).tolist(),
                     "ifov": 1e-3})
    return rays


def lon_lat_h(local) -> list[float]:
    return list(TO_GEO.transform(*apply(TRUTH, local)))


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    require_browser()
    import httpx

    from tests.servertools import start_server

    root = tmp_path_factory.mktemp("georef-panel")
    data = root / "data"
    build_tileset(write_scene_ply(root / "box.ply"), data / "scenes" / SCENE, Georeference(),
                  max_splats=4096, progress=None)
    proc, base = start_server(data)
    try:
        c = httpx.Client(base_url=base, timeout=60)
        r = c.post("/api/projects", json={"name": "Georef", "id": PID, "scene": SCENE,
                                         "crs": "EPSG:27700"})
        assert r.status_code == 201, r.text
        rng = np.random.default_rng(16)
        for pid, p in {**CONTROL, **CHECK}.items():
            r = c.post(f"/api/projects/{PID}/points",
                       json={"id": pid, "rays": rays_at(apply(LOCAL, p), rng), "georef_version": 0})
            assert r.status_code == 201, r.text
        pts = []
        for cid, p in CONTROL.items():
            lon, lat, h = lon_lat_h(p)
            pts.append({"id": cid, "x": lon, "y": lat, "z": h + (0.5 if cid == BLUNDER else 0.0),
                        "sigma_h": 0.01, "sigma_v": 0.01, "description": f"pillar {cid}"})
        r = c.post(f"/api/projects/{PID}/checkpoints",
                   json={"crs": "EPSG:4979", "role": "control", "points": pts})
        assert r.status_code in (200, 201), r.text
        lon, lat, h = lon_lat_h(CHECK["K1"])
        r = c.post(f"/api/projects/{PID}/checkpoints", json={
            "crs": "EPSG:4979", "role": "check", "points": [{"id": "K1", "x": lon, "y": lat, "z": h}]})
        assert r.status_code in (200, 201), r.text
        yield base, c, data
    finally:
        proc.terminate()
        proc.communicate(timeout=10)


@pytest.fixture(scope="module")
def page(server, browser):
    base = server[0]
    pg = browser.new_page(viewport=VIEWPORT, accept_downloads=True)
    errors: list[str] = []
    pg.on("console", lambda m: m.type == "error" and errors.append(m.text))
    pg.on("pageerror", lambda e: errors.append(f"page error: {e}"))
    pg.goto(f"{base}/?project={PID}")
    pg.wait_for_function("window.gsgeo && window.gsgeo.ready === true", timeout=90_000)
    pg.errors = errors
    yield pg
    pg.close()


def root_transform(page) -> np.ndarray:
    """The loaded tileset's root transform (4x4, row-major numpy)."""
    return np.array(page.evaluate("Array.from(gsgeo.Cesium.Matrix4.toArray(gsgeo.tileset.root.transform))"),
                    float).reshape(4, 4).T


def window_of(page, ecef) -> list[float]:
    return page.evaluate("""(p) => { const C = gsgeo.Cesium;
        const w = C.SceneTransforms.worldToWindowCoordinates(gsgeo.viewer.scene, new C.Cartesian3(...p));
        return [w.x, w.y]; }""", list(map(float, ecef)))


def shot(page, name: str) -> None:
    """A screenshot for people to look at (not an assertion), in the temporary folder."""
    out = Path(tempfile.gettempdir()) / "gsgeo-e2e-georef-panel"
    out.mkdir(exist_ok=True)
    page.screenshot(path=str(out / f"{name}.png"), timeout=90_000)


def wait_fit(page):
    page.wait_for_function("gsgeo.state.georef && gsgeo.state.georef.fit !== null"
                           " && document.querySelector('#georef-summary')", timeout=30_000)


def test_panel_residuals_outlier_exclude_apply_undo(server, page):
    base, client, data = server
    p = page
    # an un-georeferenced scene says so
    p.wait_for_selector("#georef-banner:not([hidden])")
    assert "This scene is not georeferenced" in p.inner_text("#georef-banner")
    assert p.evaluate("gsgeo.georefVersion") == 0
    # no globe under a scene in its trainer's frame (its surface would cut through the scene)
    assert p.evaluate("gsgeo.viewer.scene.globe.show") is False
    old_root = root_transform(p)
    assert np.allclose(old_root[:3, :3], LOCAL[:3, :3], atol=1e-9)

    # G opens the panel: every control point measured, live residuals, the blunder in red
    p.keyboard.press("g")
    p.wait_for_selector("#georef-panel:not([hidden])")
    wait_fit(p)
    rows = p.locator("#georef-table tbody tr")
    assert rows.count() == len(CONTROL)
    assert sorted(p.locator("#georef-table tbody tr").evaluate_all(
        "rs => rs.map(r => r.dataset.id)")) == sorted(CONTROL)
    assert p.locator("#georef-table tbody tr td:nth-child(3)").all_inner_texts() == ["✓"] * 6
    # each control point with its coordinates as given; its id looks at it (the view's centre)
    c3 = lon_lat_h(CONTROL["C3"])
    text = p.inner_text("#georef-table tbody tr[data-id='C3'] td:nth-child(2)")
    assert [float(v) for v in text.split(" (")[0].split(", ")] == pytest.approx(list(c3), abs=1e-9), text
    assert text.endswith("(EPSG:4979) · pillar C3"), text
    p.click("#georef-table tbody tr[data-id='C3'] button.known")
    centre = p.evaluate("[gsgeo.viewer.scene.canvas.clientWidth / 2,"
                        " gsgeo.viewer.scene.canvas.clientHeight / 2]")
    c3_ecef = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True).transform(*c3)
    assert window_of(p, c3_ecef) == pytest.approx(centre, abs=0.5)
    outliers = p.evaluate("gsgeo.state.georef.fit.outliers")
    assert outliers == [BLUNDER], outliers
    bad = p.locator(f"#georef-table tbody tr[data-id='{BLUNDER}']")
    assert "outlier" in bad.get_attribute("class")
    assert p.locator("#georef-table tbody tr.outlier").count() == 1
    red = p.evaluate(f"""getComputedStyle(document.querySelector(
        "#georef-table tbody tr[data-id='{BLUNDER}'] td")).color""")
    assert red == "rgb(255, 123, 114)", red
    d_bad = float(bad.locator("td:nth-child(7)").inner_text())  # 3-D residual, mm
    assert d_bad > 100.0, d_bad
    assert BLUNDER in p.inner_text("#georef-outliers")
    shot(p, "01_outlier")

    # excluding the blunder refits without it: no outlier, residuals of a few centimetres at most
    with p.expect_request(lambda r: r.url.endswith(f"/projects/{PID}/georeference")
                          and r.method == "POST") as req:
        bad.locator("input.georef-exclude").check()
    assert req.value.post_data_json == {"exclude": [BLUNDER], "apply": False}
    p.wait_for_function("gsgeo.state.georef.fit && gsgeo.state.georef.fit.outliers.length === 0"
                        " && document.querySelector('#georef-summary')", timeout=30_000)
    assert "excluded" in p.locator(f"#georef-table tbody tr[data-id='{BLUNDER}']").get_attribute("class")
    d_good = [float(t) for t in p.locator(
        "#georef-table tbody tr:not(.excluded) td:nth-child(7)").all_inner_texts()]
    assert len(d_good) == 5 and max(d_good) < 30.0, d_good  # mm
    summary = p.inner_text("#georef-summary")
    scale = float(re.search(r"scale × ([\d.]+) \(-6\d{5}\.\d ± [\d.]+ ppm\)", summary).group(1))
    assert abs(scale - 0.37) < 1e-3, summary
    assert re.search(r"RMSE check +H [\d.]+ +V [\d.]+ +3D [\d.]+ mm \(1\)", summary), summary

    # the view before: where a feature is on the screen
    feature = MARKERS["roof_ne"]
    p.evaluate(AIM_JS, [list(map(float, apply(LOCAL, feature))), 30.0, 35.0, 9.0, [0.4, -0.3, 0.0]])
    win_before = window_of(p, apply(LOCAL, feature))

    # Apply asks first and says what will change
    p.click("#btn-georef-apply")
    p.wait_for_selector("#georef-confirm:not([hidden])")
    text = p.inner_text("#georef-confirm-text")
    shot(p, "02_confirm_apply")
    assert re.search(r"Scale: × 0\.3[67]\d+ \(-6\d\d,\d{3} ppm ± [\d.]+ ppm\)", text), text
    assert "Rotation:" in text and "Shift: the scene's centre moves" in text, text
    assert f"Re-solved: {len(CONTROL) + len(CHECK)} points in 1 project" in text, text
    with p.expect_response(lambda r: r.url.endswith(f"/projects/{PID}/georeference")
                           and r.request.method == "POST" and r.request.post_data_json["apply"]) as resp:
        p.click("#btn-georef-confirm")
    applied = resp.value.json()
    assert resp.value.status == 200 and applied["applied"] is True, applied
    assert resp.value.request.post_data_json == {"exclude": [BLUNDER], "apply": True,
                                                 "accept_outliers": False}
    p.wait_for_function("gsgeo.georefVersion === 1 && gsgeo.tileset && gsgeo.tilesReady",
                        timeout=60_000)
    sim = np.array(applied["scene"]["similarity"], float).reshape(4, 4).T
    new_root = root_transform(p)
    # the loaded tileset's root transform is the fitted similarity in front of the old one,
    # and that is the truth: the scene's splats where the site is
    assert np.allclose(new_root, sim @ old_root, rtol=0, atol=1e-6)
    truth_sim = TRUTH @ np.linalg.inv(LOCAL)
    assert abs(np.cbrt(np.linalg.det(sim[:3, :3])) - 0.37) < 1e-3
    for p_local in [*CONTROL.values(), *CHECK.values()]:
        x = apply(LOCAL, p_local)
        assert np.linalg.norm(apply(sim, x) - apply(truth_sim, x)) < 0.05
    p.wait_for_selector("#georef-banner", state="hidden")
    assert p.evaluate("gsgeo.viewer.scene.globe.show") is True  # the Earth under it again
    # the camera moved with the scene: the feature is where it was on the screen
    win_after = window_of(p, apply(sim, apply(LOCAL, feature)))
    assert np.allclose(win_after, win_before, atol=1.0), (win_before, win_after)
    # the points were re-solved in the new frame: the check point is at its true place
    p.wait_for_function("gsgeo.state.points.length > 0 && gsgeo.state.georef.status"
                        " && gsgeo.state.georef.status.version === 1", timeout=30_000)
    k1 = np.array(p.evaluate("gsgeo.state.points.find(q => q.id === 'K1').result.point_ecef"))
    assert np.linalg.norm(k1 - apply(TRUTH, CHECK["K1"])) < 0.05
    assert p.locator("#btn-georef-undo").is_enabled()
    # fitted again in the new frame, the fit changes nothing: Apply is off and says why
    p.wait_for_selector("#georef-current")
    assert p.locator("#btn-georef-apply").is_disabled()
    shot(p, "03_applied")

    # a point measured now carries the new georeference version and lands at its true place
    marker = MARKERS["ground_sw"]
    target = apply(TRUTH, marker)
    p.keyboard.press("m")
    p.wait_for_selector("#measure-panel:not([hidden])")
    for i, (az, el) in enumerate([(30.0, 35.0), (150.0, 45.0), (260.0, 40.0)]):
        aim = p.evaluate(AIM_JS, [list(map(float, target)), az, el, 4.0, [0.1, -0.1, 0.0]])
        assert aim["dist"] < 1e-5, aim
        p.mouse.click(aim["x"], aim["y"])
        p.wait_for_function(f"gsgeo.state.measure.rays.length === {i + 1}")
    p.keyboard.press("Enter")  # asks for the id
    p.wait_for_selector("#id-prompt:not([hidden])")
    with p.expect_response(lambda r: r.url.endswith(f"/projects/{PID}/points")
                           and r.request.method == "POST") as resp:
        p.keyboard.press("Enter")
    assert resp.value.status == 201, resp.value.text()
    assert resp.value.request.post_data_json["georef_version"] == 1
    got = np.array(resp.value.json()["result"]["point_ecef"])
    assert np.linalg.norm(got - target) < 0.01, got - target

    # a point measured before the change, reopened now (Add rays): its stored rays are carried
    # into the current frame before a new ray joins them, so it stays at its true place
    p.click("#points-table tbody tr[data-id='C1']")
    p.wait_for_selector("#point-detail:not([hidden])")
    p.click("#point-detail button:text('Add rays')")
    p.wait_for_function("gsgeo.state.measure && gsgeo.state.measure.rays.length === 4")
    target = apply(TRUTH, CONTROL["C1"])
    aim = p.evaluate(AIM_JS, [list(map(float, target)), 200.0, 40.0, 4.0, [0.1, 0.1, 0.0]])
    p.mouse.click(aim["x"], aim["y"])
    p.wait_for_function("gsgeo.state.measure.rays.length === 5")
    with p.expect_response(lambda r: r.url.endswith(f"/projects/{PID}/points/C1")
                           and r.request.method == "PATCH") as resp:
        p.keyboard.press("Enter")
    assert resp.value.status == 200, resp.value.text()
    c1 = resp.value.json()
    assert c1["record"]["n_rays"] == 5, c1["record"]
    got = np.array(c1["result"]["point_ecef"])
    assert np.linalg.norm(got - target) < 0.05, got - target

    # Undo asks, then restores the old root transform, the banner and the view (the row click
    # above started a flight to C1: stopped, as an Undo would stop it)
    p.evaluate("gsgeo.viewer.camera.cancelFlight()")
    p.evaluate(AIM_JS, [list(map(float, apply(TRUTH, feature))), 30.0, 35.0, 4.0, [0.1, -0.1, 0.0]])
    win_before = window_of(p, apply(TRUTH, feature))
    p.click("#btn-georef-undo")
    p.wait_for_selector("#georef-confirm:not([hidden])")
    assert "Re-solved: 8 points in 1 project" in p.inner_text("#georef-confirm-text")
    with p.expect_response(lambda r: r.url.endswith(f"/projects/{PID}/georeference/undo")) as resp:
        p.click("#btn-georef-confirm")
    assert resp.value.status == 200, resp.value.text()
    p.wait_for_function("gsgeo.georefVersion === 2 && gsgeo.tileset && gsgeo.tilesReady",
                        timeout=60_000)
    assert np.allclose(root_transform(p), old_root, rtol=0, atol=1e-6)
    p.wait_for_selector("#georef-banner:not([hidden])")
    assert p.evaluate("gsgeo.viewer.scene.globe.show") is False  # in its trainer's frame again
    undo = np.array(resp.value.json()["similarity"], float).reshape(4, 4).T
    win_after = window_of(p, apply(undo, apply(TRUTH, feature)))
    assert np.allclose(win_after, win_before, atol=1.0), (win_before, win_after)
    p.wait_for_function("gsgeo.state.georef.status && gsgeo.state.georef.status.version === 2",
                        timeout=30_000)
    # version 2 is the scene as tiled again: nothing more to undo
    assert p.locator("#btn-georef-undo").is_disabled()
    assert p.errors == [], p.errors


def test_report_button_downloads_the_pdf(server, page):
    page.keyboard.press("Escape")
    if page.locator("#georef-panel").is_hidden():
        page.keyboard.press("g")
    page.wait_for_selector("#georef-panel:not([hidden])")
    with page.expect_download(timeout=120_000) as dl:
        page.click("#btn-georef-report")
    assert dl.value.url.endswith(f"/api/projects/{PID}/report?format=pdf") or \
        dl.value.suggested_filename.endswith(".pdf")
    path = dl.value.path()
    assert path.read_bytes()[:5] == b"%PDF-"
    # the same report from the main bar, the panel closed
    page.keyboard.press("g")
    page.wait_for_selector("#georef-panel", state="hidden")
    with page.expect_download(timeout=120_000) as dl:
        page.click("#btn-report")
    assert dl.value.path().read_bytes()[:5] == b"%PDF-"
    assert page.errors == [], page.errors
