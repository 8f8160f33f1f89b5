"""Auto-aim in the viewer (key A), end to end in headless Chromium on the demo scene (drawing with
the software renderer the browser tests use: Mesa's llvmpipe, or SwiftShader with
GSGEO_TEST_GL=swiftshader, as in the figures before 2026-11-28 15:00 UTC in benchmarks/README.md):
the time from A to the auto rays and where it goes, and the operator's clicks per point with
the 3-D error of each method (the accuracy experiment's "auto" row).

    python benchmarks/autoaim.py [--data DIR] [--markers G1,B1,...] [--manual] [--out FILE]
                                 [--at-once | --a-at-once] [--web DIR] [--aim-error-px PX]

For each marker (default all 20 of gsgeo.demo.place.truth_points()): M, one real mouse click on
the marker from one view (45 degrees up, 12 m, from outside the building) once that view is
drawn (--at-once: as soon as the camera is set, so A also waits for the view's own frames), A
once the frames the click asked (its ray, the guide) are drawn, as an operator who sees the ray
drawn before reaching for the key (--a-at-once: right after the click, so that A also waits for
the click's own frames, each of every splat); the page's window.gsgeo.autoaim.last gives the
instants (ms from A) of the depth answer, the reference crop, the suggested views, each view
drawn and matched, and the rays added. With >= 2 auto rays the point is stored (Enter, its
id); its 3-D error against the truth is recorded.
--manual also measures each marker by hand: three clicks from three views (the workplace
tests' procedure), then Enter. The figures are printed and, with --out, written as JSON.
--web serves the viewer from another web/ directory (e.g. an older commit's, for A/B runs).
--aim-error-px PX clicks the first ray PX pixels off the marker's exact pixel, in a direction
drawn at random (seeded by the marker id), as a person aims: what auto-aim's stated precision
must then hold (gsgeo.solve.sharedaim).
With all 20 markers it checks the rate the suite's old 20-marker sweep asserted (>= 15 within
3 cm with >= 3 rays, none stored > 10 cm off, the 95 % ellipsoid holding >= 80 % of the stored
points) and exits 1 when one is not met; tests/e2e/test_autoaim.py keeps a sample of eight.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gsgeo.demo import place, scene  # noqa: E402
from gsgeo.demo.project import PROJECT_ID  # noqa: E402
from tests.e2e.workplace import AIM_JS, CHROMIUM, CHROMIUM_ARGS  # noqa: E402
from tests.servertools import start_server  # noqa: E402

VIEWPORT = {"width": 1280, "height": 720}
ELEVATION, RANGE, OFFSET = 45.0, 12.0, [0.4, -0.3, 0.0]


def outward(local) -> float:
    cx, cy = np.mean(scene.BUILDING_X), np.mean(scene.BUILDING_Y)
    return float(np.degrees(np.arctan2(local[0] - cx, local[1] - cy)))


FINISH_JS = """() => { const c = document.createElement('canvas'); c.width = c.height = 1;
    const g = c.getContext('2d'); g.drawImage(gsgeo.viewer.scene.canvas, 0, 0, 1, 1);
    g.getImageData(0, 0, 1, 1); }"""
#: Whether a click waits for its view to be drawn (--at-once: no, as in the first version).
SETTLE = True
#: Whether A waits for the click's frames (the ray and the guide drawn); not with --a-at-once.
A_SETTLE = True
#: How far (CSS px) auto-aim's first click lands off the marker's exact pixel (--aim-error-px).
AIM_ERROR_PX = 0.0


def click(page, t, az: float, el: float, rng: float, off, miss_px: float = 0.0) -> None:
    """Set the camera, wait until the view is drawn (an operator sees the feature before
    clicking it), click the marker's window position (``miss_px`` off it, in a direction drawn
    from the marker's id)."""
    f0 = page.evaluate("gsgeo.renderer.frames")
    t0 = time.perf_counter()
    a = page.evaluate(AIM_JS, [list(t.ecef), az, el, rng, off])
    if SETTLE:
        drawn(page, f0)
        print(f"{t.id}: the view drawn {time.perf_counter() - t0:.1f} s after the camera was set",
              flush=True)
    angle = np.random.default_rng(sum(map(ord, t.id))).uniform(0.0, 2 * np.pi)
    page.mouse.click(a["x"] + miss_px * np.cos(angle), a["y"] + miss_px * np.sin(angle))


#: The renderer's and the splat primitive's state, printed when a view never settles.
STATE_JS = """() => { const r = gsgeo.renderer, t = gsgeo.tileset, p = t && t.gaussianSplatPrimitive,
    C = Cesium, cam = gsgeo.viewer.camera;
    const last = p && p._hasLastSteadySortCameraPosition ? {
        moved_m: C.Cartesian3.distance(cam.positionWC, p._lastSteadySortCameraPosition),
        turned_deg: C.Math.toDegrees(C.Cartesian3.angleBetween(cam.directionWC,
                                                               p._lastSteadySortCameraDirection))} : null;
    return {frames: r.frames, pending: r.pending, busy: r.busy(), moving: r.moving,
            sorterState: p && p._sorterState, sorterPromise: !!(p && p._sorterPromise),
            pendingSnapshot: !!(p && p._pendingSnapshot), rebuild: !!(p && p._needsSnapshotRebuild),
            dirty: !!(p && p._dirty), numSplats: p && p._numSplats,
            selected: t && t.statistics.numberOfPointsSelected, tilesLoaded: t && t.tilesLoaded,
            instanceCount: p && p._drawCommand ? p._drawCommand.instanceCount : null,
            lastSortFrame: p && p._lastSteadySortFrameNumber,
            frameNumber: gsgeo.viewer.scene.frameState.frameNumber,
            lastSort: last}; }"""


def drawn(page, f0: int) -> None:
    """Wait until a frame after frame count `f0` is drawn and no more are asked or needed."""
    # (an older viewer, --web, has no settled(): no frame asked and none needed)
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    try:
        page.wait_for_function(f"gsgeo.renderer.frames > {f0} && (gsgeo.renderer.settled ? "
                               "gsgeo.renderer.settled() : gsgeo.renderer.pending === 0 "
                               "&& !gsgeo.renderer.busy())", timeout=90_000, polling=200)
    except PlaywrightTimeout:
        print(f"not settled: {json.dumps(page.evaluate(STATE_JS))}", flush=True)
        raise
    # and drawn: a read of the canvas waits for the frames the page has sent to the GPU
    page.evaluate(FINISH_JS)


def store(page, t) -> dict:
    page.wait_for_function("gsgeo.state.measure.solution !== null || gsgeo.state.measure.error !== null",
                           timeout=120_000)
    page.keyboard.press("Enter")
    t0 = time.perf_counter()
    page.wait_for_selector("#id-prompt:not([hidden])", timeout=120_000)
    print(f"{t.id}: the ID prompt {time.perf_counter() - t0:.1f} s after Enter", flush=True)
    page.fill("#id-prompt-input", t.id)
    with page.expect_response(lambda r: r.url.endswith("/points") and r.request.method == "POST") as resp:
        page.keyboard.press("Enter")
    page.wait_for_selector("#measure-panel", state="hidden")
    return resp.value.json()


def error_of(pt: dict, t) -> float:
    return float(np.linalg.norm(np.asarray(pt["result"]["point_ecef"]) - np.asarray(t.ecef)))


def maha2_of(pt: dict, t) -> float:
    """Squared Mahalanobis distance of the truth from the stored point under its stated total
    covariance (ECEF): inside the 95 % ellipsoid when below chi2(3, 0.95) = 7.81."""
    d = np.asarray(pt["result"]["point_ecef"]) - np.asarray(t.ecef)
    cov = np.asarray(pt["result"]["cov_ecef_total"], dtype=float).reshape(3, 3)
    return float(d @ np.linalg.solve(cov, d))


def summary(r: dict) -> str:
    """One line of auto-aim's instants (s from A) and outcome."""
    tm = r["timings"]
    views = " ".join(f"v{v['view']} drawn {v['drawn'] / 1000:.1f} s ({v['frames']} frames"
                     + (f", {v['splats']} splats" if "splats" in v else "")
                     + f") matched {v.get('matched', 0) / 1000:.1f} s" for v in tm.get("views", []))
    sec = {k: tm.get(k, float("nan")) / 1000 for k in ("rays", "depth", "reference", "suggested")}
    return (f"A -> rays {sec['rays']:.1f} s (wall {r['wall_s']:.1f} s); depth {sec['depth']:.2f} s, "
            f"reference {sec['reference']:.1f} s, views {sec['suggested']:.1f} s; {views}; "
            f"{tm['added']} auto rays; ray 1 snapped {tm.get('snap_px', 0):.2f} px")


def auto_point(page, t) -> dict:
    start = time.perf_counter()
    page.keyboard.press("m")
    page.wait_for_selector("#measure-panel:not([hidden])")
    f0 = page.evaluate("gsgeo.renderer.frames")
    click(page, t, outward(t.local), ELEVATION, RANGE, OFFSET, AIM_ERROR_PX)
    page.wait_for_function("gsgeo.state.measure.rays.length === 1")
    if A_SETTLE:  # the ray and the guide drawn after the click before A
        drawn(page, f0)
    t0 = time.perf_counter()
    page.keyboard.press("a")
    page.wait_for_function("gsgeo.state.measure.autoaim && !gsgeo.state.measure.autoaim.running",
                           timeout=900_000, polling=100)
    wall = time.perf_counter() - t0
    last = page.evaluate("gsgeo.autoaim.last")
    out = {"id": t.id, "wall_s": wall, "timings": last, "clicks": 1}
    print(f"{t.id}: {summary(out)}", flush=True)
    if last["added"] >= 2:
        pt = store(page, t)
        out["error_m"], out["maha2"] = error_of(pt, t), maha2_of(pt, t)
        out["rays"] = len(pt["rays"])
    else:
        page.keyboard.press("Escape")
        page.wait_for_selector("#measure-panel", state="hidden")
    out["point_s"] = time.perf_counter() - start
    print(f"{t.id}: {out['point_s']:.1f} s for the point, M to stored (or Esc)", flush=True)
    return out


def manual_point(page, t) -> dict:
    page.keyboard.press("m")
    page.wait_for_selector("#measure-panel:not([hidden])")
    az = outward(t.local)
    views = [(az, ELEVATION, RANGE, OFFSET), (az - 50.0, 35.0, 12.0, [-0.4, 0.4, 0.0]),
             (az + 50.0, 55.0, 10.0, [0.3, 0.5, -0.2])]
    for i, v in enumerate(views):
        click(page, t, *v)
        page.wait_for_function(f"gsgeo.state.measure.rays.length === {i + 1}")
    pt = store(page, t)
    return {"id": t.id, "clicks": len(views), "error_m": error_of(pt, t), "maha2": maha2_of(pt, t)}


def rmse(xs: list[float]) -> float:
    return float(np.sqrt(np.mean(np.square(xs)))) if xs else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, help="DATA directory with the demo (made when missing)")
    ap.add_argument("--markers", help="comma-separated marker ids (default: all 20)")
    ap.add_argument("--manual", action="store_true", help="also measure each marker by three clicks")
    ap.add_argument("--manual-only", action="store_true", help="only the three-click measurements")
    ap.add_argument("--out", type=Path, help="write the results as JSON")
    ap.add_argument("--at-once", action="store_true",
                    help="click as soon as the camera is set, before its view is drawn (then A "
                         "waits for that view's frames)")
    ap.add_argument("--a-at-once", action="store_true",
                    help="press A right after the click, before the frames it asked (its ray, the "
                         "guide) are drawn (by default A waits for them)")
    ap.add_argument("--web", type=Path, help="serve the viewer from this web/ directory (A/B runs)")
    ap.add_argument("--aim-error-px", type=float, default=0.0,
                    help="auto-aim's first click this many pixels off the marker (a person's aim)")
    args = ap.parse_args()
    global SETTLE, A_SETTLE, AIM_ERROR_PX
    AIM_ERROR_PX = args.aim_error_px
    SETTLE = not args.at_once
    A_SETTLE = not (args.a_at_once or args.at_once)
    from playwright.sync_api import TimeoutError as PlaywrightTimeout
    from playwright.sync_api import sync_playwright

    tmp = tempfile.TemporaryDirectory()
    data = args.data or Path(tmp.name) / "data"
    if not (data / "scenes" / "demo").is_dir():
        subprocess.run([sys.executable, "-m", "gsgeo", "demo", "--data", str(data), "--no-serve"],
                       cwd=REPO, check=True, capture_output=True)
    truth = {t.id: t for t in place.truth_points()}
    ids = args.markers.split(",") if args.markers else list(truth)
    print(f"{platform.node()} {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; markers {','.join(ids)}")
    proc, base = start_server(data, *(["--web", str(args.web)] if args.web else []))
    auto: list[dict] = []
    manual: list[dict] = []
    try:
        with sync_playwright() as pw:
            b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
            page = b.new_page(viewport=VIEWPORT)
            page.on("pageerror", lambda exc: print(f"page error: {exc}", flush=True))
            page.goto(f"{base}/?scene=demo&project={PROJECT_ID}")
            page.wait_for_function("window.gsgeo && window.gsgeo.ready === true", timeout=120_000)
            page.wait_for_function("gsgeo.tileset && gsgeo.tilesReady && gsgeo.tileset.tilesLoaded",
                                   timeout=300_000)
            for pid in [] if args.manual_only else ids:
                try:
                    r = auto_point(page, truth[pid])
                except PlaywrightTimeout as exc:  # reported, and the sweep goes on
                    print(f"{pid}: timed out ({str(exc).splitlines()[0]}); page reloaded", flush=True)
                    auto.append({"id": pid, "timeout": True, "timings": {}, "clicks": 1})
                    page.goto(f"{base}/?scene=demo&project={PROJECT_ID}")
                    page.wait_for_function("window.gsgeo && window.gsgeo.ready === true",
                                           timeout=120_000)
                    page.wait_for_function("gsgeo.tileset && gsgeo.tilesReady && "
                                           "gsgeo.tileset.tilesLoaded", timeout=300_000)
                    continue
                err = f"{1000 * r['error_m']:.1f} mm from the truth" if "error_m" in r else "not stored"
                print(f"{pid}: {err}", flush=True)
                auto.append(r)
            if args.manual or args.manual_only:
                # the auto points hold the markers' ids: the manual ones go to a second project
                import httpx

                r = httpx.post(f"{base}/api/projects", json={"name": "manual", "id": "manual",
                                                             "scene": "demo", "crs": place.CRS})
                r.raise_for_status()
                page.goto(f"{base}/?scene=demo&project=manual")
                page.wait_for_function("window.gsgeo && window.gsgeo.ready === true", timeout=120_000)
                for pid in ids:
                    r = manual_point(page, truth[pid])
                    print(f"{pid}: manual, {r['clicks']} clicks, {1000 * r['error_m']:.1f} mm", flush=True)
                    manual.append(r)
            b.close()
    finally:
        proc.terminate()
        proc.communicate(timeout=10)
    done = [r for r in auto if "error_m" in r]
    to_rays = [r["timings"]["rays"] / 1000 for r in auto if "rays" in r["timings"]]
    if auto:
        median = f"A -> rays median {statistics.median(to_rays):.1f} s" if to_rays else "no rays added"
        print(f"\nauto: {len(done)} of {len(auto)} stored; {median}")
        print(f"auto: 1 click per point (+ A); RMSE 3-D {100 * rmse([r['error_m'] for r in done]):.2f} cm "
              f"over {len(done)} points")
        good = [r for r in done if r["error_m"] <= 0.03 and r.get("rays", 0) >= 3]
        print(f"auto: {len(good)} of {len(auto)} stored with >= 3 rays within 3 cm; worst "
              f"{100 * max([r['error_m'] for r in done], default=float('nan')):.1f} cm; "
              f"95 % ellipsoid holds the truth for {sum(r['maha2'] < 7.815 for r in done)} of {len(done)}; "
              f"timed out: {sum(1 for r in auto if r.get('timeout'))}")
    if manual:
        print(f"manual: 3 clicks per point; RMSE 3-D {1000 * rmse([r['error_m'] for r in manual]):.2f} mm "
              f"over {len(manual)} points; 95 % ellipsoid holds the truth for "
              f"{sum(r['maha2'] < 7.815 for r in manual)} of {len(manual)}")
    if args.out:
        args.out.write_text(json.dumps({"auto": auto, "manual": manual}, indent=1))
    if auto and len(auto) == len(place.truth_points()):
        # the rate the 20-marker browser sweep asserted before it moved here (the suite keeps
        # a sample of eight, tests/e2e/test_autoaim.py): >= 15 of 20 within 3 cm with >= 3
        # rays, none stored more than 10 cm off, the 95 % ellipsoid holding >= 80 % of them
        held = {">= 15 of 20 within 3 cm with >= 3 rays": len(good) >= 15,
                "none stored > 10 cm off": all(r["error_m"] <= 0.10 for r in done),
                "95 % ellipsoid holds >= 80 % of stored":
                    sum(r["maha2"] < 7.815 for r in done) >= 0.8 * len(done)}
        for what, ok in held.items():
            print(f"{'met' if ok else 'NOT MET'}: {what}")
        if not all(held.values()):
            sys.exit(1)


if __name__ == "__main__":
    main()
