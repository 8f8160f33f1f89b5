"""Frames the viewer draws, and the CPU they cost, to open a scene and after a camera move, in
headless Chromium with the software renderer the browser tests use (Mesa's llvmpipe, or
SwiftShader with GSGEO_TEST_GL=swiftshader).

    python benchmarks/frames.py [--demo DATA] [--settle S] [--web DIR]

For the tests' box scene (12 880 splats, `gsgeo tiles` of tests/e2e/scene.py's PLY) and, with
--demo (a DATA directory of `gsgeo demo --no-serve`), the demo (341 816 splats): the frames
(window.gsgeo.renderer.frames; "of all": those that drew every splat) and the CPU seconds of
every Chromium process (from /proc, so Linux only) from opening the page until S seconds after
its tiles are loaded; then, one after the other, an arrow key (pan a tenth of the view), Shift
+ an arrow key (orbit 5 degrees) and a turn of the camera by 0.3 rad set from JavaScript, each
followed by S seconds. On a GPU each frame costs milliseconds; here a frame of the box scene
costs ~0.3 CPU-s and one of the demo ~1 CPU-s, which is what the browser tests wait for.
--web serves the viewer from another web/ directory (an older commit's, for before/after).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tests.e2e.workplace import CHROMIUM, CHROMIUM_ARGS, make_data_dir  # noqa: E402
from tests.servertools import start_server  # noqa: E402

HZ = os.sysconf("SC_CLK_TCK")
READY_JS = ("window.gsgeo && window.gsgeo.ready === true && gsgeo.tileset && gsgeo.tilesReady "
            "&& gsgeo.tileset.tilesLoaded")
FRAMES_JS = "[gsgeo.renderer.frames, gsgeo.renderer.framesOfAll]"
TURN_JS = "() => { gsgeo.viewer.camera.rotateRight(0.3); gsgeo.viewer.scene.requestRender(); }"


def chromium_cpu_s() -> float:
    """User + system CPU seconds of every running Chromium process."""
    total = 0.0
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
            stat = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if cmd and b"chromium" in cmd[0]:
            total += (int(stat[11]) + int(stat[12])) / HZ
    return total


def measure(browser, url: str, settle_s: float) -> list[tuple[str, int, int, float]]:
    """(step, frames, frames of all, CPU s) for opening `url` and each move after."""
    page = browser.new_page(viewport={"width": 1280, "height": 720})
    rows = []
    cpu0 = chromium_cpu_s()
    page.goto(url)
    page.wait_for_function(READY_JS, timeout=300_000)
    page.wait_for_timeout(settle_s * 1000)
    f = page.evaluate(FRAMES_JS)
    rows.append(("open", f[0], f[1], chromium_cpu_s() - cpu0))
    page.mouse.move(640, 400)
    for step, act in (("arrow key", lambda: page.keyboard.press("ArrowLeft")),
                      ("Shift + arrow key", lambda: page.keyboard.press("Shift+ArrowLeft")),
                      ("turn 0.3 rad", lambda: page.evaluate(TURN_JS))):
        f0, cpu0 = page.evaluate(FRAMES_JS), chromium_cpu_s()
        act()
        page.wait_for_timeout(settle_s * 1000)
        f = page.evaluate(FRAMES_JS)
        rows.append((step, f[0] - f0[0], f[1] - f0[1], chromium_cpu_s() - cpu0))
    page.close()
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--demo", type=Path, help="DATA directory holding the demo scene")
    ap.add_argument("--settle", type=float, default=15.0, help="seconds after each step")
    ap.add_argument("--web", type=Path, help="serve the viewer from this web/ directory")
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        box = make_data_dir(Path(tmp))
        scenes = [("box", box, "?scene=box")]
        if args.demo:
            scenes.append(("demo", args.demo, "?scene=demo&project=demo"))
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
            try:
                for name, data, query in scenes:
                    proc, base = start_server(data, *(["--web", str(args.web)] if args.web else []))
                    try:
                        for step, frames, full, cpu in measure(browser, f"{base}/{query}",
                                                               args.settle):
                            print(f"{name:5s} {step:18s} {frames:3d} frames ({full:3d} of every "
                                  f"splat) {cpu:6.1f} CPU-s", flush=True)
                    finally:
                        proc.terminate()
                        proc.communicate(timeout=10)
            finally:
                browser.close()


if __name__ == "__main__":
    main()
