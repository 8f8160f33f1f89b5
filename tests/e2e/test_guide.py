"""The guidance for manual clicks (web/js/guide.js, web/js/views.js) in a real browser on the demo
scene (`gsgeo demo`): the drawn epipolar segments and the predicted pixel agree within 1 px with
an independent pinhole projection (the shared interface's formula, in Python, from the camera
read from the page) of the rays' near/far points and of the marker's truth; the predicted 95 %
ellipse is the 3-D covariance projected through the camera's Jacobian and holds the truth where
the 3-D ellipsoid does; V flies to suggested views from which the marker is in the image; a
click on the sky is warned at once, naming the ray.

The clicks land exactly on a marker's projection (tests/e2e/workplace.py's AIM_JS), so the
splats need not be drawn (they are hidden, for speed): the depth and the views come from the
server's splats.
"""

from __future__ import annotations

import numpy as np
import pytest

from gsgeo.demo import place
from tests.e2e.shared import demo_project_copy, open_demo_page
from tests.e2e.workplace import AIM_JS

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1024, "height": 640}  # small: SwiftShader draws every frame on the CPU
#: The marker measured: a checker target on the open ground, and three views of it
#: (azimuth, elevation in degrees, range m, look offset ENU m) 60-100 degrees apart.
MARKER = "G2"
VIEWS = [(30.0, 40.0, 12.0, [0.8, -0.5, 0.0]), (130.0, 50.0, 10.0, [-0.6, 0.4, 0.0]),
         (250.0, 35.0, 14.0, [0.5, 0.6, 0.0])]
#: The guide's colours (web/js/guide.js STYLE): the segment and the predicted cross.
SEGMENT_RGB = (0xFF, 0x4F, 0xD8)
PREDICTED_RGB = (0x39, 0xFF, 0x14)
#: Scales of the 95 % regions: 2-D (chi-square 2 dof) and 3-D (3 dof).
K2 = float(np.sqrt(5.991))
K3 = 2.7955

#: The camera as the shared interface's Camera object, the modelMatrix, and the guide, read
#: together (the same frame).
READ_JS = """() => { const v = gsgeo.viewer, c = v.camera, a = (p) => [p.x, p.y, p.z];
  return {camera: {position: a(c.positionWC), direction: a(c.directionWC), up: a(c.upWC),
                   fovy: c.frustum.fovy, width: v.scene.canvas.clientWidth,
                   height: v.scene.canvas.clientHeight},
          mm: gsgeo.Cesium.Matrix4.toArray(gsgeo.tileset.modelMatrix), guide: gsgeo.guide}; }"""

#: RGB of the overlay canvas at CSS pixels [[x, y], ...] (the last drawn frame).
OVERLAY_RGB_JS = """(pts) => { const c = document.querySelector('canvas.gsgeo-overlay');
  const g = c.getContext('2d'), dpr = window.devicePixelRatio || 1;
  return pts.map(([x, y]) => Array.from(
    g.getImageData(Math.floor(x * dpr), Math.floor(y * dpr), 1, 1).data)); }"""


#: This module's copy of the demo project (the demo scene, EPSG:27700, the truth as check points).
PID = "demo-guide"


@pytest.fixture(scope="module")
def server(demo_server):
    demo_project_copy(demo_server, PID)
    return demo_server


@pytest.fixture(scope="module")
def page(server, browser):
    # the splats are not drawn: SwiftShader takes seconds a frame for them, and nothing
    # here depends on them (the server answers /depth and /views from the tiles' files)
    yield from open_demo_page(browser, server, PID, VIEWPORT, draw_splats=False)


@pytest.fixture()
def measuring(page):
    """A new point being measured (M); cancelled afterwards."""
    page.keyboard.press("m")
    page.wait_for_selector("#measure-panel:not([hidden])")
    yield page
    page.keyboard.press("Escape")
    page.wait_for_function("gsgeo.state.measure === null")


def truth_ecef(pid: str = MARKER) -> np.ndarray:
    return np.array(next(t.ecef for t in place.truth_points() if t.id == pid))


def project(cam: dict, p) -> np.ndarray:
    """Window position of rendered-ECEF point p: the shared interface's pinhole."""
    pos, d, up = (np.asarray(cam[k], float) for k in ("position", "direction", "up"))
    right = np.cross(d, up)
    f = cam["height"] / (2 * np.tan(cam["fovy"] / 2))
    v = np.asarray(p, float) - pos
    c = v @ d
    assert c > 0, "behind the camera"
    return np.array([cam["width"] / 2 + f * (v @ right) / c, cam["height"] / 2 - f * (v @ up) / c])


def jacobian(cam: dict, p) -> np.ndarray:
    """d(window x, y) / d(point), 2x3, by central differences of `project` (1 mm steps)."""
    return np.stack([(project(cam, p + e) - project(cam, p - e)) / 2e-3
                     for e in np.eye(3) * 1e-3], axis=1)


def rendered(mm16, p) -> np.ndarray:
    m = np.asarray(mm16, float).reshape(4, 4).T  # column-major
    return m[:3, :3] @ np.asarray(p, float) + m[:3, 3]


def aim(page, view) -> dict:
    az, el, rng, off = view
    a = page.evaluate(AIM_JS, [truth_ecef().tolist(), az, el, rng, off])
    assert a["dist"] < 1e-5, a
    return a


def depth_at(a: dict):
    """Predicate for page.expect_response: the /depth answer of the ray through the clicked
    pixel (not the navigation's, at the view's centre for the scale bar)."""
    def pred(r) -> bool:
        if not r.url.endswith("/depth"):
            return False
        px = ((r.request.post_data_json or {}).get("ray") or {}).get("pixel")
        return px is not None and abs(px[0] - a["win"][0]) <= 1 and abs(px[1] - a["win"][1]) <= 1
    return pred


def click(page, view, n: int) -> dict:
    """Aim at the marker from `view`, click it; wait for ray n and its depth answer."""
    a = aim(page, view)
    with page.expect_response(depth_at(a)) as resp:
        page.mouse.click(a["x"], a["y"])
    assert resp.value.status == 200, resp.value.text()
    page.wait_for_function(f"gsgeo.state.measure.rays.length === {n}")
    return resp.value.json()


def settled(page) -> dict:
    """The camera, modelMatrix and guide once one more frame has been drawn (and the guide
    painted on the overlay after it)."""
    page.evaluate("""() => new Promise((ok) => { const s = gsgeo.viewer.scene;
        const off = s.postRender.addEventListener(() => { off(); ok(); }); s.requestRender(); })""")
    return page.evaluate(READ_JS)


def near_far_points(ray: dict, depth: dict) -> tuple[np.ndarray, np.ndarray]:
    o = np.asarray(ray["origin"], float)
    d = np.asarray(ray["direction"], float)
    d /= np.linalg.norm(d)
    return o + depth["near_m"] * d, o + depth["far_m"] * d


def colour_near(rgba_list, rgb, tol: float = 40.0) -> bool:
    return any(px[3] > 200 and np.all(np.abs(np.array(px[:3]) - rgb) < tol) for px in rgba_list)


def check_segments(page, seen: dict, rays: list[dict], depths: list[dict]) -> None:
    """Every ray's drawn segment ends are its near/far points projected (1 px), the marker's
    truth projects onto the segment, and the segment is drawn in its colour."""
    cam = seen["camera"]
    t_px = project(cam, truth_ecef())
    assert len(seen["guide"]["epipolar"]) == len(rays), seen["guide"]
    for i, (ray, depth) in enumerate(zip(rays, depths, strict=True)):
        entry = seen["guide"]["epipolar"][i]
        assert entry["ray"] == i and entry["segment"] is not None, entry
        near, far = near_far_points(ray, depth)
        drawn = np.asarray(entry["segment"], float)
        expect = np.stack([project(cam, near), project(cam, far)])
        assert np.all(np.abs(drawn - expect) < 1.0), (i, drawn, expect)
        # the truth is on the segment: within 1 px of its line, between its ends
        a, b = expect
        ab = b - a
        s = float((t_px - a) @ ab / (ab @ ab))
        off = np.linalg.norm(a + s * ab - t_px)
        assert off < 1.0 and -1e-3 <= s <= 1 + 1e-3, (i, off, s, depth)
        # drawn: the tick across the near end has the segment's colour
        n = np.array([-ab[1], ab[0]]) / np.linalg.norm(ab)
        tick = [(a + k * n).tolist() for k in (-6, -5, -4, 4, 5, 6)]
        assert colour_near(page.evaluate(OVERLAY_RGB_JS, tick), SEGMENT_RGB), (i, tick)


def test_epipolar_segments_and_predicted_pixel_agree_with_an_independent_projection(measuring):
    page = measuring
    truth = truth_ecef()
    # ray 1: its depth answer places the marker within its near..far segment
    d1 = click(page, VIEWS[0], 1)
    assert d1["hit"] is True and d1["near_m"] <= d1["depth_m"] <= d1["far_m"], d1
    rays = page.evaluate("gsgeo.state.measure.rays")
    o1 = np.asarray(rays[0]["origin"])
    assert d1["near_m"] - 0.05 <= np.linalg.norm(truth - o1) <= d1["far_m"] + 0.05, d1
    # in view 2, before the click: ray 1's segment and the depth hint
    aim(page, VIEWS[1])
    seen = settled(page)
    check_segments(page, seen, rays, [d1])
    hint = seen["guide"]["depth"]
    assert hint is not None and abs(hint["depth_m"] - d1["depth_m"]) < 1e-9, hint
    assert seen["guide"]["predicted"] is None

    # ray 2, then view 3: both segments, the predicted pixel and its ellipse
    d2 = click(page, VIEWS[1], 2)
    assert d2["hit"] is True, d2
    page.wait_for_function("gsgeo.state.measure.solution !== null")
    m = page.evaluate("""() => { const m = gsgeo.state.measure;
        return {rays: m.rays, solution: m.solution}; }""")
    aim(page, VIEWS[2])
    seen = settled(page)
    cam = seen["camera"]
    check_segments(page, seen, m["rays"], [d1, d2])
    pred = seen["guide"]["predicted"]
    assert pred is not None, seen["guide"]
    t_px = project(cam, truth)
    assert np.linalg.norm(np.asarray(pred["pixel"]) - t_px) < 1.0, (pred, t_px)
    p = rendered(seen["mm"], m["solution"]["point_ecef"])
    assert np.linalg.norm(np.asarray(pred["pixel"]) - project(cam, p)) < 1e-3

    # the ellipse: the 3-D covariance through the camera's Jacobian, at the 2-D 95 % scale
    lin = np.asarray(seen["mm"], float).reshape(4, 4).T[:3, :3]
    cov3 = lin @ np.asarray(m["solution"]["cov_ecef"], float) @ lin.T
    jac = jacobian(cam, p)
    cov2 = jac @ cov3 @ jac.T
    w, v = np.linalg.eigh(cov2)
    axes = K2 * np.sqrt(w[::-1])
    ell = pred["ellipse"]
    assert np.allclose(ell["axes"], axes, rtol=0.01, atol=0.01), (ell, axes)
    assert np.allclose(ell["center"], pred["pixel"])
    major = v[:, 1]
    drawn_major = np.array([np.cos(np.radians(ell["angle_deg"])), np.sin(np.radians(ell["angle_deg"]))])
    if axes[0] > 1.05 * axes[1]:
        assert abs(abs(drawn_major @ major) - 1) < 1e-3, (ell, major)
    # the truth: inside the 3-D 95 % ellipsoid, so its projection is inside the drawn ellipse
    e3 = truth - p
    r3 = float(np.sqrt(e3 @ np.linalg.solve(cov3, e3)))
    e2 = t_px - np.asarray(pred["pixel"])
    rot = np.array([drawn_major, [-drawn_major[1], drawn_major[0]]])
    u = rot @ e2
    r2_drawn = float(np.hypot(u[0] / ell["axes"][0], u[1] / ell["axes"][1])) * K2
    r2 = float(np.sqrt(e2 @ np.linalg.solve(cov2, e2)))
    assert abs(r2_drawn - r2) < 0.02 * max(r2, 0.1), (r2_drawn, r2)
    assert r2 <= r3 + 1e-6, (r2, r3)  # a projection never moves the truth farther out
    assert r3 <= K3, r3
    assert r2_drawn <= K2 or r3 > K2, (r2_drawn, r3)
    # drawn: the predicted cross in its colour, beside the target: within 4.5 px of the
    # predicted pixel nothing is drawn (rays, segments, the ellipse all pass through it)
    arm = [(np.asarray(pred["pixel"]) + [k, dy]).tolist() for k in (9, 12, 15) for dy in (-1, 0, 1)]
    assert colour_near(page.evaluate(OVERLAY_RGB_JS, arm), PREDICTED_RGB), arm
    centre = [(np.asarray(pred["pixel"]) + [dx, dy]).tolist() for dx in range(-4, 5)
              for dy in range(-4, 5) if np.hypot(dx, dy) <= 3.5]
    assert all(px[3] == 0 for px in page.evaluate(OVERLAY_RGB_JS, centre)), centre
    ring = [(np.asarray(pred["pixel"]) + [9 * np.cos(a), 9 * np.sin(a)]).tolist()
            for a in np.linspace(0, 2 * np.pi, 24, endpoint=False)]
    assert any(px[3] > 0 for px in page.evaluate(OVERLAY_RGB_JS, ring)), ring  # drawn around it
    assert page.errors == [], page.errors


def wait_camera_at(page, position, direction=None, tol_m: float = 0.01, tol_dir: float = 1e-6) -> None:
    """Wait until the camera is within tol_m of position (ECEF, m) and, if given, its view
    direction within tol_dir of direction: a flight's last frames still turn the camera
    after its position has (nearly) arrived."""
    page.wait_for_function("""([p, d, tol, tolDir]) => { const cam = gsgeo.viewer.camera;
        const c = cam.positionWC, v = cam.directionWC;
        if (Math.hypot(c.x - p[0], c.y - p[1], c.z - p[2]) >= tol) return false;
        if (d === null) return true;
        return Math.max(Math.abs(v.x - d[0]), Math.abs(v.y - d[1]), Math.abs(v.z - d[2])) < tolDir; }""",
                           arg=[position, direction, tol_m, tol_dir], timeout=20_000)


def test_v_flies_to_suggested_views_from_which_the_marker_is_seen(measuring):
    page = measuring
    click(page, VIEWS[0], 1)
    with page.expect_response(lambda r: r.url.endswith("/views")) as resp:
        page.keyboard.press("v")
    assert resp.value.status == 200, resp.value.text()
    views = resp.value.json()["views"]
    body = resp.value.request.post_data_json
    assert len(views) >= 2 and body["k"] >= 2, views
    assert len(body["rays"]) == 1 and len(body["point_ecef"]) == 3, body
    positions = []
    for k in range(2):  # V flew to the first view; V again flies to the next
        if k:
            page.keyboard.press("v")
        page.wait_for_function("(t) => document.querySelector('#messages').innerText.includes(t)",
                               arg=f"Suggested view {k + 1} of {len(views)}", timeout=5_000)
        target = views[k]["camera"]
        wait_camera_at(page, target["position"], target["direction"])
        cam = settled(page)["camera"]
        assert np.allclose(cam["direction"], target["direction"], atol=1e-6), (cam, target)
        x, y = project(cam, truth_ecef())
        assert 0 <= x <= cam["width"] and 0 <= y <= cam["height"], (x, y, cam)
        positions.append(cam["position"])
    assert np.linalg.norm(np.subtract(*positions)) > 1.0  # two different viewpoints


def test_a_click_on_the_sky_is_warned_at_once_naming_the_ray(measuring):
    page = measuring
    # the camera under a point 40 m above the marker, looking up at it: sky only
    az, _, _, _ = VIEWS[0]
    up_target = (truth_ecef() + 40.0 * truth_ecef() / np.linalg.norm(truth_ecef())).tolist()
    a = page.evaluate(AIM_JS, [up_target, az, -15.0, 30.0, [0.0, 0.0, 0.0]])
    with page.expect_response(depth_at(a)) as resp:
        page.mouse.click(a["x"], a["y"])
    assert resp.value.json()["hit"] is False, resp.value.json()
    text = "Ray 1 hits no splat (sky?) — Backspace removes it"
    page.wait_for_function("(t) => document.querySelector('#messages').innerText.includes(t)", arg=text,
                           timeout=5_000)
    row = page.inner_text("#ray-table tbody tr:nth-child(1)")
    assert "hits no splat (sky?)" in row, row
    assert "Ray 1 hits no splat" in page.inner_text("#status")
    # a good second ray: the live solution still names ray 1
    click(page, VIEWS[1], 2)
    page.wait_for_function("gsgeo.state.measure.solution !== null || gsgeo.state.measure.error !== null")
    live = page.inner_text("#live-solution")
    assert "Ray 1 hits no splat (sky?)" in live, live
    assert "press Enter to store it" not in page.inner_text("#status")
    # Backspace twice leaves no ray and no warning
    page.keyboard.press("Backspace")
    page.keyboard.press("Backspace")
    page.wait_for_function("gsgeo.state.measure.rays.length === 0")
    assert "hits no splat" not in page.inner_text("#live-solution")
