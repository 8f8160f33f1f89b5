"""Navigation made for a splat scene (web/js/navigate.js), with real mouse and keyboard events on
the demo (`gsgeo demo`) in Chromium.

- 20 wheel notches towards a ground marker (G1) seen from 12 m, the mouse on the pixel of the
  marker: after every notch the camera is above the ground there (the marker's truth height,
  gsgeo.demo.place) and not closer to the ground under the cursor than the stop (MIN_GAP_M,
  less 1 cm for the splats' depth), and that ground point stays under the cursor within
  10 px; the last notches no longer move it (it stopped short of the surface).
  Notches back move it away along the same line.
- Home returns the camera to the overview the scene opened with.
- The cursor resting on a marker shows its grid coordinates (EPSG:27700, E N H) in the status
  bar, within 5 cm of the truth; the scale bar's length in metres spans its pixels at the depth
  of the view's centre (within 2 %), and the north arrow turns with the camera's heading.
- H held hides every aid over the scene (overlay, status line, north arrow, scale bar,
  coordinates): nothing but the scene's canvas is seen; released, they are back.

Truth: gsgeo.demo.place.truth_points() (PROJ, independent of the viewer).
"""

from __future__ import annotations

import re

import numpy as np
import pyproj
import pytest

from gsgeo.demo import place
from gsgeo.demo.project import PROJECT_ID
from tests.e2e.shared import open_demo_page
from tests.e2e.workplace import AIM_JS

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1280, "height": 720}
MIN_GAP_M = 0.3  # navigate.js
TO_GEO = pyproj.Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
POSE_JS = """() => { const c = gsgeo.viewer.camera, p = c.positionWC, d = c.directionWC;
    return {position: [p.x, p.y, p.z], direction: [d.x, d.y, d.z], heading: c.heading}; }"""
#: Where the ray through page position (x, y) meets the level plane through point g (ECEF): the
#: ground the cursor is on (the mouse sits on whole CSS pixels; G1 is a fraction of one away).
GROUND_UNDER_JS = """([x, y, g]) => { const C = gsgeo.Cesium, v = gsgeo.viewer;
    const r = v.scene.canvas.getBoundingClientRect();
    const ray = v.camera.getPickRay(new C.Cartesian2(x - r.left, y - r.top));
    const G = new C.Cartesian3(...g), up = C.Ellipsoid.WGS84.geodeticSurfaceNormal(G, new C.Cartesian3());
    const t = C.Cartesian3.dot(C.Cartesian3.subtract(G, ray.origin, new C.Cartesian3()), up)
      / C.Cartesian3.dot(ray.direction, up);
    const p = C.Ray.getPoint(ray, t);
    return [p.x, p.y, p.z]; }"""
WINDOW_JS = """(p) => { const C = gsgeo.Cesium;
    const w = C.SceneTransforms.worldToWindowCoordinates(gsgeo.viewer.scene, new C.Cartesian3(...p));
    const r = gsgeo.viewer.scene.canvas.getBoundingClientRect();
    return w ? [r.left + w.x, r.top + w.y] : null; }"""


#: What is seen over the scene's canvas in the viewer: the ids (or class) of the visible elements.
AIDS_JS = """() => [...document.querySelectorAll('#viewer-wrap > *')].filter((e) => e.id !== 'cesium'
    && !e.hidden && getComputedStyle(e).display !== 'none' && getComputedStyle(e).visibility !== 'hidden'
    && e.getBoundingClientRect().width > 0).map((e) => e.id || e.className)"""


@pytest.fixture(scope="module")
def page(demo_server, browser):
    yield from open_demo_page(browser, demo_server, PROJECT_ID, VIEWPORT)


def truth(pid: str):
    return next(t for t in place.truth_points() if t.id == pid)


def height(ecef) -> float:
    return float(TO_GEO.transform(*map(float, ecef))[2])


def wait_idle(p) -> None:
    p.wait_for_function("gsgeo.navigation && !gsgeo.navigation.busy")


def quiet(p) -> None:
    """Wait until no frame has been drawn for 3 s."""
    p.evaluate("window.lastFrames = -1")
    p.wait_for_function("""() => { const f = gsgeo.renderer.frames, now = performance.now();
        if (window.lastFrames !== f) { window.lastFrames = f; window.lastFrameAt = now; }
        return now - window.lastFrameAt > 3000; }""", polling=250)


def test_wheel_zooms_about_the_splat_under_the_cursor_and_home_returns(page):
    p = page
    overview = p.evaluate(POSE_JS)
    g1 = truth("G1")
    aim = p.evaluate(AIM_JS, [list(g1.ecef), 200.0, 45.0, 12.0, [0.4, -0.3, 0.0]])
    cursor = (round(aim["x"]), round(aim["y"]))  # where a mouse can be: on whole pixels
    p.mouse.move(*cursor)
    target = np.asarray(p.evaluate(GROUND_UNDER_JS, [*cursor, list(g1.ecef)]))
    assert np.linalg.norm(target - np.asarray(g1.ecef)) < 0.02  # G1 is under the cursor
    ground = height(g1.ecef)
    distances = []
    for _ in range(20):
        wheels = p.evaluate("gsgeo.navigation.wheels")
        p.mouse.wheel(0, -100)  # one notch towards the scene
        p.wait_for_function(f"gsgeo.navigation.wheels > {wheels}")
        wait_idle(p)
        pose = p.evaluate(POSE_JS)
        cam = np.asarray(pose["position"])
        distances.append(float(np.linalg.norm(cam - target)))
        assert height(cam) > ground, (height(cam), ground)  # never below the ground
        assert distances[-1] > MIN_GAP_M - 0.01, distances  # never through the surface
        win = p.evaluate(WINDOW_JS, target.tolist())
        assert win is not None and np.hypot(win[0] - cursor[0], win[1] - cursor[1]) < 10, (win, cursor)
    assert distances[0] < 12.0 * 0.85, distances  # it moved in
    assert distances[-1] < 0.5, distances  # and stopped at the surface
    assert distances[-1] == pytest.approx(distances[-2], abs=1e-6)  # the last notches: stopped
    # notches back move it away along the same line
    for _ in range(3):
        wheels = p.evaluate("gsgeo.navigation.wheels")
        p.mouse.wheel(0, 100)
        p.wait_for_function(f"gsgeo.navigation.wheels > {wheels}")
        wait_idle(p)
    back = float(np.linalg.norm(np.asarray(p.evaluate(POSE_JS)["position"]) - target))
    assert back == pytest.approx(distances[-1] / 0.8**3, rel=0.05), (back, distances[-1])

    # Home: the overview the scene opened with
    p.keyboard.press("Home")
    p.wait_for_function("""(o) => { const p = gsgeo.viewer.camera.positionWC;
        return Math.hypot(p.x - o[0], p.y - o[1], p.z - o[2]) < 0.01; }""", arg=overview["position"])
    assert np.allclose(p.evaluate(POSE_JS)["direction"], overview["direction"], atol=1e-6)
    assert not p.errors, p.errors


def test_cursor_coordinates_scale_bar_and_north_arrow(page):
    p = page
    b1 = truth("B1")
    aim = p.evaluate(AIM_JS, [list(b1.ecef), 120.0, 50.0, 14.0, [0.0, 0.0, 0.0]])
    p.mouse.move(aim["x"] + 3, aim["y"] + 3)
    p.mouse.move(aim["x"], aim["y"])  # and rests there
    p.wait_for_function("gsgeo.navigation.cursor && gsgeo.navigation.cursor.located"
                        f" && Math.abs(gsgeo.navigation.cursor.pos[0] - {aim['win'][0]}) < 0.5")
    text = p.inner_text("#cursor-coords")
    m = re.search(r"E (\d+\.\d{3})\s+N (\d+\.\d{3})\s+H (-?\d+\.\d{3})\s+\(EPSG:27700\)", text)
    assert m, text
    enh = np.array([float(x) for x in m.groups()])
    err = enh - np.array([b1.easting, b1.northing, b1.height])
    assert np.linalg.norm(err) < 0.05, err

    # the scale bar at the depth of the view's centre (the marker: the camera looks at it)
    p.wait_for_function("!document.querySelector('#scale-bar').hidden"
                        " && gsgeo.navigation.centreDepth !== null")
    depth = p.evaluate("gsgeo.navigation.centreDepth")
    assert depth == pytest.approx(14.0, abs=0.3)
    px = float(p.evaluate("parseFloat(document.querySelector('#scale-bar .bar').style.width)"))
    metres = float(p.get_attribute("#scale-bar", "data-metres"))
    fovy, height_px = p.evaluate("[gsgeo.viewer.camera.frustum.fovy, gsgeo.viewer.scene.canvas.clientHeight]")
    per_px = 2 * np.tan(fovy / 2) * depth / height_px
    assert metres / px == pytest.approx(per_px, rel=0.02)
    label = p.inner_text("#scale-bar .label")
    assert label in {f"{metres:g} m", f"{round(metres * 100)} cm"}, label

    # the north arrow turns against the heading
    heading = p.evaluate("gsgeo.viewer.camera.heading")
    transform = p.evaluate("document.querySelector('#north-arrow').style.transform")
    angle = float(re.search(r"rotate\((-?[\d.e-]+)deg\)", transform).group(1))
    assert angle == pytest.approx(-np.degrees(heading), abs=0.01)

    # H held: the scene alone; released: the aids are back
    shown = p.evaluate(AIDS_JS)
    assert {"gsgeo-overlay", "status", "north-arrow", "scale-bar", "cursor-coords"} <= set(shown), shown
    p.keyboard.down("h")
    assert p.evaluate(AIDS_JS) == [], p.evaluate(AIDS_JS)
    p.keyboard.up("h")
    assert p.evaluate(AIDS_JS) == shown
    assert not p.errors, p.errors


def azimuth_deg(cam, point) -> float:
    """Azimuth (deg, clockwise from north) of the camera seen from `point` (ECEF)."""
    lon, lat, _ = TO_GEO.transform(*map(float, point))
    lon, lat = np.radians(lon), np.radians(lat)
    east = np.array([-np.sin(lon), np.cos(lon), 0.0])
    north = np.array([-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)])
    v = np.asarray(cam) - np.asarray(point)
    return float(np.degrees(np.arctan2(v @ east, v @ north)))


def elevation_deg(cam, point) -> float:
    """Elevation (deg) of the camera seen from `point` (ECEF), against the ellipsoid normal."""
    lon, lat, _ = TO_GEO.transform(*map(float, point))
    lon, lat = np.radians(lon), np.radians(lat)
    up = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    v = np.asarray(cam) - np.asarray(point)
    return float(np.degrees(np.arcsin(v @ up / np.linalg.norm(v))))


def drag(p, start, end, button="left", modifier=None) -> None:
    """A real mouse drag from `start` to `end` (page px) in three moves; waits until the
    navigation has put the camera where the drag takes it."""
    drags = p.evaluate("gsgeo.navigation.drags")
    p.mouse.move(*start)
    if modifier:
        p.keyboard.down(modifier)
    p.mouse.down(button=button)
    for k in (1, 2, 3):
        p.mouse.move(start[0] + (end[0] - start[0]) * k / 3, start[1] + (end[1] - start[1]) * k / 3)
    p.mouse.up(button=button)
    if modifier:
        p.keyboard.up(modifier)
    p.wait_for_function(f"gsgeo.navigation.drags > {drags} && !gsgeo.navigation.drag"
                        " && gsgeo.navigation.grabbing === 0")


def test_drags_pan_and_orbit_about_the_splat_under_the_cursor_and_arrows_move(page):
    """Left drag: the ground grabbed follows the cursor (within 3 px), the camera's direction
    kept. Right drag: the pivot stays at its pixel (3 px) and at its distance (1 cm); seen from
    the pivot, the camera's azimuth turns by 0.25 deg a pixel sideways and its elevation by 0.25
    deg a pixel up or down, never below 2 deg (the horizon: not below the ground). A press
    moved less than 5 px moves nothing. Arrow keys: the view's centre moves a tenth of the
    view's height; with Shift the heading turns 5 deg about it."""
    p = page
    g1 = truth("G1")
    aim = p.evaluate(AIM_JS, [list(g1.ecef), 200.0, 45.0, 12.0, [0.0, 0.0, 0.0]])
    start = (round(aim["x"]), round(aim["y"]))
    grabbed = np.asarray(p.evaluate(GROUND_UNDER_JS, [*start, list(g1.ecef)]))
    before = p.evaluate(POSE_JS)

    # a click's jitter is not a drag
    p.mouse.move(*start)
    p.mouse.down()
    p.mouse.move(start[0] + 2, start[1] + 1)
    p.mouse.up()
    assert np.allclose(p.evaluate(POSE_JS)["position"], before["position"], atol=1e-9)

    # left drag: pan
    end = (start[0] + 150, start[1] + 60)
    drag(p, start, end)
    pose = p.evaluate(POSE_JS)
    assert np.allclose(pose["direction"], before["direction"], atol=1e-9)  # moved, not turned
    win = p.evaluate(WINDOW_JS, grabbed.tolist())
    assert np.hypot(win[0] - end[0], win[1] - end[1]) < 3, (win, end)
    assert height(pose["position"]) > height(g1.ecef)

    # right drag: orbit about the splat under the cursor (G1's ground, now at `end`)
    pivot = np.asarray(p.evaluate(GROUND_UNDER_JS, [*end, list(g1.ecef)]))
    cam0 = np.asarray(pose["position"])
    e0 = elevation_deg(cam0, pivot)
    drag(p, end, (end[0] + 120, end[1] - 40), button="right")
    turned = p.evaluate(POSE_JS)
    cam1 = np.asarray(turned["position"])
    win = p.evaluate(WINDOW_JS, pivot.tolist())
    assert np.hypot(win[0] - end[0], win[1] - end[1]) < 3, (win, end)
    assert np.linalg.norm(cam1 - pivot) == pytest.approx(np.linalg.norm(cam0 - pivot), abs=0.01)
    da = (azimuth_deg(cam1, pivot) - azimuth_deg(cam0, pivot) + 180) % 360 - 180
    assert da == pytest.approx(120 * 0.25, abs=0.2), da
    assert elevation_deg(cam1, pivot) == pytest.approx(e0 - 40 * 0.25, abs=0.2)
    # a tilt far past the horizon stops above it (Ctrl + left drag orbits too)
    drag(p, end, (end[0], end[1] - 400), modifier="Control")
    low = np.asarray(p.evaluate(POSE_JS)["position"])
    assert elevation_deg(low, pivot) == pytest.approx(2.0, abs=0.2)
    assert height(low) > height(g1.ecef)

    # arrow keys
    p.evaluate(AIM_JS, [list(g1.ecef), 200.0, 45.0, 12.0, [0.0, 0.0, 0.0]])
    wait_idle(p)
    w, h = p.evaluate("[gsgeo.viewer.scene.canvas.clientWidth, gsgeo.viewer.scene.canvas.clientHeight]")
    at0 = np.asarray(p.evaluate(WINDOW_JS, list(g1.ecef)))
    keys = p.evaluate("gsgeo.navigation.keys")
    quiet(p)
    full0 = p.evaluate("gsgeo.renderer.framesOfAll")
    p.keyboard.press("ArrowRight")  # the camera goes right: the scene moves left
    p.wait_for_function(f"gsgeo.navigation.keys > {keys} && !gsgeo.navigation.busy")
    at1 = np.asarray(p.evaluate(WINDOW_JS, list(g1.ecef)))
    assert at1 - at0 == pytest.approx([-h / 10, 0.0], abs=3), (at0, at1, w, h)
    # the pan draws the scene once or twice, not once every few ticks of a drifting camera
    # (Cesium read the heading on every tick for its entity clustering, turning the camera by
    # 3e-16 each time: 28 frames of every splat after one arrow key, web/js/render.js)
    quiet(p)
    assert p.evaluate("gsgeo.renderer.framesOfAll") - full0 <= 4
    heading = p.evaluate("gsgeo.viewer.camera.heading")
    p.keyboard.press("Shift+ArrowLeft")
    p.wait_for_function(f"gsgeo.navigation.keys > {keys + 1} && !gsgeo.navigation.busy")
    dh = (np.degrees(p.evaluate("gsgeo.viewer.camera.heading") - heading) + 180) % 360 - 180
    assert dh == pytest.approx(-5.0, abs=0.3), dh
    assert not p.errors, p.errors


def test_idle_means_no_frame(page):
    """Once the view has settled after a move (no frame for 3 s), nothing changing for 30 s (the
    mouse resting on the scene, the scene loaded) draws not one WebGL frame (gsgeo.renderer
    counts every frame, web/js/render.js). The issue saw a frame of every splat every 6 s."""
    p = page
    g1 = truth("G1")
    aim = p.evaluate(AIM_JS, [list(g1.ecef), 150.0, 40.0, 15.0, [0.0, 0.0, 0.0]])
    p.mouse.move(aim["x"] + 40, aim["y"] + 30)
    wait_idle(p)
    p.wait_for_function("!gsgeo.renderer.busy()", polling=250)
    # settled: the view's last frames drawn (the cursor's coordinates and the scale bar asked
    # and shown), no frame for 3 s
    quiet(p)
    frames = p.evaluate("[gsgeo.renderer.frames, gsgeo.renderer.framesOfAll]")
    p.wait_for_timeout(30_000)
    after = p.evaluate("[gsgeo.renderer.frames, gsgeo.renderer.framesOfAll]")
    assert after == frames, (frames, after)
    assert not p.errors, p.errors


#: The largest alpha of the overlay's pixels within 8 px of each labelled marker `ids`.
MOST_OPAQUE_JS = """(ids) => { const C = gsgeo.Cesium, o = gsgeo.draw.overlay, s = gsgeo.viewer.scene;
    const img = o.ctx.getImageData(0, 0, o.canvas.width, o.canvas.height);
    const dpr = window.devicePixelRatio || 1;
    const alpha = (x, y) => img.data[4 * (Math.round(y * dpr) * img.width + Math.round(x * dpr)) + 3];
    return ids.map((id) => { const m = o.labelled().find((k) => k.id === id);
      const w = C.SceneTransforms.worldToWindowCoordinates(s, new C.Cartesian3(...m.position));
      let most = 0;
      for (let dy = -8; dy <= 8; dy++) for (let dx = -8; dx <= 8; dx++) {
        most = Math.max(most, alpha(w.x + dx, w.y + dy)); }
      return most; }); }"""


def test_labels_the_splats_hide_are_drawn_faint(page):
    """From 1.5 m above the lawn, 22 m south of the house, looking at it: the rays to the
    north eaves corners B3 and B4 meet the south wall 0.8 m below the eaves (hand geometry of
    the house in gsgeo.demo.place: walls at local y 2 and 9, eaves at z 5), so their markers
    and labels are drawn faint (the server's /visible, from the splats); the south corners
    B1 and B2 and the lamp top T1, in front of the house, are drawn in full, and so are
    their pixels."""
    p = page
    cam = place.local_to_ecef(np.array([[-9.0, -20.0, 1.5]]))[0]
    look = place.local_to_ecef(np.array([[-9.0, 5.5, 4.0]]))[0]
    up = place.local_to_ecef(np.array([[-9.0, -20.0, 2.5]]))[0] - cam
    p.evaluate("""([c, l, u]) => { const C = gsgeo.Cesium, V = (a) => new C.Cartesian3(...a);
        const d = C.Cartesian3.normalize(C.Cartesian3.subtract(V(l), V(c), new C.Cartesian3()),
                                         new C.Cartesian3());
        const r = C.Cartesian3.normalize(C.Cartesian3.cross(d, V(u), new C.Cartesian3()),
                                         new C.Cartesian3());
        gsgeo.viewer.camera.setView({destination: V(c),
            orientation: {direction: d, up: C.Cartesian3.cross(r, d, new C.Cartesian3())}}); }""",
               [cam.tolist(), look.tolist(), up.tolist()])
    # the labels tested from this pose, once the camera rested
    p.wait_for_function("gsgeo.occlusion.checkedPose === gsgeo.occlusion.poseKey()")
    hidden = set(p.evaluate("""() => gsgeo.draw.overlay.labelled()
        .filter((m) => gsgeo.draw.overlay.hiddenKeys.has(m.key)).map((m) => m.id)"""))
    assert {"B3", "B4"} <= hidden, hidden
    assert not {"B1", "B2", "T1"} & hidden, hidden
    # drawn faint: the most opaque pixel about the marker is about 0.3 of a full one
    alpha = p.evaluate(MOST_OPAQUE_JS, ["B3", "B1"])
    assert alpha[0] < 0.4 * 255 and alpha[1] > 0.9 * 255, alpha
    assert not p.errors, p.errors
