"""Scenes on a static host: `gsgeo serve --scenes URL` with Debian's nginx serving a copy of the
scene folders, and the viewer (Chromium) fetching the tiles from nginx.

Debian's nginx runs as a child of the test with its own configuration, pid file, logs and
temporary folders in the test's temporary folder, on free loopback ports, and is stopped at the
end even when a test fails. It serves the same folder twice: on one port with the CORS header
the viewer needs (Access-Control-Allow-Origin: the gsgeo server's origin), on another without.
The gsgeo data directory keeps only each scene's tileset.json (the georeference): gsgeo has no
tile to serve, so a scene that renders drew nginx's tiles, and nginx's access log shows them
asked for. Scene ``box`` comes from the CORS port (--scenes), scene ``bare`` from the port
without CORS (--scene-url bare=...): the browser refuses those tiles and the viewer says why.
"""

from __future__ import annotations

import io
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.e2e.shared import require_browser
from tests.e2e.tiles_page import ALL_SPLATS_DRAWN_JS
from tests.e2e.workplace import SCENE, make_data_dir
from tests.servertools import REPO, free_port

pytestmark = pytest.mark.e2e

NGINX = Path("/usr/sbin/nginx")
VIEWPORT = {"width": 1000, "height": 640}

NGINX_CONF = """daemon off;
master_process on;
worker_processes 1;
pid {work}/nginx.pid;
error_log {work}/error.log warn;
{user}
events {{ worker_connections 64; }}
http {{
    access_log {work}/access.log;
    client_body_temp_path {work}/tmp/body;
    proxy_temp_path {work}/tmp/proxy;
    fastcgi_temp_path {work}/tmp/fastcgi;
    uwsgi_temp_path {work}/tmp/uwsgi;
    scgi_temp_path {work}/tmp/scgi;
    types {{ application/json json; model/gltf-binary glb; }}
    default_type application/octet-stream;
    server {{
        listen 127.0.0.1:{cors_port};
        root {site};
        location / {{
            add_header Access-Control-Allow-Origin "{origin}" always;
            add_header Vary Origin always;
        }}
    }}
    server {{
        listen 127.0.0.1:{bare_port};
        root {site};
    }}
}}
"""


def wait_port(port: int, proc: subprocess.Popen, what: str, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"{what} exited with {proc.returncode}")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise RuntimeError(f"{what} does not listen on port {port}")


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)


@pytest.fixture(scope="module")
def hosts(tmp_path_factory):
    """nginx (CORS and bare ports) and gsgeo serve --scenes: a dict of URLs and log paths."""
    require_browser()
    if not os.access(NGINX, os.X_OK):
        pytest.skip("Debian's nginx is not installed (bash scripts/install.sh --test "
                    "installs nginx-light)")
    root = tmp_path_factory.mktemp("static-scenes")
    data = make_data_dir(root)
    scenes = data / "scenes"
    site = root / "site"
    shutil.copytree(scenes / SCENE, site / SCENE)  # the static host's copy: tileset and tiles
    shutil.rmtree(scenes / SCENE / "tiles")  # gsgeo keeps only tileset.json
    (scenes / "bare").mkdir()
    shutil.copy(scenes / SCENE / "tileset.json", scenes / "bare" / "tileset.json")

    work = root / "nginx"
    (work / "tmp").mkdir(parents=True)
    gs_port, cors_port, bare_port = free_port(), free_port(), free_port()
    origin = f"http://127.0.0.1:{gs_port}"
    # as root, nginx's workers would switch to nobody, who cannot read the test's folders
    user = f"user {'root'};" if os.geteuid() == 0 else ""
    conf = work / "nginx.conf"
    conf.write_text(NGINX_CONF.format(work=work, user=user, cors_port=cors_port,
                                      bare_port=bare_port, site=site, origin=origin))
    nginx = subprocess.Popen([str(NGINX), "-p", f"{work}/", "-c", str(conf),
                              "-e", str(work / "error.log")],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    gs_log = root / "gsgeo.log"
    gsgeo = None
    try:
        wait_port(cors_port, nginx, "nginx")
        wait_port(bare_port, nginx, "nginx")
        with open(gs_log, "w") as log:
            gsgeo = subprocess.Popen(
                [sys.executable, "-m", "gsgeo", "serve", "--data", str(data), "--port",
                 str(gs_port), "--log-level", "info",
                 "--scenes", f"http://127.0.0.1:{cors_port}",
                 "--scene-url", f"bare=http://127.0.0.1:{bare_port}/{SCENE}/"],
                cwd=REPO, stdout=log, stderr=subprocess.STDOUT)
        wait_port(gs_port, gsgeo, "gsgeo serve", timeout=40)
        yield {"gsgeo": origin, "cors": f"http://127.0.0.1:{cors_port}",
               "bare": f"http://127.0.0.1:{bare_port}", "access_log": work / "access.log",
               "gsgeo_log": gs_log}
    finally:
        if gsgeo is not None:
            stop(gsgeo)
        stop(nginx)


def canvas_pixels(page) -> np.ndarray:
    """The viewer's canvas as an RGB array, with the overlays on it hidden."""
    from PIL import Image

    page.evaluate("""() => { for (const s of ['#scene-message', '#status', '#georef-banner'])
                               document.querySelector(s).style.visibility = 'hidden'; }""")
    png = page.locator("#cesium").screenshot(timeout=90_000)
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)


@pytest.fixture(scope="module")
def loaded(hosts, browser):
    """Both scenes opened in the viewer: per scene its canvas, messages and console errors."""
    out = {}
    for name in (SCENE, "bare"):
        errors: list[str] = []
        page = browser.new_page(viewport=VIEWPORT)
        page.on("console", lambda m, errors=errors: m.type == "error" and errors.append(m.text))
        page.goto(f"{hosts['gsgeo']}/?scene={name}")
        page.wait_for_function("window.gsgeo && window.gsgeo.ready === true", timeout=90_000)
        if name == SCENE:
            page.wait_for_function(
                "window.gsgeo.tilesReady && window.gsgeo.tileset.tilesLoaded", timeout=90_000)
            page.wait_for_function(f"({ALL_SPLATS_DRAWN_JS})(window.gsgeo.tileset)",
                                   timeout=90_000, polling=250)
        else:
            page.wait_for_function("!document.querySelector('#scene-message').hidden",
                                   timeout=90_000)
            page.wait_for_timeout(1500)  # frames of the empty scene
        selected = page.evaluate("window.gsgeo.tileset.statistics.numberOfPointsSelected")
        out[name] = {"message": page.locator("#scene-message").text_content()
                     if page.locator("#scene-message").is_visible() else "",
                     "messages": page.locator("#messages").text_content(),
                     "selected": selected, "errors": errors, "pixels": canvas_pixels(page)}
        page.close()
    return out


def test_tiles_come_from_the_static_host(hosts, loaded):
    box = loaded[SCENE]
    assert box["selected"] > 0  # splats of the static host's tiles are drawn
    assert box["message"] == "" and "failed" not in box["messages"], box["messages"]
    nginx_log = hosts["access_log"].read_text()
    tile_lines = [ln for ln in nginx_log.splitlines() if f"GET /{SCENE}/tiles/" in ln]
    assert tile_lines and all('" 200 ' in ln for ln in tile_lines), nginx_log
    gs_log = hosts["gsgeo_log"].read_text()
    assert f"GET /scenes/{SCENE}/tileset.json" in gs_log  # the georeference came from gsgeo
    assert "/tiles/" not in gs_log, gs_log  # no tile was asked of gsgeo
    # the picture is not blank: it differs from the same view without the tiles (scene bare)
    diff = np.abs(box["pixels"] - loaded["bare"]["pixels"]).max(axis=2)
    assert (diff > 40).mean() > 0.02, (diff > 40).mean()


def test_host_without_cors_gets_a_clear_message(hosts, loaded):
    bare = loaded["bare"]
    assert bare["selected"] == 0
    text = bare["message"]
    assert "static host" in text and hosts["bare"] in text, text
    assert "CORS" in text and f"Access-Control-Allow-Origin: {hosts['gsgeo']}" in text, text
    assert "Scenes on a static host" in text
    # the request reached nginx and was answered: it is the missing header the browser refused
    assert f"GET /{SCENE}/tiles/" in hosts["access_log"].read_text()
    assert text in bare["messages"]  # also in the messages list, once
    assert bare["messages"].count("cannot be read from the static host") == 1
