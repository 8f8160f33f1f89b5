"""The README's picture of the measuring workplace (docs/images/viewer.png), made the way a
person works: the demo built and served, G1 measured by three clicks from three stations in
Chromium, stored with Enter, Enter, then a view over the lawn with the cursor resting on G2.

    .venv/bin/python scripts/viewer_screenshot.py [--out docs/images/viewer.png] [--data DIR]

Needs what the browser tests need (scripts/install.sh --test): Debian's chromium, Playwright
for Python, CesiumJS in web/node_modules. About a minute on two cores (llvmpipe).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gsgeo.demo import place  # noqa: E402
from tests.e2e.workplace import AIM_JS, CHROMIUM, CHROMIUM_ARGS  # noqa: E402
from tests.servertools import start_server  # noqa: E402

#: Stations (azimuth deg, elevation deg, range m) G1 is clicked from.
STATIONS = [(200.0, 45.0, 12.0), (290.0, 40.0, 12.0), (110.0, 50.0, 12.0)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "images" / "viewer.png")
    ap.add_argument("--data", type=Path, help="a demo DATA directory (built when missing)")
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        data = args.data or Path(tmp) / "data"
        if not (data / "scenes" / "demo").is_dir():
            subprocess.run([sys.executable, "-m", "gsgeo", "demo", "--data", str(data), "--no-serve"],
                           cwd=REPO, check=True)
        proc, base = start_server(data)
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
                page = browser.new_page(viewport={"width": 1280, "height": 720})
                page.set_default_timeout(120_000)
                page.goto(f"{base}/?scene=demo&project=demo")
                page.wait_for_function("window.gsgeo && gsgeo.ready === true && gsgeo.tileset"
                                       " && gsgeo.tilesReady && gsgeo.tileset.tilesLoaded")
                truth = {t.id: t for t in place.truth_points()}
                g1 = list(truth["G1"].ecef)
                if not page.evaluate("gsgeo.state.points.some((p) => p.id === 'G1')"):
                    page.keyboard.press("m")
                    for k, (az, el, rng) in enumerate(STATIONS):
                        a = page.evaluate(AIM_JS, [g1, az, el, rng, [0.0, 0.0, 0.0]])
                        page.mouse.click(a["x"], a["y"])
                        page.wait_for_function(f"gsgeo.state.measure.rays.length === {k + 1}")
                    page.keyboard.press("Enter")
                    page.wait_for_selector("#id-prompt:not([hidden])")
                    page.fill("#id-prompt-input", "G1")
                    page.keyboard.press("Enter")
                    page.wait_for_function("gsgeo.state.selected === 'G1'")
                else:
                    page.click("#points-table tbody tr[data-id='G1']")
                    page.wait_for_function("gsgeo.state.selected === 'G1'")
                page.evaluate(AIM_JS, [g1, 205.0, 32.0, 26.0, [4.0, 6.0, 0.0]])
                g2 = page.evaluate("""(p) => { const C = gsgeo.Cesium, scene = gsgeo.viewer.scene;
                    const w = C.SceneTransforms.worldToWindowCoordinates(scene, new C.Cartesian3(...p));
                    const r = gsgeo.viewer.scene.canvas.getBoundingClientRect();
                    return [r.left + w.x, r.top + w.y]; }""", list(truth["G2"].ecef))
                page.mouse.move(g2[0] + 2, g2[1] + 2)
                page.mouse.move(*g2)
                page.wait_for_function("gsgeo.navigation.cursor && gsgeo.navigation.cursor.located")
                # settled: the new view's tiles loaded and drawn, no frame for 3 s
                page.wait_for_function("""() => { const f = gsgeo.renderer.frames, now = performance.now();
                    if (window.lastFrames !== f) { window.lastFrames = f; window.lastFrameAt = now; }
                    return !gsgeo.renderer.busy() && now - window.lastFrameAt > 3000
                      && !document.querySelector('#scale-bar').hidden; }""", polling=250)
                args.out.parent.mkdir(parents=True, exist_ok=True)
                page.screenshot(path=str(args.out))
                browser.close()
        finally:
            proc.terminate()
            proc.communicate(timeout=10)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
