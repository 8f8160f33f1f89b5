"""Auto-aim (key A) in a real browser on the demo scene (`gsgeo demo`): for a sample of eight of
the 20 demo markers, one of each kind (the four sculpture corners S1-S4, the ground target G1,
the roof target R1, the eaves corner B4, the pole top T4), one real mouse click on the marker in
one view, A, and Enter (the ID prompt answered with the marker's id) store a point, or auto-aim
declines with a reason (issue 20). The rate over all 20 markers (>= 15 within 3 cm) is a
measurement and lives in `python benchmarks/autoaim.py`, which checks the same thresholds.

Truth: gsgeo.demo.place.truth_points() (the demo's analytic markers carried to ECEF by PROJ),
independent of the viewer. The click goes to the marker's window position as the pinhole of
the contract projects it (AIM_JS, checked against Cesium's pick ray).

The markers are clicked from five camera stations (S1-S4 share one view, as a surveyor measures
every target in sight before moving on): each station costs one or two frames of every splat
(seconds each in SwiftShader), and everything done on a standing camera (the click, auto-aim's
four views, each drawn as one frame of only the splats reaching its crop, Enter) costs none,
which the test checks at every station, with the still the operator sees meanwhile pixel for
pixel the view's last frame.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from gsgeo.demo import place, scene
from gsgeo.demo.project import PROJECT_ID
from tests.e2e.shared import open_demo_page
from tests.e2e.workplace import AIM_JS

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1280, "height": 720}
#: First view of every marker: from outside the building (azimuth away from its centre),
#: elevation (degrees), range (m), look offset (ENU m) so that the marker is off the centre.
ELEVATION, RANGE, OFFSET = 45.0, 12.0, [0.4, -0.3, 0.0]
WITHIN_M, WRONG_M = 0.03, 0.10
#: Camera stations: the marker whose first view (first_view) the station takes, and the markers
#: clicked from it (each in the picture, > 70 px from its edges). The four small targets S1-S4
#: share one view; every other marker is clicked from its own (from another marker's view, at
#: 13-15 m and obliquely, the roof corners B1, B5 and B6 were declined in most views). One
#: marker of each kind: sculpture corners, ground target, roof target, eaves corner, pole top.
STATIONS = [("S1", ["S1", "S2", "S3", "S4"]), ("G1", ["G1"]), ("R1", ["R1"]), ("B4", ["B4"]),
            ("T4", ["T4"])]
#: Of the sample, at least this many stored with >= 3 rays within 3 cm (over all 20 markers
#: the benchmark's threshold is 15; these eight were all stored within 2 cm in its runs).
GOOD_OF_SAMPLE = 7
#: chi-square(3) at 0.95: the truth is inside the stated 95 % ellipsoid below this.
CHI2_3_95 = 7.815


@pytest.fixture(scope="module")
def server(demo_server):
    return demo_server


@pytest.fixture(scope="module")
def page(server, browser):
    yield from open_demo_page(browser, server, PROJECT_ID, VIEWPORT)


def first_view(local) -> float:
    """Azimuth (degrees from north) of the first view: from the building's centre outwards."""
    cx, cy = np.mean(scene.BUILDING_X), np.mean(scene.BUILDING_Y)
    return float(np.degrees(np.arctan2(local[0] - cx, local[1] - cy)))


def auto_aim(page, t: place.TruthPoint, a: dict) -> dict:
    """M, one click on the marker at its window position `a` (AIM_JS), A; then Enter and the id
    when auto-aim found >= 2 views, else Esc. Returns what happened: the auto-aim report and
    the stored point (or None)."""
    page.keyboard.press("m")
    page.wait_for_selector("#measure-panel:not([hidden])")
    page.mouse.click(a["x"], a["y"])
    page.wait_for_function("gsgeo.state.measure.rays.length === 1")
    page.keyboard.press("a")
    page.wait_for_function("gsgeo.state.measure.autoaim && !gsgeo.state.measure.autoaim.running",
                           timeout=600_000, polling=250)
    report = page.evaluate("""() => { const m = gsgeo.state.measure;
        return {...gsgeo.autoaim.last, toRays: gsgeo.autoaim.last.rays,
                rays: m.rays.map((r) => ({auto: !!r.auto, score: r.score ?? null})),
                status: document.querySelector('#status').textContent,
                panel: (document.querySelector('#autoaim-report') || {}).textContent || '',
                thumbs: document.querySelectorAll('#ray-table img.autoaim-thumb').length}; }""")
    if len(report["rays"]) < 3:
        page.keyboard.press("Escape")
        page.wait_for_selector("#measure-panel", state="hidden")
        return {"report": report, "point": None}
    page.wait_for_function("gsgeo.state.measure.solution !== null || gsgeo.state.measure.error !== null",
                           timeout=60_000)
    page.keyboard.press("Enter")
    page.wait_for_selector("#id-prompt:not([hidden])")
    page.fill("#id-prompt-input", t.id)
    with page.expect_response(lambda r: r.url.endswith("/points") and r.request.method == "POST") as resp:
        page.keyboard.press("Enter")
    assert resp.value.status == 201, resp.value.text()
    page.wait_for_selector("#measure-panel", state="hidden")
    return {"report": report, "point": resp.value.json()}


def truth(pid: str) -> place.TruthPoint:
    return next(t for t in place.truth_points() if t.id == pid)


def error_of(point: dict, t: place.TruthPoint) -> float:
    return float(np.linalg.norm(np.asarray(point["result"]["point_ecef"]) - np.asarray(t.ecef)))


def check_report(rep: dict) -> None:
    """Every auto ray shows its thumbnail and score; every declined view is named with its
    reason in the panel; the status line says briefly how many rays were added and how many
    views declined, and what to do next; the four views are all accounted for."""
    assert rep["thumbs"] == sum(1 for ray in rep["rays"] if ray["auto"]), rep
    assert all(ray["score"] is not None for ray in rep["rays"] if ray["auto"]), rep
    whole = rep["text"].startswith("Auto-aim declined")  # before any view: ray 1 itself
    assert len(rep["declined"]) + rep["added"] == 4 or whole, rep
    for reason in rep["declined"]:
        assert reason.startswith("view ") and ": " in reason, reason
        assert reason in rep["panel"] and reason not in rep["text"], rep
    if not whole and rep["added"]:
        declined = f"; {len(rep['declined'])} declined" if rep["declined"] else ""
        assert rep["text"] == (f"Auto-aim added {rep['added']} ray{'s' if rep['added'] > 1 else ''} of 4 "
                               f"views{declined}{' (why: in the panel)' if declined else ''}. "
                               "Review them, then Enter stores the point."), rep
    elif not whole:
        assert "none of the 4 views" in rep["text"] and "another view" in rep["text"], rep
    assert rep["status"].startswith(rep["text"]), rep


#: The scene canvas (WebGL, its drawing buffer kept) or the still over it, as RGBA bytes of a
#: box [x0, y0, w, h] in drawing-buffer pixels.
PIXELS_JS = """([which, box]) => { const src = which === 'still'
    ? document.querySelector('canvas.gsgeo-still') : gsgeo.viewer.scene.canvas;
  const c = document.createElement('canvas'); c.width = box[2]; c.height = box[3];
  const g = c.getContext('2d'); g.drawImage(src, box[0], box[1], box[2], box[3], 0, 0, box[2], box[3]);
  return Array.from(g.getImageData(0, 0, box[2], box[3]).data); }"""


#: The window position (page CSS pixels) of a world point (rendered ECEF) in the present view,
#: and the distance of the pick ray through it from the point (m), as AIM_JS returns them.
WINDOW_JS = """(target) => { const C = Cesium, v = gsgeo.viewer;
  const K = new C.Cartesian3(target[0], target[1], target[2]);
  const win = C.SceneTransforms.worldToWindowCoordinates(v.scene, K);
  const ray = v.camera.getPickRay(win);
  const w = C.Cartesian3.subtract(K, ray.origin, new C.Cartesian3());
  const along = C.Cartesian3.dot(w, ray.direction);
  const perp = C.Cartesian3.subtract(w, C.Cartesian3.multiplyByScalar(ray.direction, along,
                                                                     new C.Cartesian3()), new C.Cartesian3());
  const rect = v.scene.canvas.getBoundingClientRect();
  return {x: rect.left + win.x, y: rect.top + win.y, win: [win.x, win.y],
          canvas: [v.scene.canvas.clientWidth, v.scene.canvas.clientHeight],
          dist: C.Cartesian3.magnitude(perp)};
}"""


#: What a failure needs to tell why the view shows no splats: the camera, the frames, the
#: splats' hold, draw command and sort (CesiumJS 1.145's private state, as render.js reads it).
VIEW_STATE_JS = """() => { const v = gsgeo.viewer, t = gsgeo.state.tileset, p = t && t.gaussianSplatPrimitive;
  const c = v.camera, o = c.positionWC, d = c.directionWC;
  return {camera: [o.x, o.y, o.z, d.x, d.y, d.z],
          frames: gsgeo.renderer.frames, framesOfAll: gsgeo.renderer.framesOfAll,
          settled: gsgeo.renderer.settled(), still: gsgeo.still.shown() !== null,
          releasing: gsgeo.still.releasing !== null, show: !!(t && t.show),
          tilesLoaded: !!(t && t.tilesLoaded),
          numSplats: p ? p._numSplats : null, selected: t ? t.statistics.numberOfPointsSelected : null,
          instanceCount: p && p._drawCommand ? p._drawCommand.instanceCount : null,
          sorter: p ? p._sorterState : null, globeShown: v.scene.globe.show}; }"""


def station(page, lead: place.TruthPoint, ids: list[str]) -> list[dict]:
    """Take the station of marker `lead`, wait until its view is drawn, and measure markers
    `ids` from it by auto-aim; checks that no frame of every splat is drawn meanwhile and that
    the operator sees the view's last frame (the still) throughout. Returns the outcomes."""
    f0 = page.evaluate("gsgeo.renderer.framesOfAll")
    t0 = time.perf_counter()
    view = [first_view(lead.local), ELEVATION, RANGE, OFFSET]
    page.evaluate(AIM_JS, [list(lead.ecef), *view])
    aims = {pid: page.evaluate(WINDOW_JS, list(truth(pid).ecef)) for pid in ids}
    # drawn, and the globe's tiles all loaded: a tile that arrives later asks Cesium for a
    # frame of its own (of every splat), which is the globe's, not the measuring's
    page.wait_for_function(f"gsgeo.still.shown() === null && gsgeo.renderer.framesOfAll > {f0}"
                           " && gsgeo.renderer.settled() && gsgeo.viewer.scene.globe.tilesLoaded",
                           timeout=180_000, polling=200)
    # (and its last frame one of the whole scene, as the operator sees it: the still can be
    # taken, so the click and A draw no frame of every splat)
    page.wait_for_function("gsgeo.renderer.settled() && gsgeo.viewer.scene.globe.tilesLoaded"
                           " && gsgeo.still.ready()", timeout=180_000, polling=200)
    w, h = aims[ids[0]]["canvas"]
    for pid, a in aims.items():
        assert a["dist"] < 1e-5, a  # the projection and Cesium's pick ray agree
        assert 70 < a["win"][0] < w - 70 and 70 < a["win"][1] < h - 70, (pid, a)
    x, y = aims[ids[0]]["win"]
    box = [int(x) - 40, int(y) - 40, 80, 80]
    before = page.evaluate(PIXELS_JS, ["scene", box])
    assert len(set(before)) > 20, (lead.id, page.evaluate(VIEW_STATE_JS), aims)  # the scene is drawn there
    full = page.evaluate("gsgeo.renderer.framesOfAll")
    out = []
    print(f"station {lead.id}: drawn {time.perf_counter() - t0:.1f} s after the camera was set")
    for pid in ids:
        t1 = time.perf_counter()
        r = auto_aim(page, truth(pid), aims[pid])
        print(f"{pid}: {time.perf_counter() - t1:.1f} s, M to stored; A -> rays "
              f"{(r['report'].get('toRays') or float('nan')) / 1000:.1f} s; {r['report']['text']}")
        check_report(r["report"])
        assert not page.errors, page.errors
        out.append({"id": pid, **r})
    # on the standing camera: no frame of every splat, and the still is the view's last frame
    assert page.evaluate("gsgeo.still.shown() !== null")
    assert page.evaluate("gsgeo.renderer.framesOfAll") == full, lead.id
    assert page.evaluate(PIXELS_JS, ["still", box]) == before, lead.id
    return out


def maha2_of(point: dict, t: place.TruthPoint) -> float:
    """Squared Mahalanobis distance of the truth from the stored point under its stated total
    covariance (ECEF)."""
    d = np.asarray(point["result"]["point_ecef"]) - np.asarray(t.ecef)
    cov = np.asarray(point["result"]["cov_ecef_total"], dtype=float).reshape(3, 3)
    return float(d @ np.linalg.solve(cov, d))


def test_one_click_and_a_measure_a_sample_of_every_kind_of_marker(server, page):
    """>= 7 of the 8 sampled markers stored with >= 3 rays within 3 cm of the truth; no stored
    point more than 10 cm off (the others declined, each view with its reason); the stated 95 %
    ellipsoid holds the truth for >= 80 % of the stored points (the manual clicks' figure in
    benchmarks/README.md is 20 of 20); each auto ray stored with its score and the flag."""
    kinds = {pid[0] for _, ids in STATIONS for pid in ids}
    assert kinds == {"S", "G", "R", "B", "T"}, kinds
    results = []
    for lead, ids in STATIONS:
        results += station(page, truth(lead), ids)
    stored = [r for r in results if r["point"] is not None]
    summary = {r["id"]: (round(1000 * error_of(r["point"], truth(r["id"])), 1) if r["point"] else
                         r["report"]["text"]) for r in results}
    print(summary)
    good = [r for r in stored if error_of(r["point"], truth(r["id"])) <= WITHIN_M
            and len(r["point"]["rays"]) >= 3]
    assert len(good) >= GOOD_OF_SAMPLE, summary
    assert all(error_of(r["point"], truth(r["id"])) <= WRONG_M for r in stored), summary
    for r in stored:
        auto = [ray for ray in r["point"]["rays"] if ray.get("auto")]
        assert len(auto) >= 2 and all(isinstance(ray.get("score"), float) for ray in auto), r["point"]["rays"]
    inside = sum(maha2_of(r["point"], truth(r["id"])) < CHI2_3_95 for r in stored)
    assert inside >= 0.8 * len(stored), (inside, len(stored))
