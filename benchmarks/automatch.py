"""Image matching (/api/match) on real Chromium renders of the demo's 20 markers, against
the truth: a dataset captured once, then evaluated offline (fast) as the matcher changes.

    python benchmarks/automatch.py capture [--data DIR] [--dataset DIR] [--markers G1,B1,...]
                                           [--shape-views] [--scene-match]
    python benchmarks/automatch.py evaluate [--dataset DIR] [--normal] [--foreground]
                                            [--answers] [-v]

capture: `gsgeo demo` into --data (kept), `gsgeo serve`, and for each marker the viewer's own
auto-aim (web/js/autoaim.js: M, one real click on the marker's exact projection from 45
degrees up at 12 m, A) in headless Debian chromium; the bodies of its POST /api/match requests
(reference crop, target crops, cameras, the depth hint) and the /depth, /views answers are
saved as <dataset>/<marker>.json with the truth in rendered ECEF (the tileset's modelMatrix
applied to gsgeo.demo.place.truth_points()). Slow: every view is rendered by a software
renderer (the browser tests' GSGEO_TEST_GL).

evaluate: gsgeo.aim.match.match_feature on every (reference, target) pair, as the server
would run it (with /depth's normal_ecef when --normal); per pair whether it was accepted, the
matched pixel's distance from the truth's exact projection in the target (px) and the
distance of the matched ray from the truth (cm); then the percentiles of the accepted
errors, the declines by reason, the markers with >= 2 views within 3 cm, and the 3-D error of
each point the click's ray and the accepted matches' rays make when there are >= 3 of them
(gsgeo.solve's least squares, as the viewer stores it). With --foreground the matcher also
gets the splats about the click (as POST /api/scenes/{scene}/match does): the patch weighted
by their opacity and warped by their shape too. capture --shape-views asks /views for that
matcher's views (a corner's or pole top's within 35 degrees of the click's ray), and
--scene-match sends the viewer's matches to that matcher (POST /api/scenes/demo/match with
the tileset's modelMatrix); evaluate --answers scores the answers the server gave then.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gsgeo.aim.camera import Camera  # noqa: E402
from gsgeo.aim.foreground import BALL_PX, foreground_of_click  # noqa: E402
from gsgeo.aim.images import decode_image  # noqa: E402
from gsgeo.aim.match import MatchResult, View, match_feature  # noqa: E402
from gsgeo.solve import intersect  # noqa: E402

ELEVATION, RANGE, OFFSET = 45.0, 12.0, [0.4, -0.3, 0.0]
VIEWPORT = {"width": 1280, "height": 720}
WITHIN_CM = 3.0


def capture(data: Path, dataset: Path, markers: list[str], shape_views: bool = False,
            scene_match: bool = False) -> None:
    from playwright.sync_api import sync_playwright

    from gsgeo.demo import place, scene
    from gsgeo.demo.project import PROJECT_ID
    from tests.e2e.workplace import AIM_JS, CHROMIUM, CHROMIUM_ARGS
    from tests.servertools import start_server

    dataset.mkdir(parents=True, exist_ok=True)
    if not (data / "scenes").exists():
        subprocess.run([sys.executable, "-m", "gsgeo", "demo", "--data", str(data), "--no-serve"],
                       cwd=REPO, check=True, capture_output=True)
    cx, cy = np.mean(scene.BUILDING_X), np.mean(scene.BUILDING_Y)
    proc, base = start_server(data)
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
            pg = browser.new_page(viewport=VIEWPORT)
            cur: dict = {}

            def on_response(r) -> None:
                if r.request.method != "POST":
                    return
                if r.url.endswith("/match"):
                    cur.setdefault("match", []).append(json.loads(r.request.post_data))
                    cur.setdefault("match_answers", []).append(r.json())
                elif r.url.endswith("/depth"):
                    # the clicked ray's, not the navigation's (the view's centre, scale bar)
                    px = (json.loads(r.request.post_data or "{}").get("ray") or {}).get("pixel")
                    click = cur.get("click")
                    if click is None or (px and abs(px[0] - click[0]) <= 1
                                         and abs(px[1] - click[1]) <= 1):
                        cur["depth"] = r.json()
                elif r.url.endswith("/views"):
                    cur["views"] = r.json()

            pg.on("response", on_response)
            if shape_views:         # the views for the scene's matcher (POST /views shape_views)
                def views_for_shapes(route, request) -> None:
                    if request.method != "POST":
                        route.continue_()
                        return
                    body = json.loads(request.post_data or "{}")
                    route.continue_(post_data=json.dumps(dict(body, shape_views=True)))

                pg.route("**/api/scenes/*/views", views_for_shapes)
            if scene_match:         # the scene's matcher: POST /api/scenes/demo/match
                def match_in_scene(route, request) -> None:
                    body = json.loads(request.post_data or "{}")
                    body["model_matrix"] = np.asarray(mm, dtype=float).tolist()
                    route.continue_(url=request.url.replace("/api/match",
                                                            "/api/scenes/demo/match"),
                                    post_data=json.dumps(body))

                pg.route("**/api/match", match_in_scene)
            pg.goto(f"{base}/?scene=demo&project={PROJECT_ID}")
            pg.wait_for_function("window.gsgeo && window.gsgeo.ready === true", timeout=90_000)
            pg.wait_for_function("gsgeo.tileset && gsgeo.tilesReady && gsgeo.tileset.tilesLoaded",
                                 timeout=120_000)
            mm = pg.evaluate("Array.from(Cesium.Matrix4.toArray(gsgeo.tileset.modelMatrix))")
            model = np.array(mm).reshape(4, 4).T                 # Cesium: column-major
            for t in place.truth_points():
                if markers and t.id not in markers:
                    continue
                t0 = time.time()
                cur.clear()
                pg.keyboard.press("m")
                pg.wait_for_selector("#measure-panel:not([hidden])")
                az = float(np.degrees(np.arctan2(t.local[0] - cx, t.local[1] - cy)))
                a = pg.evaluate(AIM_JS, [list(t.ecef), az, ELEVATION, RANGE, OFFSET])
                cur["click"] = a["win"]
                pg.mouse.click(a["x"], a["y"])
                try:
                    pg.wait_for_function("gsgeo.state.measure.rays.length === 1",
                                         timeout=120_000)
                except Exception as exc:            # noqa: BLE001 - one marker lost, not all
                    print(f"{t.id}: the click gave no ray ({exc.__class__.__name__}); skipped",
                          flush=True)
                    pg.keyboard.press("Escape")
                    continue
                pg.keyboard.press("a")
                pg.wait_for_function("gsgeo.state.measure.autoaim && "
                                     "!gsgeo.state.measure.autoaim.running",
                                     timeout=600_000, polling=250)
                time.sleep(0.5)                                   # the last answers in
                text = pg.evaluate("gsgeo.state.measure.autoaim.text")
                pg.keyboard.press("Escape")
                pg.wait_for_selector("#measure-panel", state="hidden")
                truth = (model @ np.r_[t.ecef, 1.0])[:3]
                (dataset / f"{t.id}.json").write_text(json.dumps(
                    dict(cur, id=t.id, truth_rendered_ecef=truth.tolist(), report=text,
                         model_matrix=model.tolist())))
                print(f"{t.id} {time.time() - t0:.0f} s: {text[:150]}", flush=True)
            browser.close()
    finally:
        proc.terminate()
        proc.communicate(timeout=10)


def camera(c: dict) -> Camera:
    return Camera.checked(c["position"], c["direction"], c["up"], c["fovy"], c["width"],
                          c["height"])


def view(v: dict, field: str) -> View:
    return View(decode_image(v["image"], field), np.asarray(v.get("origin", [0, 0]), float),
                camera(v["camera"]))


def evaluate(dataset: Path, use_normal: bool, verbose: bool, data: Path | None = None,
             ball_px: float = BALL_PX, answers: bool = False) -> dict:
    """The matcher on every captured pair (module docstring); with ``data`` (the demo's data
    folder of the capture) the foreground of the click's splats weights the patches, as the
    server does when the request names the scene. With ``answers`` the server's own answers
    kept by the capture are scored instead of running the matcher."""
    index = None
    if data is not None:
        from gsgeo.aim.splatindex import scene_index
        index = scene_index(data / "scenes" / "demo" / "tileset.json")
    rows = []
    rays: dict[str, list] = {}
    truths: dict[str, np.ndarray] = {}
    for path in sorted(dataset.glob("*.json")):
        rec = json.loads(path.read_text())
        truth = np.asarray(rec["truth_rendered_ecef"])
        depth = rec.get("depth") or {}
        for k, body in enumerate(rec.get("match", [])):
            ref = view(body["reference"], "reference")
            tgt = view(body["target"], "target")
            click = np.asarray(body["reference"]["pixel"], float)
            normal = depth.get("normal_ecef") if use_normal else None
            t0 = time.perf_counter()
            fg = None
            if index is not None:
                mm = rec.get("model_matrix")
                fg = foreground_of_click(index, ref.camera, click, depth["depth_m"],
                                         None if mm is None else np.asarray(mm), ball_px)
            if answers:
                ans = rec["match_answers"][k]
                res = MatchResult(bool(ans["ok"]), None if ans["pixel"] is None
                                  else np.asarray(ans["pixel"], float), ans["score"],
                                  ans["second"], ans["depth_m"], ans["reason"])
            else:
                res = match_feature(ref, click, tgt, depth["near_m"], depth["far_m"],
                                    depth["depth_m"],
                                    None if normal is None else np.asarray(normal), fg)
            ms = (time.perf_counter() - t0) * 1e3
            row = {"marker": rec["id"], "view": k + 1, "ok": res.ok, "score": res.score,
                   "reason": res.reason, "ms": ms}
            if k == 0:
                rays[rec["id"]] = [(ref.camera.position, ref.camera.pick_ray(click[None])[0],
                                    ref.camera.ifov)]
                truths[rec["id"]] = truth
            if res.ok and res.pixel is not None:
                rays[rec["id"]].append((tgt.camera.position,
                                        tgt.camera.pick_ray(res.pixel[None])[0],
                                        tgt.camera.ifov))
                xy, _ = tgt.camera.project(truth[None])
                ray = tgt.camera.pick_ray(res.pixel[None])[0]
                w = truth - tgt.camera.position
                row["px"] = float(np.linalg.norm(res.pixel - xy[0]))
                row["cm"] = float(np.linalg.norm(w - (w @ ray) * ray)) * 100
            rows.append(row)
            if verbose:
                print(rec["id"], k + 1, "ok" if res.ok else "declined",
                      f"score {res.score:.2f}" if res.score is not None else "",
                      f"{row.get('px', 0):.2f} px {row.get('cm', 0):.1f} cm" if res.ok
                      else res.reason)
    acc = [r for r in rows if r["ok"]]
    cm = np.array([r["cm"] for r in acc]) if acc else np.full(1, np.nan)
    px = np.array([r["px"] for r in acc]) if acc else np.full(1, np.nan)
    markers = sorted({r["marker"] for r in rows})
    good = {m: sum(1 for r in acc if r["marker"] == m and r["cm"] <= WITHIN_CM) for m in markers}
    bad = {m: sum(1 for r in acc if r["marker"] == m and r["cm"] > WITHIN_CM) for m in markers}
    # the point of the click's ray and the accepted matches' rays (>= 3 rays), as stored
    point_cm = {}
    for m, rs in rays.items():
        if len(rs) >= 3:
            res = intersect(np.array([r[0] for r in rs]), np.array([r[1] for r in rs]),
                            ifov=np.array([r[2] for r in rs]))
            point_cm[m] = float(np.linalg.norm(res.point - truths[m])) * 100
    summary = {
        "points_3_rays": len(point_cm),
        "points_within_3cm": sum(1 for v in point_cm.values() if v <= WITHIN_CM),
        "points_over_10cm": sum(1 for v in point_cm.values() if v > 10.0),
        "point_error_cm": {m: round(v, 2) for m, v in sorted(point_cm.items())},
        "pairs": len(rows), "accepted": len(acc),
        "accepted_within_3cm": sum(1 for r in acc if r["cm"] <= WITHIN_CM),
        "error_cm_p50_p90_max": [float(np.percentile(cm, 50)), float(np.percentile(cm, 90)),
                                 float(cm.max())],
        "error_px_p50_p90_max": [float(np.percentile(px, 50)), float(np.percentile(px, 90)),
                                 float(px.max())],
        "declined": dict(Counter((r["reason"] or "").split(":")[0] for r in rows if not r["ok"])),
        "markers": len(markers),
        "markers_2_within_3cm": sum(1 for m in markers if good[m] >= 2),
        "markers_2_within_3cm_none_worse": sum(1 for m in markers if good[m] >= 2 and not bad[m]),
        "per_marker": {m: " ".join((f"{r['cm']:.1f}cm" if r["ok"] else "-")
                                   for r in rows if r["marker"] == m) for m in markers},
        "match_ms_median": float(np.median([r["ms"] for r in rows])) if rows else None,
        "match_ms_p90_max": [float(np.percentile([r["ms"] for r in rows], 90)),
                             float(max(r["ms"] for r in rows))] if rows else None,
    }
    print(json.dumps(summary, indent=1))
    return summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("capture")
    c.add_argument("--data", type=Path, default=REPO / "benchmarks" / "out" / "automatch-data")
    c.add_argument("--dataset", type=Path, default=REPO / "benchmarks" / "out" / "automatch")
    c.add_argument("--markers", default="")
    c.add_argument("--scene-match", action="store_true",
                   help="send the viewer's matches to POST /api/scenes/demo/match (the splats "
                        "weigh and shape the patches on the server; its answers are kept)")
    c.add_argument("--shape-views", action="store_true",
                   help="ask /views for the views of the scene's matcher (shape_views: a "
                        "corner's or pole top's within 35 degrees of the click's ray)")
    e = sub.add_parser("evaluate")
    e.add_argument("--dataset", type=Path, default=REPO / "benchmarks" / "out" / "automatch")
    e.add_argument("--normal", action="store_true", help="pass /depth's normal_ecef")
    e.add_argument("-v", action="store_true")
    e.add_argument("--foreground", type=Path, metavar="DATA", nargs="?",
                   const=REPO / "benchmarks" / "out" / "automatch-data",
                   help="weight the patches by the splats about the click (the capture's data "
                        "folder, default benchmarks/out/automatch-data)")
    e.add_argument("--answers", action="store_true",
                   help="score the server's answers kept by the capture, not the matcher now")
    e.add_argument("--ball-px", type=float, default=BALL_PX,
                   help="the foreground's ball radius, px of the reference view at the point")
    a = ap.parse_args()
    if a.cmd == "capture":
        capture(a.data, a.dataset, [m for m in a.markers.split(",") if m], a.shape_views,
                a.scene_match)
    else:
        evaluate(a.dataset, a.normal, a.v, a.foreground, a.ball_px, a.answers)


if __name__ == "__main__":
    main()
