"""Auto-aim (key A) in a real browser on the demo scene (`gsgeo demo`): for each of the 20
markers one real mouse click on it from one view, A, and Enter (the ID prompt answered with the
marker's id) store a point, or auto-aim declines with a reason.

Truth: gsgeo.demo.place.truth_points() (the demo's analytic markers carried to ECEF by PROJ),
independent of the viewer. The click goes to the marker's window position as the pinhole of
the contract projects it (AIM_JS, checked against Cesium's pick ray).

What is asserted (issue 20, "Done when"):
- at least 15 of the 20 markers are stored with >= 3 rays (the click and >= 2 auto rays)
  within 3 cm (3-D) of the truth;
- no marker is stored more than 10 cm off: where auto-aim does not find >= 2 views it says
  why (every declined view with its reason) and nothing is stored;
- the stated 95 % ellipsoids hold the truth in the proportion they promise, as manual clicks'
  do: the count of stored points whose 95 % ellipsoid (Mahalanobis distance² <= chi²₃(0.95))
  contains the truth is not below what a true 95 % coverage makes 99 % likely (binomial).
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

from gsgeo.demo import place, scene
from gsgeo.demo.project import PROJECT_ID
from tests.e2e.workplace import AIM_JS, ARTIFACTS, CESIUM_JS, CHROMIUM, CHROMIUM_ARGS, REPO

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1280, "height": 720}
#: First view of every marker: from outside the building (azimuth away from its centre),
#: elevation (degrees), range (m), look offset (ENU m) so that the marker is off the centre.
ELEVATION, RANGE, OFFSET = 45.0, 12.0, [0.4, -0.3, 0.0]
WITHIN_M, WRONG_M, MIN_FOUND = 0.03, 0.10, 15
CHI2_3_95 = float(stats.chi2.ppf(0.95, 3))
#: Why the test is expected to fail for now (the matcher is the server's, gsgeo.aim.match).
MATCHER_SHORT = ("the server's matcher (POST /api/match) finds >= 2 of the 4 views for too few markers: "
                 "3 of 20 in this test's run of 2026-11-25 (R1, S1, S4), 7 of 20 offline with the "
                 "matcher of 2bcc396 (benchmarks/README.md); 15 are needed")


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    if not CHROMIUM.exists():
        pytest.skip("/usr/bin/chromium is not installed")
    if importlib.util.find_spec("playwright") is None:
        pytest.skip("Playwright for Python is not installed")
    if not CESIUM_JS.is_file():
        pytest.skip("cesium is not installed in web/node_modules (run npm ci in web/)")
    from tests.servertools import start_server

    data = tmp_path_factory.mktemp("autoaim") / "data"
    r = subprocess.run([sys.executable, "-m", "gsgeo", "demo", "--data", str(data), "--no-serve"],
                       cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    proc, base = start_server(data)
    try:
        yield base
    finally:
        proc.terminate()
        proc.communicate(timeout=10)


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


# ~55 min on the loaded 2-core machine: one full frame of the splats per view (benchmarks/README.md)
@pytest.mark.slow
@pytest.mark.xfail(strict=False, reason=MATCHER_SHORT)
def test_one_click_and_a_store_the_demo_markers(server, page):
    results = {}
    for t in place.truth_points():
        r = auto_aim(page, t)
        pt = r["point"]
        if pt is not None:
            res = pt["result"]
            e = np.asarray(res["point_ecef"]) - np.asarray(t.ecef)
            r["error_m"] = float(np.linalg.norm(e))
            r["mahalanobis2"] = float(e @ np.linalg.solve(np.asarray(res["cov_ecef"]), e))
            r["n_rays"] = len(pt["rays"])
            r["n_auto"] = sum(1 for ray in pt["rays"] if ray.get("auto"))
        results[t.id] = r
    ARTIFACTS.mkdir(exist_ok=True)
    (ARTIFACTS / "autoaim_demo.json").write_text(json.dumps(
        {k: {kk: vv for kk, vv in v.items() if kk != "point"} for k, v in results.items()}, indent=1))
    summary = {k: (round(v["error_m"], 4) if "error_m" in v else v["report"]["text"])
               for k, v in results.items()}

    stored = {k: v for k, v in results.items() if v["point"] is not None}
    found = [k for k, v in stored.items()
             if v["n_rays"] >= 3 and v["n_auto"] >= 2 and v["error_m"] <= WITHIN_M]
    assert len(found) >= MIN_FOUND, summary
    wrong = [k for k, v in stored.items() if v["error_m"] > WRONG_M]
    assert not wrong, summary
    for k, v in results.items():
        rep = v["report"]
        # every auto ray shows its thumbnail and score; every declined view is named with a reason
        assert rep["thumbs"] == sum(1 for ray in rep["rays"] if ray["auto"]), (k, rep)
        assert all(ray["score"] is not None for ray in rep["rays"] if ray["auto"]), (k, rep)
        whole = rep["text"].startswith("Auto-aim declined")  # before any view: ray 1 itself
        assert len(rep["declined"]) + rep["added"] == 4 or whole, (k, rep)
        for reason in rep["declined"]:
            assert reason.startswith("view ") and ": " in reason, (k, reason)
            assert reason in rep["panel"] and reason in rep["status"], (k, rep)
        if v["point"] is None:
            assert rep["declined"] or whole, (k, rep)
    # coverage of the stated 95 % ellipsoids, as manual clicks promise it
    n = len(stored)
    inside = sum(1 for v in stored.values() if v["mahalanobis2"] <= CHI2_3_95)
    least = int(stats.binom.ppf(0.01, n, 0.95))
    assert inside >= least, ({k: round(v["mahalanobis2"], 1) for k, v in stored.items()}, least)
    assert not page.errors, page.errors
