"""Auto-aim (key A) in a real browser on the demo scene (`gsgeo demo`): one real mouse click on
a marker from one view, A, and Enter (the ID prompt answered with the marker's id) store a
point, or auto-aim declines with a reason.

Truth: gsgeo.demo.place.truth_points() (the demo's analytic markers carried to ECEF by PROJ),
independent of the viewer. The click goes to the marker's window position as the pinhole of
the contract projects it (AIM_JS, checked against Cesium's pick ray).

Two markers, for the suite's time (each A draws four views in SwiftShader, each one frame of
the splats that reach its crop: 5-20 s a marker on this machine): a ground target (G1), which
auto-aim finds in its suggested views and stores within 3 cm with >= 3 rays, and a pole top
(T1), where it must not store a point more than 10 cm off and names every declined view with
its reason. The sweep over all 20 markers (issue 20's ">= 15 of 20") is benchmarks/autoaim.py's,
with its figures in benchmarks/README.md (2026-11-28: 17 of 20 stored within 3 cm with >= 3
rays; T1, T2 and T3 declined with their reasons).
"""

from __future__ import annotations

import numpy as np
import pytest

from gsgeo.demo import place, scene
from gsgeo.demo.project import PROJECT_ID
from tests.e2e.demoserver import demo_server
from tests.e2e.workplace import AIM_JS, CHROMIUM, CHROMIUM_ARGS

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1280, "height": 720}
#: First view of every marker: from outside the building (azimuth away from its centre),
#: elevation (degrees), range (m), look offset (ENU m) so that the marker is off the centre.
ELEVATION, RANGE, OFFSET = 45.0, 12.0, [0.4, -0.3, 0.0]
WITHIN_M, WRONG_M = 0.03, 0.10


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    yield from demo_server(tmp_path_factory, "autoaim")


@pytest.fixture(scope="module")
def page(server):
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        pg = b.new_page(viewport=VIEWPORT)
        errors: list[str] = []
        pg.on("console", lambda m: m.type == "error" and errors.append(m.text))
        pg.on("pageerror", lambda e: errors.append(f"page error: {e}"))
        pg.goto(f"{server}/?scene=demo&project={PROJECT_ID}")
        pg.wait_for_function("window.gsgeo && window.gsgeo.ready === true", timeout=90_000)
        pg.wait_for_function("gsgeo.tileset && gsgeo.tilesReady && gsgeo.tileset.tilesLoaded",
                             timeout=120_000)
        pg.errors = errors
        yield pg
        b.close()


def first_view(local) -> float:
    """Azimuth (degrees from north) of the first view: from the building's centre outwards."""
    cx, cy = np.mean(scene.BUILDING_X), np.mean(scene.BUILDING_Y)
    return float(np.degrees(np.arctan2(local[0] - cx, local[1] - cy)))


def auto_aim(page, t: place.TruthPoint) -> dict:
    """M, one click on the marker, A; then Enter and the id when auto-aim found >= 2 views,
    else Esc. Returns what happened: the auto-aim report and the stored point (or None)."""
    page.keyboard.press("m")
    page.wait_for_selector("#measure-panel:not([hidden])")
    a = page.evaluate(AIM_JS, [list(t.ecef), first_view(t.local), ELEVATION, RANGE, OFFSET])
    assert a["dist"] < 1e-5, a  # the projection and Cesium's pick ray agree
    w, h = a["canvas"]
    assert 0 < a["win"][0] < w and 0 < a["win"][1] < h, a
    page.mouse.click(a["x"], a["y"])
    page.wait_for_function("gsgeo.state.measure.rays.length === 1")
    page.keyboard.press("a")
    page.wait_for_function("gsgeo.state.measure.autoaim && !gsgeo.state.measure.autoaim.running",
                           timeout=600_000, polling=250)
    report = page.evaluate("""() => { const m = gsgeo.state.measure;
        return {...gsgeo.autoaim.last, rays: m.rays.map((r) => ({auto: !!r.auto, score: r.score ?? null})),
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
    reason in the panel and the status line; the four views are all accounted for."""
    assert rep["thumbs"] == sum(1 for ray in rep["rays"] if ray["auto"]), rep
    assert all(ray["score"] is not None for ray in rep["rays"] if ray["auto"]), rep
    whole = rep["text"].startswith("Auto-aim declined")  # before any view: ray 1 itself
    assert len(rep["declined"]) + rep["added"] == 4 or whole, rep
    for reason in rep["declined"]:
        assert reason.startswith("view ") and ": " in reason, reason
        assert reason in rep["panel"] and reason in rep["status"], rep


def test_one_click_and_a_store_a_ground_target_within_3_cm(server, page):
    t = truth("G1")
    r = auto_aim(page, t)
    rep, pt = r["report"], r["point"]
    check_report(rep)
    assert pt is not None, rep["text"]
    auto = [ray for ray in pt["rays"] if ray.get("auto")]
    assert len(pt["rays"]) >= 3 and len(auto) >= 2, pt["rays"]
    assert all(isinstance(ray.get("score"), float) for ray in auto), auto
    assert error_of(pt, t) <= WITHIN_M, (error_of(pt, t), rep["text"])
    assert not page.errors, page.errors


def test_a_pole_top_is_declined_with_reasons_or_stored_close(server, page):
    """A pole top: the patch around it is mostly background, which changes between views;
    auto-aim may decline, but never stores a point more than 10 cm off."""
    t = truth("T1")
    r = auto_aim(page, t)
    rep, pt = r["report"], r["point"]
    check_report(rep)
    if pt is None:
        assert rep["declined"] or rep["text"].startswith("Auto-aim declined"), rep
    else:
        assert error_of(pt, t) <= WRONG_M, (error_of(pt, t), rep["text"])
    assert not page.errors, page.errors
