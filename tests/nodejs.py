"""Running the web client's ES modules (web/js/) in Node.js for the tests that check its pure
JavaScript."""

from __future__ import annotations

import json
import subprocess

from tests.conftest import REPO

WEB_JS = REPO / "web" / "js"


def run_web_module(module: str, body: str, data=None) -> object:
    """Run `body` with web/js/`module` bound as M and `data` as data; it prints one JSON value.
    A `window` without Cesium stands in for the page's: the module is imported after it (a
    dynamic import), as some read window.Cesium when they load."""
    src = (f"globalThis.window = {{}};\nconst M = await import('{(WEB_JS / module).as_uri()}');\n"
           f"const data = {json.dumps(data)};\n{body}\n")
    out = subprocess.run(["node", "--input-type=module", "-e", src], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)
