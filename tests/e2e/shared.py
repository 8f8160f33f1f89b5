"""What the browser tests share, built once per test session (fixtures, made available to every
test by tests/conftest.py): one Chromium (Playwright), one
demo (`gsgeo demo --no-serve`) with its server, one box scene (`gsgeo tiles`) with its server.

Each test module opens its own pages, and works in its own project where it stores anything,
so no test depends on what another left behind. Everything here is skipped, with the reason,
where Debian's chromium, Playwright for Python or CesiumJS (web/node_modules) is missing.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.e2e.workplace import CESIUM_JS, CHROMIUM, CHROMIUM_ARGS, GL, REPO, make_data_dir


def require_browser() -> None:
    """Skip (with the reason) where the browser tests cannot run."""
    if not CHROMIUM.exists():
        pytest.skip("/usr/bin/chromium is not installed")
    if importlib.util.find_spec("playwright") is None:
        pytest.skip("Playwright for Python is not installed")
    if not CESIUM_JS.is_file():
        pytest.skip("cesium is not installed in web/node_modules (run npm ci in web/)")


#: The running Playwright (sync API) and its Chromium, while the browser tests run.
_PLAYWRIGHT: list = []


def stop_browser() -> None:
    """Close the session's Chromium and stop Playwright (idempotent). The browser tests'
    worker calls it after the last of them (tests/conftest.py): Playwright's sync API keeps an
    asyncio loop marked running in the main thread, and the modules the worker runs next call
    asyncio.run()."""
    while _PLAYWRIGHT:
        pw, b = _PLAYWRIGHT.pop()
        try:
            b.close()
        finally:
            pw.stop()


@pytest.fixture(scope="session")
def browser() -> Iterator:
    """Headless Chromium for the browser tests, drawing with the software renderer GL
    (workplace.py); tests open and close pages. Stopped after the last browser test."""
    require_browser()
    from playwright.sync_api import sync_playwright

    pw = sync_playwright().start()
    b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
    _PLAYWRIGHT.append((pw, b))
    try:
        renderer = webgl_renderer(b)
        if GL not in renderer.lower():
            pytest.fail(f"Chromium draws with {renderer!r}, not {GL} (GSGEO_TEST_GL): for llvmpipe, "
                        "Debian's libegl-mesa0 and libgl1-mesa-dri (scripts/install.sh --test)")
        yield b
    finally:
        stop_browser()


def webgl_renderer(browser) -> str:
    """The WebGL 2 renderer string of a page of `browser` (unmasked)."""
    page = browser.new_page()
    try:
        return page.evaluate("""() => { const g = document.createElement('canvas').getContext('webgl2');
            if (!g) return 'no WebGL 2'; const e = g.getExtension('WEBGL_debug_renderer_info');
            return String(e ? g.getParameter(e.UNMASKED_RENDERER_WEBGL) : g.getParameter(g.RENDERER)); }""")
    finally:
        page.close()


def serve(data: Path, *extra: str, env: dict | None = None) -> Iterator[str]:
    """`gsgeo serve --data DATA` on a free loopback port for a fixture's lifetime: its URL."""
    from tests.servertools import start_server

    proc, base = start_server(data, *extra, env=env)
    try:
        yield base
    finally:
        proc.terminate()
        proc.communicate(timeout=10)


@pytest.fixture(scope="session")
def demo_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The demo built once (`gsgeo demo --no-serve`): its DATA directory."""
    require_browser()
    data = tmp_path_factory.mktemp("demo") / "data"
    r = subprocess.run([sys.executable, "-m", "gsgeo", "demo", "--data", str(data), "--no-serve"],
                       cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return data


@pytest.fixture(scope="session")
def demo_server(demo_data: Path) -> Iterator[str]:
    """The URL of `gsgeo serve` on the demo."""
    yield from serve(demo_data)


def demo_project_copy(server: str, pid: str) -> str:
    """A project `pid` on the demo scene with the demo project's settings and check points (the
    ground truth), for a module that stores points of its own; returns its id."""
    import httpx

    from gsgeo.demo.project import PROJECT_ID

    with httpx.Client(base_url=server, timeout=60) as c:
        demo = c.get(f"/api/projects/{PROJECT_ID}").json()
        r = c.post("/api/projects", json={"name": f"{demo['name']} ({pid})", "id": pid,
                                          "scene": demo["scene"], "crs": demo["crs"],
                                          "sigma_px": demo["sigma_px"]})
        assert r.status_code == 201, r.text
        cps = c.get(f"/api/projects/{PROJECT_ID}/checkpoints").json()["check_points"]
        by_crs: dict[str, list[dict]] = {}
        for cp in cps:
            by_crs.setdefault(cp["crs"], []).append(
                {"id": cp["id"], "x": cp["x"], "y": cp["y"], "z": cp["z"]})
        for crs, pts in by_crs.items():
            r = c.post(f"/api/projects/{pid}/checkpoints", json={"crs": crs, "points": pts})
            assert r.status_code == 201, r.text
    return pid


@pytest.fixture(scope="session")
def box_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """DATA with scenes/box, made once by `gsgeo tiles` from tests/e2e/scene.py's PLY."""
    require_browser()
    return make_data_dir(tmp_path_factory.mktemp("box"))


@pytest.fixture(scope="session")
def box_server(box_data: Path) -> Iterator[str]:
    """The URL of `gsgeo serve` on the box scene."""
    yield from serve(box_data)


def open_demo_page(browser, server: str, pid: str, viewport: dict, *,
                   draw_splats: bool = True) -> Iterator:
    """A page of the viewer on the demo scene and project `pid` for a module's lifetime (a
    fixture's body): console errors collected in ``page.errors``, waits of 120 s (a frame of
    the demo's 341 816 splats takes seconds in SwiftShader, more on a busy machine; waits are
    for correctness here, speed is the benchmarks'). With ``draw_splats`` False the splats are
    hidden once the scene is open (for tests that need no picture of them)."""
    pg = browser.new_page(viewport=viewport)
    pg.set_default_timeout(120_000)
    errors: list[str] = []
    pg.on("console", lambda m: m.type == "error" and errors.append(m.text))
    pg.on("pageerror", lambda e: errors.append(f"page error: {e}"))
    pg.goto(f"{server}/?scene=demo&project={pid}")
    if draw_splats:
        pg.wait_for_function("window.gsgeo && window.gsgeo.ready === true", timeout=90_000)
        pg.wait_for_function("gsgeo.tileset && gsgeo.tilesReady && gsgeo.tileset.tilesLoaded")
    else:
        pg.wait_for_function("window.gsgeo && window.gsgeo.ready === true && !!gsgeo.tileset",
                             timeout=90_000)
        pg.evaluate("gsgeo.tileset.show = false")
    pg.errors = errors
    try:
        yield pg
    finally:
        pg.close()
