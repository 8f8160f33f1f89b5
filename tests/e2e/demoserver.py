"""The demo (`gsgeo demo --no-serve`) built in a fresh DATA directory and served by `gsgeo serve`,
for the browser tests that work on the demo scene; skipped where chromium, Playwright or
CesiumJS is missing."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from collections.abc import Iterator

import pytest

from tests.e2e.workplace import CESIUM_JS, CHROMIUM, REPO


def demo_server(tmp_path_factory: pytest.TempPathFactory, name: str) -> Iterator[str]:
    """Yield the base URL of a server on a freshly built demo (a module fixture's body)."""
    if not CHROMIUM.exists():
        pytest.skip("/usr/bin/chromium is not installed")
    if importlib.util.find_spec("playwright") is None:
        pytest.skip("Playwright for Python is not installed")
    if not CESIUM_JS.is_file():
        pytest.skip("cesium is not installed in web/node_modules (run npm ci in web/)")
    from tests.servertools import start_server

    data = tmp_path_factory.mktemp(name) / "data"
    r = subprocess.run([sys.executable, "-m", "gsgeo", "demo", "--data", str(data), "--no-serve"],
                       cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    proc, base = start_server(data)
    try:
        yield base
    finally:
        proc.terminate()
        proc.communicate(timeout=10)
